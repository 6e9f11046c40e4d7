// GLTFLoader plugin for DETP_light_probes (docs/gltf.md): the bake's light probes, for what moves.
//
// Each grid's seven RGBA float16 buffer views are uploaded as they are, as 3D textures. A node that
// carries the extension gets an unlit material, base colour × E/π, where E/π is the SH L2 of the
// probes at the node's origin (the textures' trilinear filter between cells) read at the surface's
// world normal: probes/sh9.py's `irradiance`, the number Blender's probe-lit objects show.
// `updateProbeLit` moves that point as the node moves; call it every frame.
import {
  ClampToEdgeWrapping, Data3DTexture, HalfFloatType, LinearFilter, LinearSRGBColorSpace, Matrix4,
  RGBAFormat, ShaderMaterial, Vector3,
} from 'three';

const NAME = 'DETP_light_probes';
const TEXTURES = 7;

const VERTEX = /* glsl */ `
varying vec3 vDetpNormal;
void main() {
  vDetpNormal = normalize(transpose(inverse(mat3(modelMatrix))) * normal);
  gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0);
}`;

// sh9.py's basis constants, each band times the clamped cosine's factor over π (1, 2/3, 1/4).
const FRAGMENT = /* glsl */ `
precision highp sampler3D;
uniform sampler3D detpSh[${TEXTURES}];
uniform vec3 detpUvw;
uniform vec3 detpBase;
uniform float detpIntensity;
varying vec3 vDetpNormal;
void main() {
  vec4 t0 = texture(detpSh[0], detpUvw), t1 = texture(detpSh[1], detpUvw), t2 = texture(detpSh[2], detpUvw);
  vec4 t3 = texture(detpSh[3], detpUvw), t4 = texture(detpSh[4], detpUvw), t5 = texture(detpSh[5], detpUvw);
  vec4 t6 = texture(detpSh[6], detpUvw);
  vec3 c0 = t0.rgb, c1 = vec3(t0.a, t1.rg), c2 = vec3(t1.ba, t2.r), c3 = t2.gba;
  vec3 c4 = t3.rgb, c5 = vec3(t3.a, t4.rg), c6 = vec3(t4.ba, t5.r), c7 = t5.gba, c8 = t6.rgb;
  vec3 n = normalize(vDetpNormal);
  if (!gl_FrontFacing) n = -n;
  float x = n.x, y = n.y, z = n.z;
  vec3 e = 0.282095 * c0
    + (2.0 / 3.0) * 0.488603 * (c1 * y + c2 * z + c3 * x)
    + 0.25 * (1.092548 * (c4 * x * y + c5 * y * z + c7 * x * z)
              + 0.315392 * c6 * (3.0 * z * z - 1.0) + 0.546274 * c8 * (x * x - y * y));
  gl_FragColor = vec4(detpBase * max(e, 0.0) * detpIntensity, 1.0);
  #include <tonemapping_fragment>
  #include <colorspace_fragment>
}`;

class ProbeGrid {
  constructor(def, textures) {
    this.name = def.name;
    this.matrix = new Matrix4().fromArray(def.matrix);
    this.inverse = this.matrix.clone().invert();
    this.volume = Math.abs(this.matrix.determinant());
    this.textures = textures;
  }

  // The point in the grid's texture coordinates (cell i's centre at (i + 0.5) / resolution).
  uvw(point) {
    return point.clone().applyMatrix4(this.inverse).addScalar(1).multiplyScalar(0.5);
  }

  // How far the point lies outside the grid's box (0: inside), in world units.
  distance(point) {
    const local = point.clone().applyMatrix4(this.inverse);
    local.clampScalar(-1, 1);
    return local.applyMatrix4(this.matrix).distanceTo(point);
  }
}

// The grid a point reads, as probes/lookup.py `grid_for`: the smallest holding it, else the nearest.
function gridFor(grids, point) {
  let best = null, key = null;
  for (const grid of grids) {
    const k = [grid.distance(point), grid.volume];
    if (best === null || k[0] < key[0] - 1e-9 || (Math.abs(k[0] - key[0]) <= 1e-9 && k[1] < key[1])) {
      best = grid;
      key = k;
    }
  }
  return best;
}

function texture3d(buffer, [rx, ry, rz]) {
  const texture = new Data3DTexture(new Uint16Array(buffer), rx, ry, rz);
  texture.format = RGBAFormat;
  texture.type = HalfFloatType;
  texture.colorSpace = LinearSRGBColorSpace;
  texture.minFilter = texture.magFilter = LinearFilter;
  texture.wrapS = texture.wrapT = texture.wrapR = ClampToEdgeWrapping;
  texture.generateMipmaps = false;
  texture.unpackAlignment = 1;
  texture.needsUpdate = true;
  return texture;
}

function probeMaterial(source, grids) {
  const material = new ShaderMaterial({
    name: source.name,
    vertexShader: VERTEX,
    fragmentShader: FRAGMENT,
    uniforms: {
      detpSh: { value: grids[0].textures },
      detpUvw: { value: new Vector3(0.5, 0.5, 0.5) },
      detpBase: { value: new Vector3(source.color.r, source.color.g, source.color.b) },
      detpIntensity: { value: 1 },
    },
  });
  material.userData = { probeLit: true };
  source.dispose();
  return material;
}

export class DetpProbes {
  constructor(parser) {
    this.parser = parser;
    this.name = NAME;
  }

  async afterRoot(result) {
    const json = this.parser.json;
    const sceneIndex = json.scene ?? 0;
    const ext = json.scenes?.[sceneIndex]?.extensions?.[NAME];
    if (!ext) return;
    const grids = [];
    for (const def of ext.grids) {
      if (def.format !== 'RGBA16F') throw new Error(`${NAME}: unsupported format '${def.format}'`);
      if (def.textures.length !== TEXTURES) throw new Error(`${NAME}: a grid needs ${TEXTURES} textures`);
      const buffers = await Promise.all(def.textures.map((v) => this.parser.getDependency('bufferView', v)));
      grids.push(new ProbeGrid(def, buffers.map((b) => texture3d(b, def.resolution))));
    }
    const lit = [];
    result.scene.traverse((object) => {
      const ref = this.parser.associations.get(object);
      if (ref?.nodes === undefined || !json.nodes[ref.nodes].extensions?.[NAME]) return;
      object.traverse((mesh) => {
        if (!mesh.isMesh) return;
        mesh.material = Array.isArray(mesh.material)
          ? mesh.material.map((m) => probeMaterial(m, grids)) : probeMaterial(mesh.material, grids);
      });
      lit.push(object);
    });
    result.userData.probes = { grids, lit };
  }
}

// Point each probe-lit node's materials at the probes around its origin now; `intensity` scales
// the light (the viewer's exposure).
export function updateProbeLit(probes, intensity = 1) {
  if (!probes) return;
  const origin = new Vector3();
  for (const node of probes.lit) {
    node.updateWorldMatrix(true, false);
    node.getWorldPosition(origin);
    const grid = gridFor(probes.grids, origin);
    const uvw = grid.uvw(origin);
    node.traverse((mesh) => {
      if (!mesh.isMesh) return;
      for (const m of [].concat(mesh.material)) {
        if (!m.userData.probeLit) continue;
        m.uniforms.detpSh.value = grid.textures;
        m.uniforms.detpUvw.value.copy(uvw);
        m.uniforms.detpIntensity.value = intensity;
      }
    });
  }
}

// The x extent of the first grid's box, in world units: where the viewer rolls a probe-lit node.
export function rollRange(probes) {
  const grid = probes.grids[0];
  const xs = [-1, 1].flatMap((x) => [-1, 1].flatMap((y) => [-1, 1].map((z) =>
    new Vector3(x, y, z).applyMatrix4(grid.matrix).x)));
  return [Math.min(...xs), Math.max(...xs)];
}
