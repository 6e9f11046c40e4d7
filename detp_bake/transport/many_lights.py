"""Direct light from many lights (more than MANY_LIGHTS point, spot, sun and area lights): each
texel's shadow rays go where its light comes from, instead of a ray budget for every light at every
texel (800 point lights at 256²: 69.5 s of direct light against 0.2 s for one).

At each texel, every light's unshadowed contribution is weighed (direct_lights.light_weight, a few
flops a light). A light that gives more than LOW of the texel's total gets rays of its own, as
direct.py would give it (the part kept sharp for point, spot and sun lights: run/finishing.py); all
the others share twice `samples` rays, each drawing its light in proportion to its weight and counting
1/probability of it (unbiased, and exact where nothing is in the way, the weights being the lights'
own falloff; a light of negative power is drawn by its magnitude). That part goes to the denoised
direct light. Between LOW and HIGH a light's light is
split between the two by its share, so that neither part jumps from one texel to the next where a
light's share crosses a threshold. Cost per texel: one weight per light (float32 SIMD lanes) plus
at most 1/LOW lights' own rays and 2 × `samples` rays (in the 800-light room 39 rays a texel, its
direct light 0.4 % RMS off every light's own rays, which take 3,260); for thousands of lights a
tree of lights would weigh them faster.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from .direct_lights import POINT, SHARP_KINDS, light_ray, light_weight, radical_inverse2
from ..lightmap.texel_area import square_of, square_point
from ..sampling import jit, photon_rng, search_cdf, seed_key, uniform2

MANY_LIGHTS = 16  # more point, spot, sun and area lights than this: sampled per texel
LOW, HIGH = 0.15, 0.5  # a light's share of a texel's light from which it has rays of its own, and all of it
_OWN_MOST = int(1.0 / LOW)  # lights with rays of their own at one texel, at most
OWN, SOFT = 1, 0  # ray flags: the sharp part (own rays of SHARP_KINDS), the rest


@jit
def _point_rows(kinds, params):
    """The lights as point lights for `_point_weights` (float32 positions (3, m), |power|, size²)
    and the lights that are not plain point or sphere lights (weighed by light_weight)."""
    m = kinds.shape[0]
    at = np.empty((3, m), np.float32)
    power, size2 = np.zeros(m, np.float32), np.ones(m, np.float32)
    others = []
    for q in range(m):
        if kinds[q] == POINT and params[q, 12] <= 0.0:
            at[0, q], at[1, q], at[2, q] = params[q, 0], params[q, 1], params[q, 2]
            power[q] = abs(params[q, 3] + params[q, 4] + params[q, 5])
            size2[q] = params[q, 6] * params[q, 6]
        else:
            at[:, q] = 0.0
            others.append(q)
    return at, power, size2, np.array(others, np.int64)


@numba.njit(cache=True, nogil=True, fastmath=True)
def _point_weights(at, power, size2, x, y, z, nx, ny, nz, out):
    """light_weight of point and sphere lights at one point, in float32 and in SIMD lanes (the
    cost of many lights is here: 800 lights × 400k texels)."""
    for q in range(out.shape[0]):
        cx, cy, cz = at[0, q] - x, at[1, q] - y, at[2, q] - z
        d2 = max(cx * cx + cy * cy + cz * cz, np.float32(1e-30))
        c = (cx * nx + cy * ny + cz * nz) / math.sqrt(d2)
        out[q] = power[q] * max(c, np.float32(0.05)) / max(d2, size2[q])


@numba.njit(cache=True, nogil=True, fastmath=True)
def _sum(a):
    total = 0.0
    for v in a:
        total += v
    return total


@jit
def many_rays(kinds, params, counts, sharp_kind, samples, key, ids, n, pos, nrm, geo, eps, spread,
              sq_tri, sq_cx, sq_cy, sq_w, sq_h, cut_of, cut_p, cut_n, uvs, positions, o, d, t, w, owner, flag):
    """Shadow rays of texels 0 … n−1 for all the lights (rows `params`, kinds `kinds`): a light over
    LOW of a texel's weight `counts[q]` stratified rays of its own carrying its share s (1 from
    HIGH), flagged OWN where `sharp_kind[q]`; `samples` rays drawn among all lights by weight ×
    (1 − s), each counting 1/probability. Arrays as direct._shadow_rays; returns the ray count."""
    m = kinds.shape[0]
    weight32 = np.empty(m, np.float32)
    weight = np.empty(m)
    cdf = np.empty(m)
    at, power, size2, others = _point_rows(kinds, params)
    k = 0
    for i in range(n):
        nx, ny, nz = nrm[i, 0], nrm[i, 1], nrm[i, 2]
        gx, gy, gz = geo[i, 0], geo[i, 1], geo[i, 2]
        _point_weights(at, power, size2, np.float32(pos[i, 0]), np.float32(pos[i, 1]), np.float32(pos[i, 2]),
                       np.float32(nx), np.float32(ny), np.float32(nz), weight32)
        for q in range(m):
            weight[q] = weight32[q]
        for q in others:  # suns, spots and area lights
            weight[q] = abs(light_weight(kinds[q], params[q], pos[i, 0], pos[i, 1], pos[i, 2], nx, ny, nz))
        total = _sum(weight)
        if not total > 0.0:
            continue
        sq = square_of(spread, i, sq_tri, sq_cx, sq_cy, sq_w, sq_h, cut_of, cut_p, cut_n, uvs, positions, pos)
        state = photon_rng(key, ids[i])
        rest = 0.0
        for q in range(m):
            s = min(1.0, (weight[q] / total - LOW) / (HIGH - LOW))
            if s > 0.0:  # rays of its own, as direct.py gives them
                state, r0, r1 = uniform2(state)
                state, q0, q1 = uniform2(state)
                c = counts[q]
                for j in range(c):
                    px, py, pz = square_point(sq, j, c, q0, q1)
                    ox, oy, oz = px + eps * gx, py + eps * gy, pz + eps * gz
                    u0 = (j + 0.5) / c + r0
                    u1 = radical_inverse2(j) + r1
                    ok, dx, dy, dz, far, w0, w1, w2 = light_ray(kinds[q], params[q], ox, oy, oz, nx, ny, nz,
                                                                u0 - math.floor(u0), u1 - math.floor(u1), s / c)
                    if ok and far > 0.0:
                        o[k, 0], o[k, 1], o[k, 2] = ox, oy, oz
                        d[k, 0], d[k, 1], d[k, 2] = dx, dy, dz
                        t[k] = far
                        w[k, 0], w[k, 1], w[k, 2] = w0, w1, w2
                        owner[k] = i
                        flag[k] = OWN if sharp_kind[q] else SOFT
                        k += 1
            rest += weight[q] * (1.0 - max(s, 0.0))
            cdf[q] = rest
        if not rest > 1e-12 * total:
            continue
        state, r0, r1 = uniform2(state)
        state, q0, q1 = uniform2(state)
        for j in range(samples):
            px, py, pz = square_point(sq, j, samples, q0, q1)
            ox, oy, oz = px + eps * gx, py + eps * gy, pz + eps * gz
            q = min(search_cdf(cdf, (j + r0) / samples * rest), m - 1)  # stratified over the weights
            state, u0, u1 = uniform2(state)
            # f/p/samples with p = weight·(1 − s)/rest: the light's (1 − s) part cancels
            ok, dx, dy, dz, far, w0, w1, w2 = light_ray(kinds[q], params[q], ox, oy, oz, nx, ny, nz, u0, u1,
                                                        rest / (weight[q] * samples))
            if ok and far > 0.0:
                o[k, 0], o[k, 1], o[k, 2] = ox, oy, oz
                d[k, 0], d[k, 1], d[k, 2] = dx, dy, dz
                t[k] = far
                w[k, 0], w[k, 1], w[k, 2] = w0, w1, w2
                owner[k] = i
                flag[k] = SOFT
                k += 1
    return k


def _by_texel(n, owner, values) -> np.ndarray:
    """(n, columns): `values` (rays, columns) summed by their texel `owner`."""
    return np.stack([np.bincount(owner, weights=values[:, c], minlength=n) for c in range(values.shape[1])], axis=1)


class ManyLights:
    """The lights `indices` of direct.py's list, sampled together at each texel (many_rays)."""

    def __init__(self, lights, indices, samples, seed):
        self.indices = set(indices)
        chosen = [lights[i] for i in indices]
        self.kinds = np.array([l.kind for l in chosen], np.int64)
        self.params = np.ascontiguousarray([l.params for l in chosen], np.float64)
        self.counts = np.array([l.samples + l.extra for l in chosen], np.int64)
        self.sharp = np.array([l.kind in SHARP_KINDS for l in chosen], np.bool_)
        self.samples = 2 * int(samples)  # the drawn rays: 16 left the 800-light room's ceiling 1.1 % off, 32 0.7 %
        self.key = seed_key(seed * 7919 + 999331)

    def chunk(self, work, at, n, l1: bool, sharp_l1: bool) -> tuple:
        """Texels `at` (direct._DirectWork.inputs, n of them): their irradiance (n, 3), its sharp
        part (n, 3), and their L1 and its sharp part (n, 9) when asked (else None); the ray count."""
        ids, pos, nrm, geo, squares = at
        most = n * (self.samples + _OWN_MOST * int(self.counts.max()))
        o, d = np.empty((most, 3), np.float32), np.empty((most, 3), np.float32)
        t, w = np.empty(most, np.float32), np.empty((most, 3))
        owner, flag = np.empty(most, np.int64), np.empty(most, np.int8)
        k = many_rays(self.kinds, self.params, self.counts, self.sharp, self.samples, self.key, ids, n, pos, nrm,
                      geo, work.eps, work.spread, *squares, work.uvs, work.positions, o, d, t, w, owner, flag)
        if k == 0:
            z3 = np.zeros((n, 3))
            return z3, z3.copy(), np.zeros((n, 9)) if l1 else None, np.zeros((n, 9)) if sharp_l1 else None, 0
        o, d, t, w, owner, flag = o[:k], d[:k], t[:k], w[:k], owner[:k], flag[:k]
        arrived = work.arrived(o, d, t)
        got = w * arrived[:, None]
        own = got * (flag == OWN)[:, None]
        dirs = lambda v: (v[:, None, :] * d[:, :, None].astype(np.float64)).reshape(-1, 9)  # noqa: E731
        return (_by_texel(n, owner, got), _by_texel(n, owner, own), _by_texel(n, owner, dirs(got)) if l1 else None,
                _by_texel(n, owner, dirs(own)) if sharp_l1 else None, k)
