"""Where parallel light can meet the scene: its footprint on a plane across the light's direction.

A sun photon that starts where no triangle lies ahead of it is traced for nothing. Outdoors the
scene's bounding disc is mostly sky (and grows with every light placed far away), so photons start
instead on the cells of a grid across the sun's direction that some triangle's projection covers
(conservatively: its projected bounding box, widened for the sun's angular size and by a margin the
caller asks for: DETP discs reach past a surface's edge by their radius). Every covered
cell has the same area, so the photons stay uniform per unit area and each carries E × the covered
area over the photon count: the irradiance is unchanged, and most photons hit something.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from .sampling import cone_lobe, in_frame, jit, photon_rng, uniform2

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
