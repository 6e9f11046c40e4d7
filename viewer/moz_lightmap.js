// GLTFLoader plugin for MOZ_lightmap as detp_bake writes it: an RGBE PNG on the second UV set.
//
// The PNG's alpha is a shared exponent, not a coverage, so the browser must never see it as an
// image: premultiplying, colour-managing or sRGB-decoding it would change the numbers. The plugin
// therefore reads the PNG bytes itself (decodePng below), decodes RGBE to linear floats and uploads
// a half-float DataTexture. See docs/viewer.md.
import {
  ClampToEdgeWrapping, DataTexture, DataUtils, HalfFloatType, LinearFilter, LinearSRGBColorSpace,
  LoaderUtils, MeshBasicMaterial, MirroredRepeatWrapping, RepeatWrapping, RGBAFormat,
} from 'three';

const NAME = 'MOZ_lightmap';
const SH_NAME = 'DETP_lightmap_sh';
const HALF_MAX = 65504;
const WRAP = { 33071: ClampToEdgeWrapping, 33648: MirroredRepeatWrapping, 10497: RepeatWrapping };

// --- PNG (8-bit RGBA or RGB, not interlaced): enough for the lightmaps, and exact ---------------

const PNG_SIGNATURE = [137, 80, 78, 71, 13, 10, 26, 10];

async function inflate(bytes) {
  // PNG's IDAT stream is zlib-wrapped deflate, which DecompressionStream calls 'deflate'.
  const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream('deflate'));
  return new Uint8Array(await new Response(stream).arrayBuffer());
}

function paeth(a, b, c) {
  const p = a + b - c;
  const pa = Math.abs(p - a), pb = Math.abs(p - b), pc = Math.abs(p - c);
  if (pa <= pb && pa <= pc) return a;
  return pb <= pc ? b : c;
}

// Undo the per-row filters in place; returns the rows without their filter bytes.
function unfilter(raw, width, height, bpp) {
  const stride = width * bpp;
  const out = new Uint8Array(stride * height);
  for (let y = 0; y < height; y++) {
    const filter = raw[y * (stride + 1)];
    const src = y * (stride + 1) + 1;
    const row = y * stride, prev = row - stride;
    for (let x = 0; x < stride; x++) {
      const left = x >= bpp ? out[row + x - bpp] : 0;
      const up = y > 0 ? out[prev + x] : 0;
      const upLeft = y > 0 && x >= bpp ? out[prev + x - bpp] : 0;
      let v = raw[src + x];
      if (filter === 1) v += left;
      else if (filter === 2) v += up;
      else if (filter === 3) v += (left + up) >> 1;
      else if (filter === 4) v += paeth(left, up, upLeft);
      else if (filter !== 0) throw new Error(`PNG: unknown row filter ${filter}`);
      out[row + x] = v & 255;
    }
  }
  return out;
}

// The PNG's pixels as RGBA bytes, top row first, exactly as stored (no gamma, no profile).
export async function decodePng(buffer) {
  const bytes = new Uint8Array(buffer);
  const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  if (!PNG_SIGNATURE.every((b, i) => bytes[i] === b)) throw new Error('not a PNG image');
  let width = 0, height = 0, colourType = 0;
  const idat = [];
  for (let at = 8; at + 8 <= bytes.length;) {
    const length = view.getUint32(at);
    const type = String.fromCharCode(...bytes.subarray(at + 4, at + 8));
    const data = bytes.subarray(at + 8, at + 8 + length);
    if (type === 'IHDR') {
      width = view.getUint32(at + 8);
      height = view.getUint32(at + 12);
      const depth = data[8];
      colourType = data[9];
      if (depth !== 8 || (colourType !== 6 && colourType !== 2) || data[12] !== 0) {
        throw new Error(`PNG: lightmaps must be 8-bit RGBA, not interlaced (bit depth ${depth}, colour type ${colourType}, interlace ${data[12]})`);
      }
    } else if (type === 'IDAT') {
      idat.push(data);
    } else if (type === 'IEND') {
      break;
    }
    at += 12 + length;
  }
  const bpp = colourType === 6 ? 4 : 3;
  const pixels = unfilter(await inflate(new Blob(idat)), width, height, bpp);
  if (bpp === 4) return { width, height, data: pixels };
  const rgba = new Uint8Array(width * height * 4).fill(255);
  for (let i = 0, j = 0; i < pixels.length; i += 3, j += 4) rgba.set(pixels.subarray(i, i + 3), j);
  return { width, height, data: rgba };
}

// --- RGBE --------------------------------------------------------------------------------------

// Linear RGB of one RGBE texel, exactly as detp_bake/lightmap/encoding.py decodes it:
// byte · 2^(E − 136), i.e. byte / 256 · 2^(E − 128), with E = 0 black. The encoder rounds each
// mantissa to nearest, so there is no half-step to add back (Radiance's own +0.5 is for truncation).
export function decodeRgbe(r, g, b, e) {
  if (e === 0) return [0, 0, 0];
  const scale = Math.pow(2, e - 136);
  return [r * scale, g * scale, b * scale];
}

export function rgbeToHalfFloat(image) {
  const { width, height, data } = image;
  const half = new Uint16Array(width * height * 4);
  const one = DataUtils.toHalfFloat(1);
  for (let i = 0; i < width * height * 4; i += 4) {
    const rgb = decodeRgbe(data[i], data[i + 1], data[i + 2], data[i + 3]);
    for (let c = 0; c < 3; c++) half[i + c] = DataUtils.toHalfFloat(Math.min(rgb[c], HALF_MAX));
    half[i + 3] = one;
  }
  return half;
}

// --- DETP_lightmap_sh: L1/L0 per axis, 8 bits a channel (detp_bake/lightmap/encoding.py) ---------

// r = byte / 127.5 − 1, as encoding.ratio_decode; alpha (RGB PNGs have none) is set to 1.
export function ratioToHalfFloat(image) {
  const { width, height, data } = image;
  const half = new Uint16Array(width * height * 4);
  const one = DataUtils.toHalfFloat(1);
  for (let i = 0; i < width * height * 4; i += 4) {
    for (let c = 0; c < 3; c++) half[i + c] = DataUtils.toHalfFloat(data[i + c] / 127.5 - 1);
    half[i + 3] = one;
  }
  return half;
}

// detp_bake/lightmap/sh.py's shade() per colour channel, for the ratio r = L1/L0 (world, glTF's
// axes), the surface's normal n and the shading normal s: L0 back where s = n.
const SHADE_GLSL = /* glsl */ `
uniform sampler2D detpL1x;
uniform sampler2D detpL1y;
uniform sampler2D detpL1z;
varying vec3 vDetpNormal;
float detpShade(float l0, vec3 r, vec3 n, vec3 s) {
  const float h = 2.0 / 3.0;
  float rn = dot(r, n);
  float qa = h * h - 1.0, qb = 2.0 * h * (rn - h), qc = dot(r, r) - 2.0 * h * rn + h * h;
  float a = clamp((-qb - sqrt(max(qb * qb - 4.0 * qa * qc, 0.0))) / (2.0 * qa), 0.0, 1.0);
  vec3 d = r - (1.0 - a) * h * n;
  d /= max(length(d), 1e-8);
  float towards = max(dot(s, d), 0.0) / max(dot(n, d), 0.05);
  return l0 * (a * towards + (1.0 - a) * 0.5 * (1.0 + dot(s, n)));
}
`;

// The glTF normalTexture's normal in world space. No TANGENT attribute is exported, so the frame
// comes from how world position and the map's UV change across the pixel: the gradients of u and
// v along the surface, which point along t = dp/du and b = dp/dv wherever the UVs are not skewed.
const NORMAL_MAP_GLSL = /* glsl */ `
uniform sampler2D detpNormalMap;
uniform float detpNormalScale;
varying vec3 vDetpWorld;
varying vec2 vDetpNormalUv;
vec3 detpMappedNormal(vec3 n) {
  vec3 dpx = dFdx(vDetpWorld), dpy = dFdy(vDetpWorld);
  vec2 dux = dFdx(vDetpNormalUv), duy = dFdy(vDetpNormalUv);
  vec3 cx = cross(dpy, n), cy = cross(n, dpx);
  // the gradients are these over n · (dpx × dpy): keep its sign, which normalising would lose
  float side = dot(n, cross(dpx, dpy)) < 0.0 ? -1.0 : 1.0;
  vec3 gu = side * (cx * dux.x + cy * duy.x), gv = side * (cx * dux.y + cy * duy.y);
  gu *= inversesqrt(max(dot(gu, gu), 1e-30));
  gv *= inversesqrt(max(dot(gv, gv), 1e-30));
  vec3 m = texture2D(detpNormalMap, vDetpNormalUv).xyz * 2.0 - 1.0;
  m.xy *= detpNormalScale;
  // glTF's +y is the image's up, where v (origin at the top-left) decreases
  vec3 s = gu * m.x - gv * m.y + n * m.z;
  return dot(s, s) > 0.0 ? normalize(s) : n;
}
`;

// The unlit material's lightmap read through shade(): n is the interpolated vertex normal in world
// space; n' is the glTF normalTexture's normal where the material has one (`normal`: three's
// texture as GLTFLoader loaded it, and the glTF scale), else n again, which gives L0: the plain lightmap.
function shadeWithSh(material, [x, y, z], normal = null) {
  const mapped = normal !== null;
  material.onBeforeCompile = (shader) => {
    Object.assign(shader.uniforms, { detpL1x: { value: x }, detpL1y: { value: y }, detpL1z: { value: z } });
    let vertex = 'vDetpNormal = transformNormalByInverseViewMatrix(normalMatrix * normal, viewMatrix);';
    if (mapped) {
      normal.texture.updateMatrix();
      Object.assign(shader.uniforms, {
        detpNormalMap: { value: normal.texture },
        detpNormalMapTransform: { value: normal.texture.matrix },
        detpNormalScale: { value: normal.scale },
      });
      const uv = ['uv', 'uv1', 'uv2', 'uv3'][normal.texture.channel] ?? 'uv';
      vertex += `\nvDetpWorld = (modelMatrix * vec4(transformed, 1.0)).xyz;
vDetpNormalUv = (detpNormalMapTransform * vec3(${uv}, 1.0)).xy;`;
    }
    const varyings = 'varying vec3 vDetpNormal;' +
      (mapped ? '\nvarying vec3 vDetpWorld;\nvarying vec2 vDetpNormalUv;\nuniform mat3 detpNormalMapTransform;' : '');
    shader.vertexShader = shader.vertexShader
      .replace('#include <common>', `#include <common>\n${varyings}`)
      .replace('#include <begin_vertex>', `#include <begin_vertex>\n${vertex}`);
    shader.fragmentShader = shader.fragmentShader
      .replace('#include <common>', `#include <common>\n${SHADE_GLSL}${mapped ? NORMAL_MAP_GLSL : ''}`)
      .replace('vec4 lightMapTexel = texture2D( lightMap, vLightMapUv );', `vec4 lightMapTexel = texture2D( lightMap, vLightMapUv );
    {
      vec3 n = normalize(vDetpNormal);
      if (!gl_FrontFacing) n = -n;
      vec3 s = ${mapped ? 'detpMappedNormal(n)' : 'n'};
      vec3 rx = texture2D(detpL1x, vLightMapUv).rgb, ry = texture2D(detpL1y, vLightMapUv).rgb;
      vec3 rz = texture2D(detpL1z, vLightMapUv).rgb;
      for (int c = 0; c < 3; c++) {
        lightMapTexel[c] = detpShade(lightMapTexel[c], vec3(rx[c], ry[c], rz[c]), n, s);
      }
    }`);
  };
  material.customProgramCacheKey = () => `${SH_NAME}${mapped ? ' normal map' : ''}`;
  material.userData.sh = true;
  material.userData.normalMapped = mapped;
}

// --- the plugin ----------------------------------------------------------------------------------

export class MozLightmap {
  constructor(parser) {
    this.parser = parser;
    this.name = NAME;
    this.textures = new Map(); // texture index -> Promise<DataTexture>, shared by materials
    this.sh = new Map(); // glTF material index -> its DETP_lightmap_sh textures [x, y, z]
  }

  async imageBytes(imageIndex) {
    const def = this.parser.json.images[imageIndex];
    if (def.bufferView !== undefined) return this.parser.getDependency('bufferView', def.bufferView);
    const url = LoaderUtils.resolveURL(def.uri, this.parser.options.path);
    const response = await fetch(url);
    if (!response.ok) throw new Error(`${NAME}: ${url}: HTTP ${response.status}`);
    return response.arrayBuffer();
  }

  loadLightmap(textureIndex, texCoord, toHalf = rgbeToHalfFloat) {
    const key = `${textureIndex}:${texCoord}:${toHalf.name}`;
    if (!this.textures.has(key)) {
      this.textures.set(key, (async () => {
        const textureDef = this.parser.json.textures[textureIndex];
        const image = await decodePng(await this.imageBytes(textureDef.source));
        const texture = new DataTexture(toHalf(image), image.width, image.height, RGBAFormat, HalfFloatType);
        // glTF's UV origin is the image's top-left and decodePng returns the top row first.
        texture.flipY = false;
        texture.colorSpace = LinearSRGBColorSpace;
        texture.channel = texCoord;
        texture.magFilter = LinearFilter;
        texture.minFilter = LinearFilter; // no mipmaps: half-float mipmap generation is not portable
        texture.generateMipmaps = false;
        const sampler = this.parser.json.samplers?.[textureDef.sampler] ?? {};
        texture.wrapS = WRAP[sampler.wrapS] ?? RepeatWrapping;
        texture.wrapT = WRAP[sampler.wrapT] ?? RepeatWrapping;
        texture.name = this.parser.json.images[textureDef.source].name ?? `lightmap ${textureIndex}`;
        texture.needsUpdate = true;
        return texture;
      })());
    }
    return this.textures.get(key);
  }

  // The glTF material's lightmap, kept for afterRoot; the loader still builds its usual material.
  async extendMaterialParams(materialIndex, params) {
    const ext = this.parser.json.materials[materialIndex].extensions?.[NAME];
    if (!ext) return;
    const encoding = ext.extras?.encoding ?? 'RGBE';
    if (encoding !== 'RGBE') throw new Error(`${NAME}: unsupported encoding '${encoding}'`);
    params.lightMap = await this.loadLightmap(ext.index, ext.texCoord ?? 0);
    // three.js reads a lightMap as irradiance E and shows albedo × E / π; ours hold E/π already.
    params.lightMapIntensity = Math.PI * (ext.intensity ?? 1);
    const sh = this.parser.json.materials[materialIndex].extensions?.[SH_NAME];
    if (!sh) return;
    if (sh.encoding !== 'L1/L0 8-bit') throw new Error(`${SH_NAME}: unsupported encoding '${sh.encoding}'`);
    this.sh.set(materialIndex, await Promise.all(
      sh.l1.map((index) => this.loadLightmap(index, sh.texCoord ?? 1, ratioToHalfFloat))));
  }

  // Every lightmapped mesh gets an unlit material: base colour (factor × texture) × lightmap, as
  // Blender's Apply shows it, so the scene is lit by its lightmaps alone.
  afterRoot(result) {
    const unlit = new Map();
    for (const scene of result.scenes) {
      scene.traverse((object) => {
        if (!object.isMesh) return;
        const swap = (material) => {
          const ref = this.parser.associations.get(material);
          if (ref?.materials === undefined || !this.parser.json.materials[ref.materials].extensions?.[NAME]) return material;
          if (!unlit.has(material)) {
            // The normal map GLTFLoader loaded for the source material outlives it (dispose()
            // frees the material's programs, not its textures); its scale is the glTF's, unflipped.
            const def = this.parser.json.materials[ref.materials];
            const normal = material.normalMap && def.normalTexture
              ? { texture: material.normalMap, scale: def.normalTexture.scale ?? 1 } : null;
            const made = toUnlit(material);
            if (this.sh.has(ref.materials)) shadeWithSh(made, this.sh.get(ref.materials), normal);
            unlit.set(material, made);
          }
          return unlit.get(material);
        };
        object.material = Array.isArray(object.material) ? object.material.map(swap) : swap(object.material);
      });
    }
  }
}

function toUnlit(source) {
  const material = new MeshBasicMaterial({
    name: source.name,
    color: source.color.clone(),
    map: source.map,
    lightMap: source.lightMap,
    lightMapIntensity: source.lightMapIntensity,
    opacity: source.opacity,
    transparent: source.transparent,
    alphaTest: source.alphaTest,
    depthWrite: source.depthWrite,
    side: source.side,
    vertexColors: source.vertexColors,
  });
  material.userData = { ...source.userData, lightmapped: true };
  source.dispose();
  return material;
}
