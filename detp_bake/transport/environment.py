"""An environment map (an equirectangular HDRI world, Blender's Environment Texture) as a light:
photons from it and shadow rays towards it, both drawn in proportion to its brightness.

Directions map to the image as Cycles maps them, u = ½ − atan2(y, x)/2π and v = ½ + asin(z)/π (v = 1
at the zenith; row 0 of Blender's pixels is the nadir), after the world's Mapping rotation: the image
is read at R·ω for a world direction ω. A pixel is drawn with
probability ∝ luminance × sin θ (its solid angle), then a direction uniformly within it, so the
density over directions is p(ω) = P_pixel · W·H / (2π · π · sin θ). The radiance is the image times
the Background strength, in W/(m² sr) as Cycles reads it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .footprint import sky_areas, sky_start
from .emitter import Emitter
from ..sampling import inline, jit, photon_rng, search_cdf, uniform2
from ..lightmap.texel_area import square_of, square_point


@dataclass
class EnvironmentMap:
    """radiance: (H, W, 3) float32 linear W/(m² sr), row 0 the nadir; rotation: 3×3, the image is
    read at rotation @ ω."""
    radiance: np.ndarray
    rotation: np.ndarray

    def tables(self):
        """(pixels (H·W, 3), marginal cdf over rows (H,), conditional cdfs per row (H, W),
        pixel probabilities (H, W))."""
        img = np.ascontiguousarray(self.radiance, np.float64)
        h, w = img.shape[:2]
        lum = np.maximum(img.mean(axis=2), 0.0)
        theta = (np.arange(h)[::-1] + 0.5) / h * np.pi  # row 0 is the nadir: θ = π
        weight = lum * np.sin(theta)[:, None]
        if not np.any(weight > 0.0):
            weight = np.broadcast_to(np.sin(theta)[:, None], (h, w)).copy()
        rows = weight.sum(axis=1)
        marginal = np.cumsum(rows) / rows.sum()
        with np.errstate(invalid="ignore", divide="ignore"):
            cond = np.cumsum(weight, axis=1) / rows[:, None]
        cond[rows <= 0.0] = (np.arange(w) + 1.0) / w
        prob = weight / weight.sum()
        return img.reshape(-1, 3), marginal, np.ascontiguousarray(cond), prob

    def flux(self, radius: float) -> np.ndarray:
        """Flux crossing a disc of radius `radius` from all directions: πR² ∫ L dω."""
        return self.flux_through(lambda dirs: np.full(len(dirs), np.pi * radius ** 2))

    def flux_through(self, area) -> np.ndarray:
        """∫ L(ω) area(−ω) dω, pixel by pixel: the flux that crosses, from every direction, a start
        area of `area(travel directions (N, 3))` square metres facing it."""
        h, w = self.radiance.shape[:2]
        theta = (np.arange(h)[::-1] + 0.5) / h * np.pi
        phi = (0.5 - (np.arange(w) + 0.5) / w) * 2.0 * np.pi
        image = np.stack(np.broadcast_arrays(np.sin(theta)[:, None] * np.cos(phi)[None, :],
                                             np.sin(theta)[:, None] * np.sin(phi)[None, :],
                                             np.cos(theta)[:, None]), axis=-1).reshape(-1, 3)
        world = image @ np.asarray(self.rotation, np.float64)  # rotᵀ · image direction, row by row
        a = np.asarray(area(np.ascontiguousarray(-world)), np.float64).reshape(h, w)
        d_omega = (2 * np.pi / w) * (np.pi / h) * np.sin(theta)
        return np.einsum("hwc,hw,h->c", np.asarray(self.radiance, np.float64), a, d_omega)


@inline
def sample_direction(marginal, cond, prob, rot, u0, u1):
    """(world direction x, y, z, its density p(ω), pixel index) for two uniforms."""
    h, w = cond.shape[0], cond.shape[1]
    row = search_cdf(marginal, u0)
    below = marginal[row - 1] if row > 0 else 0.0
    fy = (u0 - below) / max(marginal[row] - below, 1e-300)
    col = search_cdf(cond[row], u1)
    left = cond[row, col - 1] if col > 0 else 0.0
    fx = (u1 - left) / max(cond[row, col] - left, 1e-300)
    u = (col + min(max(fx, 0.0), 1.0)) / w
    v = (row + min(max(fy, 0.0), 1.0)) / h
    phi = (0.5 - u) * 2.0 * math.pi  # atan2(y, x) of the image direction
    theta = (1.0 - v) * math.pi  # acos(z)
    st = math.sin(theta)
    lx, ly, lz = st * math.cos(phi), st * math.sin(phi), math.cos(theta)
    # World direction: rotᵀ · image direction (rot is a rotation).
    x = rot[0, 0] * lx + rot[1, 0] * ly + rot[2, 0] * lz
    y = rot[0, 1] * lx + rot[1, 1] * ly + rot[2, 1] * lz
    z = rot[0, 2] * lx + rot[1, 2] * ly + rot[2, 2] * lz
    pdf = prob[row, col] * w * h / (2.0 * math.pi * math.pi * max(st, 1e-12))
    return x, y, z, pdf, row * w + col


@jit
def _emit_environment(key, first, n, marginal, cond, prob, rot, pixels, lo, hi, centre, radius, scale, o, d, f, rng):
    """Photons from the map: arriving from ω (travelling −ω), starting on the geometry's box seen
    along ω (footprint.sky_start). Each carries L(ω)·area / (p(ω)·count) (`scale` = 1/count)."""
    for i in range(n):
        r = photon_rng(key, first + i)
        r, u0, u1 = uniform2(r)
        r, u2, u3 = uniform2(r)
        x, y, z, pdf, k = sample_direction(marginal, cond, prob, rot, u0, u1)
        dx, dy, dz = -x, -y, -z
        ox, oy, oz, area = sky_start(dx, dy, dz, lo, hi, centre, radius, u2, u3)
        o[i, 0], o[i, 1], o[i, 2] = ox, oy, oz
        d[i, 0], d[i, 1], d[i, 2] = dx, dy, dz
        w = scale * area / pdf
        f[i, 0], f[i, 1], f[i, 2] = pixels[k, 0] * w, pixels[k, 1] * w, pixels[k, 2] * w
        if rng.shape[0] > 0:
            rng[i] = r


def environment_emitter(env: EnvironmentMap, centre: np.ndarray, radius: float, lo=None, hi=None) -> Emitter:
    """The map's photons (see _emit_environment); its flux ∫ L(ω)·area(ω) dω summed pixel by pixel."""
    pixels, marginal, cond, prob = env.tables()
    rot = np.ascontiguousarray(env.rotation, np.float64)
    centre = np.asarray(centre, np.float64)
    lo = centre - radius if lo is None else np.asarray(lo, np.float64)
    hi = centre + radius if hi is None else np.asarray(hi, np.float64)
    flux = env.flux_through(lambda dirs: sky_areas(dirs, lo, hi, centre, float(radius)))

    def emit(key, first, n, total, o, d, f, rng):
        _emit_environment(key, first, n, marginal, cond, prob, rot, pixels, lo, hi, centre, float(radius),
                          1.0 / total, o, d, f, rng)

    return Emitter("world", flux, emit)


@jit
def environment_rays(marginal, cond, prob, rot, pixels, samples, key, ids, a, b, pos, nrm, geo, eps, spread,
                     sq_tri, sq_cx, sq_cy, sq_w, sq_h, cut_of, cut_p, cut_n, uvs, positions, o, d, t, w,
                     owner):
    """Shadow rays towards the map for texels a … b−1 (see direct._shadow_rays), each from its own
    point of the texel's square: each adds L(ω)·cos θ / (p(ω)·samples) when nothing is in the way."""
    k = 0
    inv_s = 1.0 / samples
    for i in range(a, b):
        nx, ny, nz = nrm[i, 0], nrm[i, 1], nrm[i, 2]
        gx, gy, gz = geo[i, 0], geo[i, 1], geo[i, 2]
        state, r0, r1 = uniform2(photon_rng(key, ids[i]))
        state, q0, q1 = uniform2(state)
        sq = square_of(spread, i, sq_tri, sq_cx, sq_cy, sq_w, sq_h, cut_of, cut_p, cut_n, uvs, positions, pos)
        for j in range(samples):
            u0 = (j + 0.5) * inv_s + r0
            u0 -= math.floor(u0)
            state, u1, _ = uniform2(state)
            u1 = u1 + r1
            u1 -= math.floor(u1)
            x, y, z, pdf, px = sample_direction(marginal, cond, prob, rot, u0, u1)
            cos_x = x * nx + y * ny + z * nz
            if cos_x <= 0.0 or x * gx + y * gy + z * gz <= 0.0 or pdf <= 0.0:
                continue
            scale = cos_x / pdf * inv_s
            sx, sy, sz = square_point(sq, j, samples, q0, q1)
            o[k, 0], o[k, 1], o[k, 2] = sx + eps * gx, sy + eps * gy, sz + eps * gz
            d[k, 0], d[k, 1], d[k, 2] = x, y, z
            t[k] = 1e37
            w[k, 0], w[k, 1], w[k, 2] = pixels[px, 0] * scale, pixels[px, 1] * scale, pixels[px, 2] * scale
            owner[k] = i
            k += 1
    return k
