"""Direct light at every texel by sampling the lights with shadow rays (the first pass of the
classic two-pass split; docs/design.md, Denoising).

Direct light holds the hard shadows and most of the energy, and a density estimate blurs it over its
disc. Sampled here, it has no blur at all. Each ray starts at its own point of the texel's middle,
as Cycles' bake jitters a texel (texel_area.py): a point light or a sharp sun takes FIRST_SAMPLES
rays per texel, from the corners of its square (texel_area.square_corner: no straight edge crossing
it goes unseen), and where those disagree (a shadow edge or a spot's rim in the texel) `samples`
more, stratified over the square, which alone give its value;
a light with extent `samples` stratified rays (a Hammersley set, rotated per texel and light by a
random offset so neighbouring texels do not share a pattern). A texel's random numbers are keyed by
what it is (its object's name and its pixel: `texel_ids`), not by its place among the texels baked,
so its direct light does not change with the other objects baked alongside it. The photons then
carry only the indirect part (`PhotonTracer(indirect_only=True)`), which is smooth, so the
estimators' discs cost little accuracy there.

Units as everywhere in the core: irradiance E in W/m² (the bake stores E/π, Cycles' unit):
- point/spot light of power P: intensity P/(4π) W/sr; with a radius, a sphere of that power,
  sampled uniformly in the solid angle it subtends;
- sun: `irradiance` W/m² at normal incidence, its disc sampled uniformly in solid angle;
- area light: one-sided Lambertian of power P, radiance P/(πA), sampled uniformly over its area
  (the area cancels: each sample adds P/π · cosθ·cosθ'/d²);
- emissive triangles: both faces, radiance L; a triangle is picked in proportion to its power;
- world colour L: cosine-weighted directions, π·L when nothing is in the way.

Every light is sampled at every texel. Two or more lights with extent (sphere, spot, area, a sun's
disc) share `samples` rays each per texel, dealt out by what each would give the texel unshadowed
(light_shares, at least one ray each, so every light keeps an unbiased estimate): in the L-shaped
room 2.5-2.9× less noise² per second, in the window room (where the windows' shadows decide) the
same (benchmarks/lights.py). Texel chunks run on
worker threads: the ray generation and the sums are compiled (`nogil`), the occlusion test is one
embreex `run(query='OCCLUDED')` per chunk and light, which releases the GIL.
"""
from __future__ import annotations

import hashlib
import math
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Optional

import numpy as np

from ..errors import BakeCancelled
from .direct_lights import (AREA, FAR, MESH, POINT, SHARP_KINDS, SUN, WORLD_MAP, direct_lights, light_ray,
    light_weight, radical_inverse2, towards)
from .many_lights import MANY_LIGHTS, ManyLights
from ..sampling import cosine_hemisphere, jit, photon_rng, search_cdf, seed_key, uniform2, uniform_triangle
from .environment import environment_rays
from .scattering import MAX_PASSES
from ..scene import Scene
from .textures import opacity_at, surfaces
from ..lightmap.texel_area import PROBES, square_corner, square_of, square_point, texel_squares
from ..lightmap.texels import geometric_normals

CHUNK = 2048  # texels per work item
DEFAULT_SAMPLES = 16
DISAGREE = 0.05  # a sharp light adds rays where its first ones differ by more than this share (direct_lights)


@jit
def _shadow_rays(kind, prm, j0, samples, stride, sel, counts, key, ids, a, b, pos, nrm, geo, eps,
                 cdf, tpos, tnrm, trad, spread, sq_tri, sq_cx, sq_cy, sq_w, sq_h, cut_of, cut_p, cut_n, uvs, positions,
                 o, d, t, w, owner, probe=False):
    """Rays for texels a … b−1 and one light: origins `o` (each at its own point of the texel's
    square: texel_area.py; offset along the geometric normal `geo`), unit directions `d`, far
    limits `t`, and `w` the RGB irradiance each adds when unoccluded (already divided by the sample
    count); `owner` the texel. Rays that cannot add anything (light behind the surface, outside a
    spot cone) are left out. Returns the ray count. Samples j0 … j0 + samples − 1 of `stride`, for
    the texels `sel` when it is not empty (a top-up: direct_lights); `counts`, when not empty, is
    each texel's own number of samples instead (the light's share of them: light_shares). `probe`:
    samples 0 … PROBES − 1 start at the corners of the texel's square (texel_area.square_corner), for
    a light that adds rays where its first ones disagree."""
    k = 0
    todo = sel.shape[0] if sel.shape[0] > 0 else b - a
    for q in range(todo):
        i = sel[q] if sel.shape[0] > 0 else a + q
        if counts.shape[0] > 0:
            samples = counts[i - a]
            stride = samples
        inv_s = 1.0 / samples
        nx, ny, nz = nrm[i, 0], nrm[i, 1], nrm[i, 2]
        gx, gy, gz = geo[i, 0], geo[i, 1], geo[i, 2]
        state, r0, r1 = uniform2(photon_rng(key, ids[i]))
        state, q0, q1 = uniform2(state)
        sq = square_of(spread, i, sq_tri, sq_cx, sq_cy, sq_w, sq_h, cut_of, cut_p, cut_n, uvs, positions, pos)
        for j in range(j0, j0 + samples):
            if probe and j < PROBES:
                px, py, pz = square_corner(sq, j, stride, q0, q1)
            else:
                px, py, pz = square_point(sq, j, stride, q0, q1)
            ox, oy, oz = px + eps * gx, py + eps * gy, pz + eps * gz
            u0 = (j + 0.5) * inv_s + r0
            u0 -= math.floor(u0)
            u1 = radical_inverse2(j) + r1
            u1 -= math.floor(u1)
            w0 = w1 = w2 = 0.0
            dx = dy = dz = 0.0
            far = FAR
            if kind == POINT or kind == SUN or kind == AREA:
                ok, dx, dy, dz, far, w0, w1, w2 = light_ray(kind, prm, ox, oy, oz, nx, ny, nz, u0, u1, inv_s)
                if not ok:
                    continue
            elif kind == MESH:
                lo = search_cdf(cdf, u0)
                below = cdf[lo - 1] if lo > 0 else 0.0
                v0 = (u0 - below) / max(cdf[lo] - below, 1e-300)
                v0 = min(max(v0, 0.0), 0.999999999)
                b0, b1, b2 = uniform_triangle(v0, u1)
                dx, dy, dz, d2, dist, cos_x = towards(
                    b0 * tpos[lo, 0, 0] + b1 * tpos[lo, 1, 0] + b2 * tpos[lo, 2, 0] - ox,
                    b0 * tpos[lo, 0, 1] + b1 * tpos[lo, 1, 1] + b2 * tpos[lo, 2, 1] - oy,
                    b0 * tpos[lo, 0, 2] + b1 * tpos[lo, 1, 2] + b2 * tpos[lo, 2, 2] - oz, nx, ny, nz)
                if d2 <= 0.0:
                    continue
                cos_l = abs(dx * tnrm[lo, 0] + dy * tnrm[lo, 1] + dz * tnrm[lo, 2])
                if cos_x <= 0.0 or cos_l <= 0.0:
                    continue
                scale = cos_x * cos_l / d2 * inv_s
                w0, w1, w2 = trad[lo, 0] * scale, trad[lo, 1] * scale, trad[lo, 2] * scale
                far = dist * (1.0 - 1e-4) - eps  # stop short of the emitting triangle itself
            else:  # WORLD: cosine-weighted, π·L each
                dx, dy, dz = cosine_hemisphere(nx, ny, nz, u0, u1)
                if dx * gx + dy * gy + dz * gz <= 0.0:
                    continue
                scale = math.pi * inv_s
                w0, w1, w2 = prm[0] * scale, prm[1] * scale, prm[2] * scale
            if far <= 0.0:
                continue
            o[k, 0], o[k, 1], o[k, 2] = ox, oy, oz
            d[k, 0], d[k, 1], d[k, 2] = dx, dy, dz
            t[k] = far
            w[k, 0], w[k, 1], w[k, 2] = w0, w1, w2
            owner[k] = i
            k += 1
    return k


@jit
def light_shares(kinds, params, samples, a, b, pos, nrm, out):
    """out[i − a, m]: shadow rays of texel i for shared light m, out of samples × (number of lights):
    in proportion to the light's unshadowed irradiance at the texel's centre (a sphere or an area
    light as a point no closer than its size, a sun's axis), each light at least one ray so that
    every light keeps an unbiased estimate."""
    m = kinds.shape[0]
    budget = samples * m
    weight = np.empty(m)
    for i in range(a, b):
        nx, ny, nz = nrm[i, 0], nrm[i, 1], nrm[i, 2]
        total = 0.0
        for q in range(m):
            wq = light_weight(kinds[q], params[q], pos[i, 0], pos[i, 1], pos[i, 2], nx, ny, nz)
            weight[q] = wq
            total += wq
        left = budget - m
        for q in range(m):
            share = int(left * weight[q] / total + 0.5) if total > 0.0 else samples - 1
            out[i - a, q] = 1 + share


def _disagree(value: np.ndarray, texel: np.ndarray, n: int, samples: int) -> np.ndarray:
    """Per texel (0 … n−1), whether its rays' values (`value`, ray by ray; rays left out count as 0)
    differ by more than DISAGREE of the largest."""
    high = np.zeros(n)
    np.maximum.at(high, texel, value)
    low = np.full(n, np.inf)
    np.minimum.at(low, texel, value)
    low[np.bincount(texel, minlength=n) < samples] = 0.0
    return (high > 0.0) & (high - low > DISAGREE * high)


@jit
def _gather(n, occluded, w, owner, base, out):
    for k in range(n):
        if occluded[k] < 0:  # embreex: −1 where nothing is in the way
            i = owner[k] - base
            out[i, 0] += w[k, 0]
            out[i, 1] += w[k, 1]
            out[i, 2] += w[k, 2]


@jit
def _gather_l1(n, arrived, w, d, owner, base, out):
    """Directional lightmaps (lightmap/sh.py): each arriving ray's irradiance times its unit
    direction towards the light, into out[texel, axis·3 + colour]."""
    for k in range(n):
        if arrived[k] > 0.0:
            i = owner[k] - base
            for a in range(3):
                for c in range(3):
                    out[i, 3 * a + c] += w[k, c] * arrived[k] * d[k, a]


@jit
def _gather_weighted(n, transmitted, w, owner, base, out):
    for k in range(n):
        i = owner[k] - base
        out[i, 0] += w[k, 0] * transmitted[k]
        out[i, 1] += w[k, 1] * transmitted[k]
        out[i, 2] += w[k, 2] * transmitted[k]


@jit
def _opacities(prim, bu, bv, opacity, opacity_tex, tex_uvs, pixels, info):
    out = np.zeros(prim.shape[0])
    for k in range(prim.shape[0]):
        if prim[k] >= 0:
            out[k] = opacity_at(opacity, opacity_tex, tex_uvs, pixels, info, prim[k], np.float64(bu[k]),
                                np.float64(bv[k]))
    return out


def transmittance(caster, srf, o: np.ndarray, d: np.ndarray, far: np.ndarray, eps: float) -> np.ndarray:
    """The share of light that gets along each shadow ray through cut-out surfaces: the product of
    (1 − opacity) over the surfaces it meets, found layer by layer (each pass traces only the
    rays still going). Noise-free where a stochastic pass would be a coin toss."""
    n = len(far)
    out = np.ones(n)
    o = np.array(o, np.float32)
    left = np.array(far, np.float64)
    active = np.arange(n)
    for _ in range(MAX_PASSES):
        if active.size == 0:
            return out
        tf = left[active].astype(np.float32)
        r = caster.hits(np.ascontiguousarray(o[active]), np.ascontiguousarray(d[active]), tf)
        alpha = _opacities(r["primID"], r["u"], r["v"], srf.opacity, srf.opacity_tex, srf.tex_uvs, srf.pixels,
                           srf.info)
        out[active] *= 1.0 - alpha
        go = (r["primID"] >= 0) & (alpha < 1.0)
        idx = active[go]
        step = tf[go].astype(np.float64) + eps
        o[idx] += (step[:, None] * d[idx]).astype(np.float32)
        left[idx] -= step
        active = idx[left[idx] > 0.0]
    out[active] = 0.0  # past MAX_PASSES cut-outs: taken as blocked
    return out


def lightmap_keys(texels) -> np.ndarray:
    """(lightmaps,) uint64: each lightmap's part of its texels' random streams, from its name."""
    return np.array([np.frombuffer(hashlib.blake2b(lm.name.encode(), digest_size=8).digest(), np.uint64)[0]
                     for lm in texels.lightmaps], np.uint64)


def texel_ids(texels, a: int = 0, b: Optional[int] = None, keys: Optional[np.ndarray] = None) -> np.ndarray:
    """(b − a,) uint64: texels a … b−1's random streams (all texels by default), from their
    lightmap's name (`keys`: lightmap_keys, found once for a pass of many chunks) and their pixel.
    By range, so the direct pass builds them a chunk at a time."""
    b = len(texels) if b is None else b
    keys = lightmap_keys(texels) if keys is None else keys
    ids = np.empty(b - a, np.uint64)
    ends = np.array([lm.offset + lm.count for lm in texels.lightmaps], np.int64)
    for m in range(int(np.searchsorted(ends, a, side="right")), len(ends)):
        lm = texels.lightmaps[m]
        if lm.offset >= b:
            break
        lo, hi = max(a, lm.offset), min(b, lm.offset + lm.count)
        ids[lo - a:hi - a] = texels.pixel[lo:hi].astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15) + keys[m]
    return ids


class _DirectWork:
    """The shadow rays of one direct_irradiance call, chunk by chunk (`chunk`, from any thread):
    what every chunk reads (lights, the scene's arrays) is set up once here, what the kernels read
    per texel (random streams, geometric normals, squares) once per chunk (`inputs`)."""

    def __init__(self, scene, texels, caster, lights, samples, seed, spread, select, out, sharp, progress, cancel,
                 l1=None, sharp_l1=None, masked=None, mask=None, leave_out=True, many_from=MANY_LIGHTS):
        self.caster, self.lights, self.samples, self.seed, self.spread = caster, lights, samples, seed, spread
        self.out, self.sharp, self.progress, self.cancel, self.l1 = out, sharp, progress, cancel, l1
        self.sharp_l1 = sharp_l1
        # Shadow-masked lights: {index in `lights`: column of `mask`}; `leave_out`: their direct light
        # is left out of `out` (and of `l1`, `sharp`), kept in otherwise.
        self.masked, self.mask, self.leave_out = masked or {}, mask, leave_out
        n = len(texels)
        self.texels = texels
        self.pos = np.ascontiguousarray(texels.position, np.float64)
        self.nrm = np.ascontiguousarray(texels.normal, np.float64)
        self.keys = lightmap_keys(texels)
        # The texels' triangles' unit face normals, unflipped (towards 0), and which triangles they are:
        # geometric_normals' arithmetic on the same triangles, without its (N, 3) gather.
        used = np.zeros(len(scene.positions), bool)
        used[texels.triangle] = True
        self.faces = np.flatnonzero(used).astype(np.int32)
        self.face_normals = geometric_normals(scene, self.faces, np.zeros((len(self.faces), 3)))
        self.uvs = np.ascontiguousarray(scene.uvs, np.float32)
        self.positions = np.ascontiguousarray(scene.positions, np.float32)
        self.eps = scene.ray_offset()
        self.srf = surfaces(scene)
        # Many lights: sampled per texel by what each would give it (many_lights.py); else those with
        # extent share one budget per texel, by what each would give it unshadowed.
        many = [i for i, l in enumerate(lights) if l.kind in (POINT, SUN, AREA) and i not in self.masked]
        self.many = ManyLights(lights, many, samples, seed) if select and len(many) > many_from else None
        shared = [i for i, l in enumerate(lights) if l.kind in (POINT, SUN, AREA) and not l.extra and l.samples > 1
                  and (self.many is None or i not in self.many.indices)] if select else []
        self.shared = shared if len(shared) >= 2 else []
        self.kinds = np.array([lights[i].kind for i in self.shared], np.int64)
        self.params = np.array([lights[i].params for i in self.shared], np.float64) if self.shared \
            else np.zeros((0, 32))
        self.chunks = [(a, min(n, a + CHUNK)) for a in range(0, n, CHUNK)]
        self.rays = [0] * len(self.chunks)
        self.done = 0
        self.lock = threading.Lock()

    def inputs(self, a, b) -> tuple:
        """Texels a … b−1 as the kernels read them, row 0 being texel a: (ids, pos, nrm, geo,
        squares). Built chunk by chunk: for all texels at once they held 72 bytes a texel."""
        nrm = self.nrm[a:b]
        geo = self.face_normals[np.searchsorted(self.faces, self.texels.triangle[a:b])]
        geo[np.einsum("ij,ij->i", geo, nrm) < 0.0] *= -1.0  # to the shading normal's side, as geometric_normals
        return texel_ids(self.texels, a, b, self.keys), self.pos[a:b], nrm, geo, texel_squares(self.texels, a, b)

    def chunk(self, index) -> None:
        if self.cancel is not None and self.cancel():
            raise BakeCancelled()
        a, b = self.chunks[index]
        at = self.inputs(a, b)
        lights, shared, sharp = self.lights, self.shared, self.sharp
        most = (b - a) * max(max(l.samples, l.extra) for l in lights) * (len(shared) if shared else 1)
        most = 0 if self.many is not None and len(self.many.indices) == len(lights) else most
        buffers = (np.empty((most, 3), np.float32), np.empty((most, 3), np.float32), np.empty(most, np.float32),
                   np.empty((most, 3)), np.empty(most, np.int64))
        acc = np.zeros((b - a, 3))
        sharp_acc = np.zeros((b - a, 3)) if sharp is not None else None
        acc_l1 = np.zeros((b - a, 9)) if self.l1 is not None else None
        sharp_l1 = np.zeros((b - a, 9)) if self.sharp_l1 is not None else None
        shares = None
        if shared:
            shares = np.empty((b - a, len(shared)), np.int64)
            light_shares(self.kinds, self.params, self.samples, 0, b - a, at[1], at[2], shares)
        if self.many is not None:
            got, got_sharp, got_l1, got_sharp_l1, k = self.many.chunk(self, at, b - a, acc_l1 is not None,
                                                                     sharp_l1 is not None)
            self.rays[index] += k
            acc += got
            if sharp_acc is not None:
                sharp_acc += got_sharp
            if acc_l1 is not None:
                acc_l1 += got_l1
            if sharp_l1 is not None:
                sharp_l1 += got_sharp_l1
        for li, light in enumerate(lights):
            if self.many is not None and li in self.many.indices:
                continue
            counts = shares[:, shared.index(li)].copy() if li in shared else _NONE
            own, own_l1, free = self.light(index, at, buffers, li, light, counts)
            if li in self.masked:
                # Its shadow mask: the share of its unshadowed irradiance that arrives (1 where none would).
                got, could = own.sum(axis=1), free.sum(axis=1)
                self.mask[a:b, self.masked[li]] = np.where(could > 0.0, got / np.where(could > 0.0, could, 1.0), 1.0)
                if self.leave_out:
                    continue  # its direct light is the real light's times the mask (shadowmask mode)
            acc += own
            if acc_l1 is not None:
                acc_l1 += own_l1
            if sharp is not None and light.kind in SHARP_KINDS:
                sharp_acc += own
                if sharp_l1 is not None:
                    sharp_l1 += own_l1
        self.out[a:b] = acc
        if acc_l1 is not None:
            self.l1[a:b] = acc_l1
        if sharp_l1 is not None:
            self.sharp_l1[a:b] = sharp_l1
        if sharp is not None:
            sharp[a:b] = sharp_acc
        with self.lock:
            self.done += 1
            fraction = self.done / len(self.chunks)
        if self.progress is not None:
            self.progress(fraction)

    def light(self, index, at, buffers, li, light, counts):
        """One light's irradiance (n, 3) at chunk `index`'s texels, its L1 (n, 9) when asked, and
        for a masked light its irradiance were nothing in the way (n, 3); top-ups included."""
        a, b = self.chunks[index]
        key = seed_key(self.seed * 7919 + 1000003 * (li + 1))
        parts = lambda: [np.zeros((b - a, 3)), np.zeros((b - a, 9)) if self.l1 is not None else None,
                         np.zeros((b - a, 3)) if li in self.masked else None]
        own = parts()
        disagree = self.cast(index, at, buffers, light, key, 0, light.samples, _NONE, own[0], counts, own[1],
                             own[2])
        if light.extra:
            # A shadow edge, a spot's rim or the light's horizon crosses the texel's middle: its
            # corner probes disagree. Its value is then that of the added rays alone, stratified over
            # the square (the corners, on the square's rim, would weigh its rim too much).
            mixed = np.flatnonzero(disagree)
            if mixed.size:
                more = parts()
                self.cast(index, at, buffers, light, key, light.samples, light.extra, mixed.astype(np.int64),
                          more[0], None, more[1], more[2])
                for mine, extra in zip(own, more):
                    if mine is not None:
                        mine[mixed] = extra[mixed]
        return own

    def arrived(self, o, d, t) -> np.ndarray:
        """The share of each ray's light that arrives: 0 or 1, or through cut-outs a fraction."""
        if self.srf.cutout:
            return transmittance(self.caster, self.srf, o, d, t, self.eps)
        return (self.caster.occluded(o, d, t) < 0).astype(np.float64)

    def cast(self, index, at, buffers, light, key, j0, count, sel, into, counts=None, into_l1=None, into_free=None):
        """Rays of `light` (samples j0 … j0 + count − 1) for chunk `index` (its texels `at`, from
        `inputs`; `sel` counts from the chunk's first) into `into` (and their directions into
        `into_l1`, what they would bring unshadowed into `into_free`, when given); for a light with
        a top-up, which texels of the chunk its rays disagree on, else None."""
        a, b = self.chunks[index]
        n = b - a
        ids, pos, nrm, geo, squares = at
        o, d, t, w, owner = buffers
        counts = _NONE if counts is None else counts
        mesh = light.kind == MESH
        if light.kind == WORLD_MAP:
            k = environment_rays(*light.env, light.samples, key, ids, 0, n, pos, nrm, geo, self.eps,
                                 self.spread, *squares, self.uvs, self.positions, o, d, t, w, owner)
        else:
            k = _shadow_rays(light.kind, light.params, j0, count, light.samples + light.extra, sel, counts, key,
                             ids, 0, n, pos, nrm, geo, self.eps,
                             light.tri_cdf if mesh else _EMPTY_CDF, light.tri_pos if mesh else _EMPTY_TRI,
                             light.tri_normal if mesh else _EMPTY_VEC, light.tri_radiance if mesh else _EMPTY_VEC,
                             self.spread, *squares, self.uvs, self.positions, o, d, t, w, owner,
                             bool(light.extra) and j0 == 0)
        if k == 0:
            return np.zeros(n, bool) if light.extra else None
        if self.srf.cutout:
            passed = transmittance(self.caster, self.srf, o[:k], d[:k], t[:k], self.eps)
            _gather_weighted(k, passed, w, owner, 0, into)
            arrived = passed
        else:
            occluded = self.caster.occluded(o[:k], d[:k], t[:k])
            _gather(k, occluded, w, owner, 0, into)
            arrived = occluded < 0
        if into_l1 is not None:
            _gather_l1(k, np.asarray(arrived, np.float64), w, d, owner, 0, into_l1)
        if into_free is not None:
            _gather_weighted(k, np.ones(k), w, owner, 0, into_free)
        self.rays[index] += k
        return _disagree(w[:k].sum(axis=1) * arrived, owner[:k], n, count) if light.extra else None


_NONE = np.zeros(0, np.int64)  # no texels selected, no per-texel counts
_EMPTY_CDF, _EMPTY_TRI, _EMPTY_VEC = np.zeros(1), np.zeros((1, 3, 3)), np.zeros((1, 3))


def direct_irradiance(scene: Scene, texels, caster, samples: int = DEFAULT_SAMPLES, seed: int = 0,
                      threads: int = 1, progress: Optional[Callable[[float], None]] = None,
                      cancel: Optional[Callable[[], bool]] = None, spread: bool = True,
                      select: bool = True, sharp: Optional[np.ndarray] = None,
                      l1: Optional[np.ndarray] = None, sharp_l1: Optional[np.ndarray] = None,
                      shadowmask=(), mask: Optional[np.ndarray] = None,
                      leave_out: bool = True, many_from: int = MANY_LIGHTS) -> tuple[np.ndarray, dict]:
    """Direct irradiance E (N, 3) W/m² at every texel, and counters for report.json. Each chunk
    sums its texels' rays in float64 and stores them as float32: the value is only stored until
    the estimate is added to it, and float32 holds it to the precision of the lightmap images.

    `caster` is the `rays.RayCaster` of the scene's triangles (shared with the photon tracer).
    Deterministic for a seed whatever the thread count: every texel's numbers come from its own
    stream, and each texel is summed by one chunk. `spread`: rays start all over the texel's square
    (texel_area.py, as Cycles bakes), or all at its position (its centre, for closed-form checks).
    `select`: the lights with extent share `samples` rays each per texel, dealt out by what each
    would give the texel unshadowed (light_shares), instead of `samples` rays each. `sharp`, an
    (N, 3) float32 array when given, receives the part of point, spot and sun lights (SHARP_KINDS):
    their rays all agree away from penumbrae, so that part needs no denoising (finishing.Finishing). `l1`,
    an (N, 9) float32 array when given, receives the directional lightmap's L1 of the same rays
    (lightmap/sh.py: each arriving ray's irradiance times its direction, axis-major), and `sharp_l1`
    (with `sharp` and `l1`) the sharp lights' part of it. `shadowmask`: names of lights whose
    visibility goes into `mask` ((N, 4) float32, one column each, in that order): the share of the
    light's unshadowed irradiance that its shadow rays bring, 1 where it would bring none; with
    `leave_out` their direct light is left out of the result (the real light times the mask adds
    it back at render time). More than `many_from` point, spot, sun and area lights (not masked)
    are sampled per texel by what each gives it (many_lights.py)."""
    t0 = time.perf_counter()
    lights = direct_lights(scene, int(samples), spread)
    n = len(texels)
    out = np.zeros((n, 3), np.float32)
    if n == 0 or not lights:
        return out, {"lights": len(lights), "rays": 0, "seconds": 0.0}
    names = [light.name for light in lights]
    masked = {names.index(name): column for column, name in enumerate(shadowmask)}
    work = _DirectWork(scene, texels, caster, lights, samples, seed, spread, select, out, sharp, progress, cancel, l1,
                       sharp_l1 if sharp is not None and l1 is not None else None, masked, mask, leave_out, many_from)
    if threads > 1 and len(work.chunks) > 1:
        with ThreadPoolExecutor(threads) as pool:
            for f in [pool.submit(work.chunk, i) for i in range(len(work.chunks))]:
                f.result()
    else:
        for i in range(len(work.chunks)):
            work.chunk(i)
    cuts = getattr(texels, "cuts", None)
    if cuts is not None and cuts.covered is not None:
        # Against another face's front (a box's bottom on the floor): a ray leaving such a point
        # would start behind that face, and no light reaches it (validity.covered).
        out[cuts.covered] = 0.0
        if sharp is not None:
            sharp[cuts.covered] = 0.0
        for part in (l1, sharp_l1, mask):
            if part is not None:
                part[cuts.covered] = 0.0
    rays, shared = work.rays, work.shared
    info = {"lights": len(lights), "samples": int(samples), "rays": int(sum(rays)), "shared": len(shared),
            "seconds": time.perf_counter() - t0}
    if work.many is not None:
        info["sampled_per_texel"] = len(work.many.indices)
    return out, info
