"""The final gather: each probe's incident light from rays cast over its whole sphere, read off the
bake's own lightmaps, plus shadow rays to the lights (docs/probes.md, Estimators).

A gather ray from probe p in direction ω (stratified over the sphere, rotated per probe) brings the
radiance of what it meets: on a surface's front face its albedo times the lightmap's E/π there
(bilinear, the lightmap as written: denoised and dilated) plus its emission; on a back face its
emission only (and it counts against the probe's validity, validity.py); on a miss the sky (the
world colour or its HDRI). The lights without surfaces (point, spot, sun, area) are sampled by
shadow rays from the probe, `samples` each, as the lightmaps' direct light is (transport/
direct_lights.py); a light in `masked` (a shadowmask light) adds nothing to the coefficients but
its arrived share to `occlusion` (and its first bounce, which the lightmaps then lack, is
added at the gather rays' hits: masked_bounce.py). Rays are made and summed in compiled kernels, a chunk of probes
at a time; Embree traces each chunk's rays in one call.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..rays import RayCaster
from ..sampling import inline, jit, photon_rng, seed_key, uniform2, uniform_sphere
from ..transport.direct_lights import AREA, POINT, SUN, direct_lights, light_ray, radical_inverse2
from ..transport.textures import CLOSEST, EXTEND, Textures, hit_uv, lookup, surfaces
from . import masked_bounce
from .sh9 import add_sh

CHUNK_RAYS = 1 << 18  # gather rays per Embree call
FOUR_PI = 4.0 * math.pi
@jit
def sphere_rays(pos, a, b, rays, key, o, d):
    """`rays` directions per probe a … b−1, stratified over the sphere (a Hammersley set rotated by
    the probe's own random offset): origins `o`, unit directions `d`, probe by probe."""
    inv = 1.0 / rays
    for i in range(a, b):
        _, r0, r1 = uniform2(photon_rng(key, i))
        for j in range(rays):
            k = (i - a) * rays + j
            u0 = (j + 0.5) * inv + r0
            u0 -= math.floor(u0)
            u1 = radical_inverse2(j) + r1
            u1 -= math.floor(u1)
            x, y, z = uniform_sphere(u0, u1)
            o[k, 0], o[k, 1], o[k, 2] = pos[i, 0], pos[i, 1], pos[i, 2]
            d[k, 0], d[k, 1], d[k, 2] = x, y, z


@inline
def sky(world, env_on, env_pixels, env_rot, env_h, env_w, x, y, z):
    """The sky's radiance seen along unit direction (x, y, z): the world colour, or the HDRI's pixel
    (environment.py's layout: row 0 the nadir, read at rot @ ω)."""
    if not env_on:
        return world[0], world[1], world[2]
    lx = env_rot[0, 0] * x + env_rot[0, 1] * y + env_rot[0, 2] * z
    ly = env_rot[1, 0] * x + env_rot[1, 1] * y + env_rot[1, 2] * z
    lz = env_rot[2, 0] * x + env_rot[2, 1] * y + env_rot[2, 2] * z
    theta = math.acos(min(max(lz, -1.0), 1.0))
    phi = math.atan2(ly, lx)
    u = 0.5 - phi / (2.0 * math.pi)
    v = 1.0 - theta / math.pi
    col = min(max(int(math.floor(u * env_w)), 0), env_w - 1)
    row = min(max(int(math.floor(v * env_h)), 0), env_h - 1)
    p = row * env_w + col
    return env_pixels[p, 0], env_pixels[p, 1], env_pixels[p, 2]


@jit
def shade_rays(rays, d, prim, bu, bv, tfar, normals, albedo, emission, uvs, lm_of, lm_pixels, lm_info,
               alb_tex, tex_uvs, tex_pixels, tex_info, world, env_on, env_pixels, env_rot, env_h, env_w,
               coeff, back, near_t, near_d, nearest):
    """Each gather ray's radiance, projected: coeff[i] += L·4π/rays·Y(ω) (i: the probe in the chunk). A
    back-face hit counts in back[i], and the nearest one's distance and direction are kept (virtual offset)."""
    n = d.shape[0]
    scale = FOUR_PI / rays
    for k in range(n):
        i = k // rays
        x, y, z = np.float64(d[k, 0]), np.float64(d[k, 1]), np.float64(d[k, 2])
        t = prim[k]
        if t < 0:
            r, g, bl = sky(world, env_on, env_pixels, env_rot, env_h, env_w, x, y, z)
        else:
            if tfar[k] < nearest[i]:
                nearest[i] = tfar[k]
            u, v = np.float64(bu[k]), np.float64(bv[k])
            w = 1.0 - u - v
            nx = w * normals[t, 0, 0] + u * normals[t, 1, 0] + v * normals[t, 2, 0]
            ny = w * normals[t, 0, 1] + u * normals[t, 1, 1] + v * normals[t, 2, 1]
            nz = w * normals[t, 0, 2] + u * normals[t, 1, 2] + v * normals[t, 2, 2]
            r, g, bl = emission[t, 0], emission[t, 1], emission[t, 2]  # both faces, as Cycles
            if nx * x + ny * y + nz * z > 0.0:
                back[i] += 1
                if tfar[k] < near_t[i]:
                    near_t[i] = tfar[k]
                    near_d[i, 0], near_d[i, 1], near_d[i, 2] = x, y, z
            elif lm_of[t] >= 0:
                s, q = hit_uv(uvs, t, u, v)
                ar, ag, ab = albedo[t, 0], albedo[t, 1], albedo[t, 2]
                if alb_tex[t] >= 0:
                    ts, tq = hit_uv(tex_uvs, t, u, v)
                    ar *= lookup(tex_pixels, tex_info, alb_tex[t], ts, tq, 0)
                    ag *= lookup(tex_pixels, tex_info, alb_tex[t], ts, tq, 1)
                    ab *= lookup(tex_pixels, tex_info, alb_tex[t], ts, tq, 2)
                m = lm_of[t]
                r += ar * lookup(lm_pixels, lm_info, m, s, q, 0)
                g += ag * lookup(lm_pixels, lm_info, m, s, q, 1)
                bl += ab * lookup(lm_pixels, lm_info, m, s, q, 2)
        add_sh(coeff, i, x, y, z, r * scale, g * scale, bl * scale)


@jit
def light_rays(kind, prm, pos, a, b, samples, key, salt, o, d, t, w, owner):
    """`samples` shadow rays from each probe a … b−1 to one POINT, SUN or AREA light: the radiance
    weight (L·dω/pdf over the samples) each brings when nothing is in the way. light_ray gives
    irradiance on a normal; the normal is chosen so that its cosine is never 0 over the light
    (towards a point's centre, a sun's axis, against an area light's face) and divided out."""
    k = 0
    inv_s = 1.0 / samples
    for i in range(a, b):
        px, py, pz = pos[i, 0], pos[i, 1], pos[i, 2]
        if kind == POINT:
            cx, cy, cz = prm[0] - px, prm[1] - py, prm[2] - pz
            length = math.sqrt(cx * cx + cy * cy + cz * cz)
            if length <= 0.0:
                continue
            nx, ny, nz = cx / length, cy / length, cz / length
        elif kind == SUN:
            nx, ny, nz = prm[0], prm[1], prm[2]
        else:
            nx, ny, nz = -prm[12], -prm[13], -prm[14]
        _, r0, r1 = uniform2(photon_rng(key, i * 7919 + salt))
        for j in range(samples):
            u0 = (j + 0.5) * inv_s + r0
            u0 -= math.floor(u0)
            u1 = radical_inverse2(j) + r1
            u1 -= math.floor(u1)
            ok, dx, dy, dz, far, w0, w1, w2 = light_ray(kind, prm, px, py, pz, nx, ny, nz, u0, u1, inv_s)
            cos_x = dx * nx + dy * ny + dz * nz
            if not ok or cos_x <= 0.0 or far <= 0.0:
                continue
            o[k, 0], o[k, 1], o[k, 2] = px, py, pz
            d[k, 0], d[k, 1], d[k, 2] = dx, dy, dz
            t[k] = far
            w[k, 0], w[k, 1], w[k, 2] = w0 / cos_x, w1 / cos_x, w2 / cos_x
            owner[k] = i - a
            k += 1
    return k


@jit
def add_light(n, occluded, d, w, owner, coeff, into_sh, seen, arrived, column):
    """Shadow rays' weights into the coefficients (`into_sh`) or, for a shadowmask light, its
    luminance into seen/arrived[:, column] (occlusion = arrived / seen)."""
    for k in range(n):
        i = owner[k]
        lum = (w[k, 0] + w[k, 1] + w[k, 2]) / 3.0
        if column >= 0:
            seen[i, column] += lum
        if occluded[k] >= 0:
            continue
        if column >= 0:
            arrived[i, column] += lum
        if into_sh:
            add_sh(coeff, i, np.float64(d[k, 0]), np.float64(d[k, 1]), np.float64(d[k, 2]), w[k, 0], w[k, 1],
                   w[k, 2])


@dataclass
class Lighting:
    """What a gather reads, built once per bake: the lightmaps as one texture set (lm_of: each
    triangle's lightmap, −1 where its object has none), the scene's surfaces, the sky, the lights."""
    scene: object
    caster: RayCaster
    lm_of: np.ndarray
    lightmaps: Textures
    lights: list
    masked: tuple
    leave_out: bool  # the masked lights' direct light is left out of the coefficients
    key: np.uint64
    surfaces: object
    sky: tuple  # (world colour, env on, env pixels, env rotation, env height, env width)


def lighting(scene, caster: RayCaster, images: dict, samples: int, seed: int, masked=(),
             leave_out: bool = True) -> Lighting:
    """The gather's inputs from a bake: `images` {lightmap name: (H, W, 3) E/π, row 0 at the
    bottom}, named by the object or by its atlas (BakeObject.image). `masked`: shadowmask lights,
    whose direct light is left out of the coefficients with `leave_out` (subtract mode)."""
    names = list(images)
    lm_of = np.full(max(scene.triangle_count, 1), -1, np.int32)
    for obj in scene.objects:
        key = obj.image or obj.name
        if key in images:
            lm_of[obj.triangles] = names.index(key)
    packed = Textures.pack([images[n] for n in names] or [np.zeros((1, 1, 3), np.float32)],
                           [EXTEND] * max(len(names), 1), [CLOSEST] * max(len(names), 1))
    lights = [lt for lt in direct_lights(scene, samples, spread=False) if lt.kind in (POINT, SUN, AREA)]
    for lt in lights:
        lt.samples = samples
    env = scene.world_map
    sky_of = (np.asarray(scene.world, np.float64), env is not None,
              np.zeros((1, 3)) if env is None else np.ascontiguousarray(env.radiance, np.float64).reshape(-1, 3),
              np.eye(3) if env is None else np.ascontiguousarray(env.rotation, np.float64),
              *((1, 1) if env is None else env.radiance.shape[:2]))
    return Lighting(scene, caster, lm_of, packed, lights, tuple(masked), bool(leave_out), seed_key(seed), surfaces(scene), sky_of)


def gather(lit: Lighting, positions: np.ndarray, rays: int, progress=None) -> dict:
    """Coefficients (N, 9, 3) of probes at `positions` (the scene's coordinates) with `rays` gather
    rays each, and per probe its back-face share, nearest back face (distance, direction) and each
    shadowmask light's occlusion. `progress(fraction)` between chunks (it may raise to cancel)."""
    n = len(positions)
    pos = np.ascontiguousarray(positions, np.float64)
    out = {"coefficients": np.zeros((n, 9, 3)), "back": np.zeros(n, np.int64),
           "near_t": np.full(n, np.inf), "near_d": np.zeros((n, 3)), "nearest": np.full(n, np.inf),
           "seen": np.zeros((n, len(lit.masked))), "arrived": np.zeros((n, len(lit.masked)))}
    step = max(1, CHUNK_RAYS // max(rays, 1))
    for a in range(0, n, step):
        b = min(a + step, n)
        _gather_chunk(lit, pos, a, b, rays, out)
        _lights_chunk(lit, pos, a, b, out)
        if progress is not None:
            progress(b / n)
    out["back_share"] = out["back"] / max(rays, 1)
    seen = out.pop("seen")
    out["occlusion"] = np.where(seen > 0.0, out.pop("arrived") / np.maximum(seen, 1e-300), 1.0)
    return out


def _gather_chunk(lit: Lighting, pos, a, b, rays, out) -> None:
    scene, m = lit.scene, (b - a) * rays
    o, d = np.empty((m, 3), np.float32), np.empty((m, 3), np.float32)
    sphere_rays(pos, a, b, rays, lit.key, o, d)
    tfar = np.full(m, 1e37, np.float32)
    hit = lit.caster.hits(o, d, tfar)
    sf = lit.surfaces
    shade_rays(rays, d, hit["primID"], hit["u"], hit["v"], hit["tfar"], scene.normals, scene.albedo,
               scene.emission, scene.uvs, lit.lm_of, lit.lightmaps.pixels, lit.lightmaps.info, sf.albedo_tex,
               sf.tex_uvs, sf.pixels, sf.info, *lit.sky, out["coefficients"][a:b], out["back"][a:b],
               out["near_t"][a:b], out["near_d"][a:b], out["nearest"][a:b])
    if lit.leave_out and lit.masked:  # the lightmaps lack the masked lights' direct light: its bounce here
        masked_bounce.add(lit, o, d, hit, rays, out["coefficients"][a:b], salt=a)


def _lights_chunk(lit: Lighting, pos, a, b, out) -> None:
    for number, light in enumerate(lit.lights):
        m = (b - a) * light.samples
        o, d = np.empty((m, 3), np.float32), np.empty((m, 3), np.float32)
        t, w, owner = np.empty(m, np.float32), np.empty((m, 3)), np.empty(m, np.int64)
        k = light_rays(light.kind, light.params, pos, a, b, light.samples, lit.key, number, o, d, t, w, owner)
        if k == 0:
            continue
        occluded = lit.caster.occluded(o[:k], d[:k], t[:k])
        column = lit.masked.index(light.name) if light.name in lit.masked else -1
        add_light(k, occluded, d, w, owner, out["coefficients"][a:b], column < 0 or not lit.leave_out, out["seen"][a:b],
                  out["arrived"][a:b], column)
