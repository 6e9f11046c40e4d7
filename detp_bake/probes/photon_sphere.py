"""The paper's idea carried to a sphere: a probe's incident radiance from the photon path segments
that cross a small sphere around it (docs/probes.md, Estimators; benchmarks/probes.py measures it
against the final gather).

A segment of flux Φ travelling along d that enters the sphere of radius r around a probe crossed
its cross-section πr² from direction −d: it adds Φ/(πr²)·Y_k(−d) to c_k (radiance SH, sh9.py), the
way a DETP disc adds Φ/(πr²) for a segment that crosses it. The sphere is RADIUS of a cell's
shortest side (at most half of it, so it lies in its own cell); segments walk the grid's cells
(3D DDA in the grid's own index space, any box and rotation) and test the probes of the cells they
pass. With direct light sampled (the bake's default) the photons carry indirect light only, and the
probe's direct light comes from shadow rays and a gather of the sky and emitters (gather.py).
"""
from __future__ import annotations

import math

import numba
import numpy as np

from .sh9 import add_sh
from .validity import cell_width

RADIUS = 0.4  # the sphere's radius, in cell widths (at most 0.5)


class SphereGather:
    """Sums over photon batches for the probes of `grids` (their world positions less `offset`, the
    bake's centring); `add(batch)` per batch, `coefficients()` at the end (N, 9, 3)."""

    def __init__(self, grids, offset=None, radius: float = RADIUS, clear=None):
        """`clear` (N,): each probe's distance to the nearest surface (gather's `nearest`), when
        known: a sphere is shrunk to 0.9 of it, as a sphere a surface cuts counts the photons
        landing inside it and misses those leaving."""
        shift = np.zeros(3) if offset is None else np.asarray(offset, np.float64)
        self.counts = [len(g) for g in grids]
        self.to_index, self.res, self.dense = [], [], []
        radii = []
        first = 0
        for g in grids:
            m = g.matrix.copy()
            m[:3, 3] -= shift
            inv = np.linalg.inv(m)  # world → the unit cube; then (local + 1) / 2 · res → cell coordinates
            half_res = 0.5 * np.asarray(g.resolution, np.float64)
            to_index = np.diag(np.append(half_res, 1.0)) @ inv
            to_index[:3, 3] += half_res
            rx, ry, rz = g.resolution
            dense = np.full(rx * ry * rz, -1, np.int64)
            dense[g.linear_index] = first + np.arange(len(g))
            radii.append(np.full(len(g), min(radius, 0.5) * cell_width(g)))
            self.to_index.append(to_index)
            self.res.append(np.array(g.resolution, np.int64))
            self.dense.append(dense)
            first += len(g)
        r = np.concatenate(radii) if radii else np.zeros(0)
        if clear is not None:
            r = np.minimum(r, 0.9 * np.asarray(clear, np.float64))
        self.r2, self.inv_area = r * r, 1.0 / np.maximum(math.pi * r * r, 1e-300)
        self.positions = np.concatenate([g.positions for g in grids]) - shift if grids else np.zeros((0, 3))
        self.sums = np.zeros((first, 9, 3))
        self.crossings = np.zeros(first, np.int64)

    def add(self, batch) -> None:
        """One photon batch's segments (transport/photons.PhotonBatch)."""
        for i in range(len(self.res)):
            _cross(batch.seg_origin, batch.seg_dir, batch.seg_length, batch.seg_flux, self.to_index[i],
                   self.res[i], self.dense[i], self.positions, self.r2, self.inv_area, self.sums, self.crossings)

    def coefficients(self, share: float = 1.0) -> np.ndarray:
        """The coefficients (N, 9, 3): the sums over the share of the bake traced."""
        return self.sums / max(share, 1e-300)


@numba.njit(cache=True, nogil=True)
def _cross(origin, direction, length, flux, to_index, res, dense, centre, r2, inv_area, sums, crossings):
    """Every segment walked through the grid's cells (Amanatides and Woo), each probe of a cell it
    passes tested: a segment that enters its sphere adds flux/(πr²)·Y(−d)."""
    for s in range(origin.shape[0]):
        ox, oy, oz = np.float64(origin[s, 0]), np.float64(origin[s, 1]), np.float64(origin[s, 2])
        dx, dy, dz = np.float64(direction[s, 0]), np.float64(direction[s, 1]), np.float64(direction[s, 2])
        seg = np.float64(length[s])
        q = np.empty(3)
        v = np.empty(3)
        for a in range(3):
            q[a] = to_index[a, 0] * ox + to_index[a, 1] * oy + to_index[a, 2] * oz + to_index[a, 3]
            v[a] = to_index[a, 0] * dx + to_index[a, 1] * dy + to_index[a, 2] * dz
        t0, t1 = 0.0, seg  # clip to the box [0, res]³ in cell coordinates (t in metres along d)
        for a in range(3):
            if abs(v[a]) < 1e-300:
                if q[a] < 0.0 or q[a] > res[a]:
                    t1 = -1.0
                continue
            ta, tb = (0.0 - q[a]) / v[a], (res[a] - q[a]) / v[a]
            t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
        if t0 >= t1:
            continue
        cell = np.empty(3, np.int64)
        step = np.empty(3, np.int64)
        t_next = np.empty(3)
        t_delta = np.empty(3)
        for a in range(3):
            p = q[a] + v[a] * t0
            cell[a] = min(max(int(math.floor(p)), 0), res[a] - 1)
            if v[a] > 0.0:
                step[a], t_next[a], t_delta[a] = 1, t0 + (cell[a] + 1 - p) / v[a], 1.0 / v[a]
            elif v[a] < 0.0:
                step[a], t_next[a], t_delta[a] = -1, t0 + (cell[a] - p) / v[a], -1.0 / v[a]
            else:
                step[a], t_next[a], t_delta[a] = 0, 1e300, 1e300
        while True:
            j = dense[cell[0] + res[0] * (cell[1] + res[1] * cell[2])]
            if j >= 0:
                cx, cy, cz = centre[j, 0] - ox, centre[j, 1] - oy, centre[j, 2] - oz
                tc = cx * dx + cy * dy + cz * dz
                d2 = cx * cx + cy * cy + cz * cz - tc * tc
                if d2 < r2[j]:
                    enter = tc - math.sqrt(r2[j] - d2)
                    if 0.0 <= enter < seg:
                        w = inv_area[j]
                        add_sh(sums, j, -dx, -dy, -dz, flux[s, 0] * w, flux[s, 1] * w, flux[s, 2] * w)
                        crossings[j] += 1
            a = 0
            if t_next[1] < t_next[a]:
                a = 1
            if t_next[2] < t_next[a]:
                a = 2
            if t_next[a] >= t1:
                break
            cell[a] += step[a]
            if cell[a] < 0 or cell[a] >= res[a]:
                break
            t_next[a] += t_delta[a]
