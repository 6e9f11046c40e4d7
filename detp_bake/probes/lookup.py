"""Reading a bake's probes where something moves: the SH at a point, and the grids as dense arrays a
GPU samples as 3D textures.

`at` is what Blender's probe-lit objects and the viewer agree on: a point's SH is the trilinear
blend of the eight probes around it, those absent or invalid left out and the weights of the rest
made to sum to one (Unity's probe volumes do the same, so a probe inside a wall leaks nothing).
`dense` fills every cell, absent and invalid ones from their valid neighbours, so a GPU's own
trilinear filter of the textures (`textures`) gives nearly the same blend with no per-cell test.
"""
from __future__ import annotations

import numpy as np

from . import sh9
from .grid import ProbeGrid

TEXTURES = 7  # RGBA textures that hold the 27 numbers of a cell; the last alpha is the cell's validity


def local(grid: ProbeGrid, points: np.ndarray) -> np.ndarray:
    """(M, 3) world points in the grid's unit cube [−1, 1]³."""
    inverse = np.linalg.inv(grid.matrix)
    return np.asarray(points, dtype=np.float64) @ inverse[:3, :3].T + inverse[:3, 3]


def grid_for(grids: list[ProbeGrid], point: np.ndarray) -> ProbeGrid:
    """The grid a point reads: the smallest that holds it, else the one whose box is nearest."""
    def distance(g):
        q = local(g, np.asarray(point, dtype=np.float64)[None])[0]
        inside = np.clip(q, -1.0, 1.0)
        world = np.append(inside, 1.0) @ g.matrix.T
        return np.linalg.norm(world[:3] - point), abs(np.linalg.det(g.matrix[:3, :3]))
    return min(grids, key=distance)


def _cells(grid: ProbeGrid) -> np.ndarray:
    """(rz, ry, rx) probe number of each cell, −1 where none is or it is invalid."""
    rx, ry, rz = grid.resolution
    cells = np.full(rx * ry * rz, -1, dtype=np.int64)
    number = np.arange(len(grid))
    cells[grid.linear_index[grid.valid]] = number[grid.valid]
    return cells.reshape(rz, ry, rx)


def at(grids: list[ProbeGrid], points: np.ndarray) -> np.ndarray:
    """(M, 9, 3) SH at world `points` (M, 3): for each, the grid `grid_for` picks, trilinear between
    its valid probes around the point (clamped to the box); where all eight are missing, the nearest
    valid probe; zeros where a grid has none."""
    points = np.atleast_2d(np.asarray(points, dtype=np.float64))
    out = np.zeros((len(points), sh9.COEFFICIENTS, 3))
    for m, point in enumerate(points):
        grid = grid_for(grids, point)
        if not grid.valid.any():
            continue
        res = np.asarray(grid.resolution)
        u = np.clip((local(grid, point[None])[0] + 1.0) * 0.5 * res - 0.5, 0.0, res - 1)
        base = np.minimum(np.floor(u).astype(np.int64), res - 1)
        frac = u - base
        corners = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)])
        cell = np.minimum(base + corners, res - 1)
        weight = np.prod(np.where(corners == 1, frac, 1.0 - frac), axis=1)
        probe = _cells(grid)[cell[:, 2], cell[:, 1], cell[:, 0]]
        weight = np.where(probe >= 0, weight, 0.0)
        if weight.sum() <= 1e-12:
            valid = np.flatnonzero(grid.valid)
            nearest = valid[np.argmin(np.linalg.norm(grid.positions[valid] - point, axis=1))]
            out[m] = grid.coefficients[nearest]
            continue
        out[m] = np.einsum("p,pkc->kc", weight / weight.sum(), grid.coefficients[np.maximum(probe, 0)])
    return out


def dense(grid: ProbeGrid) -> tuple[np.ndarray, np.ndarray]:
    """The grid as (rz, ry, rx, 9, 3) float32 coefficients, x fastest, every cell filled, and
    (rz, ry, rx) float32 validity (1: a valid probe, 0: filled). A missing cell takes the mean of
    its filled face neighbours, ring after ring outwards from the valid probes."""
    rx, ry, rz = grid.resolution
    values = np.zeros((rz, ry, rx, sh9.COEFFICIENTS * 3))
    cells = _cells(grid)
    filled = cells >= 0
    values[filled] = grid.coefficients[cells[filled]].reshape(-1, sh9.COEFFICIENTS * 3)
    validity = filled.astype(np.float32)
    while filled.any() and not filled.all():
        total = np.zeros_like(values)
        count = np.zeros(filled.shape)
        for axis in range(3):
            for step in (1, -1):
                shifted_v = np.roll(values * filled[..., None], step, axis=axis)
                shifted_f = np.roll(filled, step, axis=axis).astype(np.float64)
                edge = [slice(None)] * 3
                edge[axis] = 0 if step == 1 else -1
                shifted_v[tuple(edge)] = 0.0  # no wrapping round the box
                shifted_f[tuple(edge)] = 0.0
                total += shifted_v
                count += shifted_f
        grow = ~filled & (count > 0)
        values[grow] = total[grow] / count[grow][:, None]
        filled = filled | grow
    return values.reshape(rz, ry, rx, sh9.COEFFICIENTS, 3).astype(np.float32), validity


def textures(grid: ProbeGrid, dtype=np.float16) -> np.ndarray:
    """(7, rz, ry, rx, 4) the dense grid as seven RGBA 3D textures: the 27 numbers of a cell in
    order (coefficient k's red, green, blue are numbers 3k, 3k + 1, 3k + 2; texture t channel c holds
    number 4t + c), the 28th the cell's validity. Each texture's bytes are x fastest, then y, then z."""
    values, validity = dense(grid)
    rz, ry, rx = validity.shape
    flat = np.concatenate([values.reshape(rz, ry, rx, 27), validity[..., None]], axis=-1)
    return np.ascontiguousarray(flat.reshape(rz, ry, rx, TEXTURES, 4).transpose(3, 0, 1, 2, 4)).astype(dtype)


def rotated(coefficients: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """Coefficients (..., 9, 3) of the same light seen in axes turned by `rotation` (3, 3): a
    direction d becomes rotation @ d. SH L2 is closed under rotation, so the matrix found by least
    squares on a few dozen directions is exact to rounding."""
    golden = np.pi * (3.0 - np.sqrt(5.0))
    i = np.arange(64) + 0.5
    z = 1.0 - 2.0 * i / 64
    d = np.stack([np.sqrt(1 - z * z) * np.cos(golden * i), np.sqrt(1 - z * z) * np.sin(golden * i), z], axis=1)
    before, after = sh9.basis(d), sh9.basis(d @ np.asarray(rotation, dtype=np.float64).T)
    m = np.linalg.lstsq(before, after, rcond=None)[0].T  # after_k(d) = Σ_j m_kj before_j(d)
    # c'_k = ∫ L(d) Y_k(R d) dd = Σ_j m_kj c_j
    return np.einsum("kj,...jc->...kc", m, np.asarray(coefficients, dtype=np.float64))
