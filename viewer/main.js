// detp_bake's lightmap viewer: a .glb lit only by its MOZ_lightmap textures.
//   index.html?model=URL   load a model (relative URLs resolve against this page)
//   &exposure=EV           scale the lightmaps by 2^EV, as Blender's Exposure (Color Management)
//   &roll=P                move the probe-lit objects (DETP_light_probes) along the probe grid's x
//                          extent, rolling: P in [0, 1] a fixed place, 'auto' back and forth
//   &shot=1                for tests: no panel, and window.viewerReady = true once a frame of the
//                          loaded model is on screen; window.viewerErrors holds what went wrong
//                          and window.viewerInfo what was shown
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { MozLightmap } from './moz_lightmap.js';
import { DetpProbes, rollRange, updateProbeLit } from './detp_probes.js';

const params = new URLSearchParams(location.search);
const shot = params.has('shot') && params.get('shot') !== '0';
const exposure = Number(params.get('exposure') ?? 0) || 0;
const roll = params.get('roll');
const status = document.getElementById('status');
const canvas = document.getElementById('view');

window.viewerReady = false;
window.viewerErrors = [];
window.viewerInfo = null;
if (shot) {
  document.body.classList.add('shot');
  // Keep what the console says, so a test can fail on it even where it cannot read the console.
  for (const level of ['error', 'warn']) {
    const original = console[level].bind(console);
    console[level] = (...args) => { window.viewerErrors.push(`${level}: ${args.map(String).join(' ')}`); original(...args); };
  }
  addEventListener('error', (e) => window.viewerErrors.push(`error: ${e.message}`));
  addEventListener('unhandledrejection', (e) => window.viewerErrors.push(`error: ${e.reason}`));
}

// Blender's "Standard" view transform: linear radiance straight to sRGB, no tone curve.
const renderer = new THREE.WebGLRenderer({ canvas, antialias: true });
renderer.outputColorSpace = THREE.SRGBColorSpace;
renderer.toneMapping = THREE.NoToneMapping;
renderer.setPixelRatio(shot ? 1 : devicePixelRatio);
renderer.setClearColor(0x202124);

const scene = new THREE.Scene();
let camera = new THREE.PerspectiveCamera(50, 1, 0.01, 1000);
let cameraAspect = null; // the glTF camera's aspectRatio, when it has one
let baseFov = 50;
const controls = new OrbitControls(camera, canvas);
let model = null;
let probes = null; // DETP_light_probes: { grids, lit } and where each lit node started

const loader = new GLTFLoader();
loader.register((parser) => new MozLightmap(parser));
loader.register((parser) => new DetpProbes(parser));

function say(text) { status.textContent = text; }

// Vertical fov from the camera's own; a window narrower than the camera's aspect keeps the
// camera's horizontal extent instead (as Blender's automatic sensor fit does), so nothing is cut.
function resize() {
  const width = canvas.clientWidth, height = canvas.clientHeight;
  renderer.setSize(width, height, false);
  camera.aspect = width / height;
  let fov = baseFov;
  if (cameraAspect && camera.aspect < cameraAspect) {
    const halfWidth = Math.tan(THREE.MathUtils.degToRad(baseFov) / 2) * cameraAspect;
    fov = THREE.MathUtils.radToDeg(2 * Math.atan(halfWidth / camera.aspect));
  }
  camera.fov = fov;
  camera.updateProjectionMatrix();
}

// The glTF's first camera, moved out of the scene graph so OrbitControls can own it; the orbit
// centre is the point of the view axis nearest to the model's centre.
function useGltfCamera(source, box) {
  source.updateWorldMatrix(true, false);
  const view = new THREE.PerspectiveCamera(source.fov, source.aspect, source.near, source.far);
  source.matrixWorld.decompose(view.position, view.quaternion, new THREE.Vector3());
  const forward = new THREE.Vector3(0, 0, -1).applyQuaternion(view.quaternion);
  const centre = box.getCenter(new THREE.Vector3());
  const depth = Math.max(centre.clone().sub(view.position).dot(forward), source.near * 10);
  cameraAspect = source.aspect;
  return { view, target: view.position.clone().addScaledVector(forward, depth) };
}

function frameBox(box) {
  const sphere = box.getBoundingSphere(new THREE.Sphere());
  const radius = Math.max(sphere.radius, 1e-3);
  const view = new THREE.PerspectiveCamera(50, 1, radius / 100, radius * 100);
  const distance = radius / Math.sin(THREE.MathUtils.degToRad(50) / 2);
  view.position.copy(sphere.center).add(new THREE.Vector3(0.6, 0.45, 1).normalize().multiplyScalar(distance));
  cameraAspect = null;
  return { view, target: sphere.center.clone() };
}

function show(gltf, name) {
  if (model) {
    scene.remove(model);
    model.traverse((o) => { if (o.isMesh) { o.geometry.dispose(); } });
  }
  model = gltf.scene;
  scene.add(model);
  const box = new THREE.Box3().setFromObject(model);
  const { view, target } = gltf.cameras.length && gltf.cameras[0].isPerspectiveCamera
    ? useGltfCamera(gltf.cameras[0], box) : frameBox(box);
  camera = view;
  baseFov = view.fov;
  controls.object = camera;
  controls.target.copy(target);
  camera.lookAt(target);
  controls.update();
  resize();
  let lightmapped = 0, sh = 0, normalMapped = 0;
  const scaled = new Set();
  model.traverse((o) => {
    const materials = o.isMesh ? [].concat(o.material).filter((m) => m.userData?.lightmapped) : [];
    if (materials.length) lightmapped++;
    if (materials.some((m) => m.userData.sh)) sh++;
    if (materials.some((m) => m.userData.normalMapped)) normalMapped++;
    for (const m of materials) {
      // With Standard and no tone curve, Blender's exposure is this plain factor on the radiance.
      if (!scaled.has(m)) m.lightMapIntensity *= 2 ** exposure;
      scaled.add(m);
    }
  });
  probes = gltf.userData.probes ?? null;
  if (probes) {
    probes.start = probes.lit.map((node) => ({ position: node.position.clone(), rotation: node.rotation.z,
      radius: new THREE.Box3().setFromObject(node).getBoundingSphere(new THREE.Sphere()).radius || 1 }));
  }
  moveProbeLit(0);
  const probeLit = probes ? probes.lit.length : 0;
  window.viewerInfo = { model: name, lightmapped, sh, normalMapped, probeLit,
                        probeGrids: probes ? probes.grids.length : 0, camera: gltf.cameras.length ? 'gltf' : 'framed' };
  say(`${name}: ${lightmapped} lightmapped mesh${lightmapped === 1 ? '' : 'es'}${sh ? `, ${sh} with SH L1` : ''}` +
      `${probeLit ? `, ${probeLit} lit by light probes` : ''}`);
  if (shot) {
    // Two frames: the first compiles and draws, the second is certainly on screen.
    let frames = 0;
    const wait = () => {
      if (++frames < 3) { requestAnimationFrame(wait); return; }
      const error = renderer.getContext().getError();
      if (error !== 0) window.viewerErrors.push(`error: WebGL error 0x${error.toString(16)}`);
      window.viewerReady = true;
    };
    requestAnimationFrame(wait);
  }
}

// Roll the probe-lit nodes along the grid (the roll parameter), then aim their probe light.
function moveProbeLit(seconds) {
  if (!probes) return;
  if (roll !== null && probes.lit.length) {
    const phase = roll === 'auto' ? 1 - Math.abs(((seconds / 6) % 2) - 1) : Math.min(Math.max(Number(roll) || 0, 0), 1);
    const [low, high] = rollRange(probes);
    probes.lit.forEach((node, i) => {
      const start = probes.start[i];
      node.position.x = low + phase * (high - low);
      node.rotation.z = start.rotation - (node.position.x - start.position.x) / start.radius;
    });
  }
  updateProbeLit(probes, 2 ** exposure);
}

function failed(name, error) {
  console.error(`could not load ${name}:`, error);
  say(`could not load ${name}: ${error.message ?? error}`);
  if (shot) window.viewerReady = true; // the test reads viewerErrors
}

function loadUrl(url) {
  say(`loading ${url} …`);
  loader.load(url, (gltf) => show(gltf, url), undefined, (error) => failed(url, error));
}

function loadFile(file) {
  say(`loading ${file.name} …`);
  file.arrayBuffer()
    .then((buffer) => loader.parseAsync(buffer, ''))
    .then((gltf) => show(gltf, file.name), (error) => failed(file.name, error));
}

document.getElementById('file').addEventListener('change', (e) => {
  if (e.target.files.length) loadFile(e.target.files[0]);
});
addEventListener('dragover', (e) => { e.preventDefault(); document.body.classList.add('dragging'); });
addEventListener('dragleave', () => document.body.classList.remove('dragging'));
addEventListener('drop', (e) => {
  e.preventDefault();
  document.body.classList.remove('dragging');
  if (e.dataTransfer.files.length) loadFile(e.dataTransfer.files[0]);
});
addEventListener('resize', resize);

resize();
renderer.setAnimationLoop((time) => {
  controls.update();
  moveProbeLit(time / 1000);
  renderer.render(scene, camera);
});

if (params.get('model')) loadUrl(params.get('model'));
else say('no model: pass ?model=URL, pick a file or drop one');
