"""Where parallel light can meet the scene: its footprint on a plane across the light's direction.

A sun photon that starts where no triangle lies ahead of it is traced for nothing. Outdoors the
scene's bounding disc is mostly sky (and grows with every light placed far away), so photons start
instead on the cells of a grid across the sun's direction that some triangle's projection covers
(conservatively: its projected bounding box, widened for the sun's angular size and by a margin the
caller asks for: DETP discs reach past a surface's edge by their radius). Every covered
cell has the same area, so the photons stay uniform per unit area and each carries E × the covered
area over the photon count: the irradiance is unchanged, and most photons hit something.

Sky photons (a world colour or an HDRI) each have a direction of their own, so a grid per direction
would not pay: each starts instead on the geometry's bounding box as seen along its direction,
and carries L·area/p(ω), the area being that view's (never more than the bounding disc's).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from ..sampling import (cone_lobe, in_frame, inline, jit, orthonormal_basis, photon_rng, uniform2,
    uniform_disc, uniform_sphere)

GRID = 256  # cells along each side of the footprint's bounding rectangle


@dataclass
class Footprint:
    """Covered cells of a grid in the plane spanned by (t, s), which is perpendicular to the light."""
    origin: np.ndarray  # 3D point of the grid's corner (cell (0, 0)), 2 radii upstream of the scene
    t: np.ndarray
    s: np.ndarray
    cell: float  # cell side, metres
    cells: np.ndarray  # (K, 2) int64 covered cell coordinates

    @property
    def area(self) -> float:
        return len(self.cells) * self.cell * self.cell

    @staticmethod
    def build(positions: np.ndarray, axis: np.ndarray, frame: tuple, centre: np.ndarray, radius: float,
              half_angle: float = 0.0, margin: float = 0.0) -> "Footprint":
        t, s = np.asarray(frame[0], np.float64), np.asarray(frame[1], np.float64)
        p = np.asarray(positions, np.float64).reshape(-1, 3, 3)
        u = p @ t
        v = p @ s
        lo_u, hi_u = u.min(axis=1), u.max(axis=1)
        lo_v, hi_v = v.min(axis=1), v.max(axis=1)
        # A direction up to half_angle off the axis, over the scene's depth (4 radii at most from
        # the start plane), shifts where a triangle is met by up to 4R·tan(half_angle).
        widen = 4.0 * radius * math.tan(half_angle) if half_angle > 0.0 else 0.0
        widen += margin
        u0, u1 = lo_u.min() - widen, hi_u.max() + widen
        v0, v1 = lo_v.min() - widen, hi_v.max() + widen
        cell = max(u1 - u0, v1 - v0, 1e-9) / GRID
        covered = np.zeros((GRID + 1, GRID + 1), np.bool_)
        _cover(((lo_u - widen - u0) / cell), ((hi_u + widen - u0) / cell), ((lo_v - widen - v0) / cell),
               ((hi_v + widen - v0) / cell), covered)
        cells = np.argwhere(covered).astype(np.int64)
        axis = np.asarray(axis, np.float64)
        depth = float(np.dot(np.asarray(centre, np.float64), axis)) - 2.0 * radius
        origin = u0 * t + v0 * s + depth * axis
        return Footprint(origin, t, s, cell, np.ascontiguousarray(cells))


@numba.njit(cache=True)
def _cover(a0, a1, b0, b1, covered):
    n = covered.shape[0]
    for k in range(a0.shape[0]):
        i0 = max(int(math.floor(a0[k])), 0)
        i1 = min(int(math.floor(a1[k])), n - 1)
        j0 = max(int(math.floor(b0[k])), 0)
        j1 = min(int(math.floor(b1[k])), n - 1)
        for i in range(i0, i1 + 1):
            for j in range(j0, j1 + 1):
                covered[i, j] = True


@jit
def emit_sun(key, first, n, frame, cos_max, origin, cell, cells, flux, o, d, f, rng):
    """Photons on the covered cells (uniform over their union), travelling along the frame's axis
    or within acos(cos_max) of it."""
    t, s, axis = frame
    m = cells.shape[0]
    for i in range(n):
        r = photon_rng(key, first + i)
        r, u0, u1 = uniform2(r)
        r, u2, u3 = uniform2(r)
        pick = u0 * m
        c = min(int(pick), m - 1)
        fu = pick - c  # the rest of u0 places the photon across its cell, with u1 along it
        cu = (cells[c, 0] + fu) * cell
        cv = (cells[c, 1] + u1) * cell
        if cos_max < 1.0:
            lx, ly, lz = cone_lobe(cos_max, u2, u3)
            dx, dy, dz = in_frame(lx, ly, lz, t, s, axis)
        else:
            dx, dy, dz = axis
        for k in range(3):
            o[i, k] = origin[k] + cu * t[k] + cv * s[k]
        d[i, 0], d[i, 1], d[i, 2] = dx, dy, dz
        f[i, 0], f[i, 1], f[i, 2] = flux[0], flux[1], flux[2]
        if rng.shape[0] > 0:
            rng[i] = r


@inline
def sky_start(dx, dy, dz, lo, hi, centre, radius, u, v):
    """Start of a photon travelling (dx, dy, dz), from two uniforms: uniform over the box [lo, hi]
    as seen along the direction (a point of one of the faces it enters through, chosen by their
    projected areas, which tile that view without overlap), moved 2 radii back, out of the
    scene. Returns the start and the projected area."""
    lx, ly, lz = hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]
    ax, ay, az = abs(dx) * ly * lz, abs(dy) * lx * lz, abs(dz) * lx * ly
    area = ax + ay + az
    if not area > 0.0:  # a point: the bounding sphere's disc
        t, s = orthonormal_basis(dx, dy, dz)
        px, py = uniform_disc(u, v)
        pa, pb = radius * px, radius * py
        return (centre[0] + pa * t[0] + pb * s[0] - 2.0 * radius * dx,
                centre[1] + pa * t[1] + pb * s[1] - 2.0 * radius * dy,
                centre[2] + pa * t[2] + pb * s[2] - 2.0 * radius * dz, math.pi * radius * radius)
    pick = u * area
    if pick < ax:
        f = pick / ax
        px = lo[0] if dx > 0.0 else hi[0]
        py, pz = lo[1] + f * ly, lo[2] + v * lz
    elif pick < ax + ay:
        f = min((pick - ax) / ay, 1.0)
        py = lo[1] if dy > 0.0 else hi[1]
        px, pz = lo[0] + f * lx, lo[2] + v * lz
    else:
        f = min((pick - ax - ay) / max(az, 1e-300), 1.0)
        pz = lo[2] if dz > 0.0 else hi[2]
        px, py = lo[0] + f * lx, lo[1] + v * ly
    return px - 2.0 * radius * dx, py - 2.0 * radius * dy, pz - 2.0 * radius * dz, area


@jit
def sky_areas(dirs, lo, hi, centre, radius):
    """The start area `sky_start` uses for each direction of travel in `dirs` (N, 3)."""
    out = np.empty(dirs.shape[0])
    for i in range(dirs.shape[0]):
        out[i] = sky_start(dirs[i, 0], dirs[i, 1], dirs[i, 2], lo, hi, centre, radius, 0.5, 0.5)[3]
    return out


def mean_sky_area(lo, hi, centre, radius, n: int = 16384) -> float:
    """The start area averaged over all directions (a Fibonacci sphere of n points)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = math.pi * (3.0 - math.sqrt(5.0)) * k
    rho = np.sqrt(1.0 - z * z)
    dirs = np.stack([rho * np.cos(phi), rho * np.sin(phi), z], axis=1)
    return float(sky_areas(dirs, lo, hi, centre, radius).mean())


@jit
def emit_sky(key, first, n, lo, hi, centre, radius, scale, o, d, f, rng):
    """Uniform sky radiance: directions uniform over the sphere, each photon L·area·4π/count
    (`scale` = L·4π/count, per channel)."""
    for i in range(n):
        r = photon_rng(key, first + i)
        r, u0, u1 = uniform2(r)
        r, u2, u3 = uniform2(r)
        dx, dy, dz = uniform_sphere(u2, u3)
        ox, oy, oz, area = sky_start(dx, dy, dz, lo, hi, centre, radius, u0, u1)
        o[i, 0], o[i, 1], o[i, 2] = ox, oy, oz
        d[i, 0], d[i, 1], d[i, 2] = dx, dy, dz
        f[i, 0], f[i, 1], f[i, 2] = scale[0] * area, scale[1] * area, scale[2] * area
        if rng.shape[0] > 0:
            rng[i] = r
