"""No light through walls: a probe whose gather rays meet back faces is inside geometry or behind a
wall (a closed mesh's inside, under a one-sided floor), and what it gathered is not what an object
there would receive.

Such a probe (more than BACK_LIMIT of its rays on back faces) is moved out (virtual offset): along
the direction of its nearest back face, through that face and PUSH cells' widths beyond it, when the
face is within SEARCH cells' widths, then gathered again there. A probe still invalid after that
takes the mean of its valid neighbours' coefficients (the 26 cells around it), and stays marked
invalid (`ProbeGrid.valid`), so that a loader interpolating between probes leaves it out.
"""
from __future__ import annotations

import numba
import numpy as np

BACK_LIMIT = 0.25  # a probe is invalid when more than this share of its rays hit back faces
SEARCH = 1.0  # virtual offset: a back face further than this many cell widths is not pushed through
PUSH = 0.1  # ... and the probe lands this many cell widths beyond it


def cell_width(grid) -> float:
    """The shortest side of one cell of `grid`, in metres."""
    axes = np.linalg.norm(grid.matrix[:3, :3], axis=0) * 2.0 / np.asarray(grid.resolution, np.float64)
    return float(axes.min())


def offsets(grid, found: dict) -> np.ndarray:
    """(N, 3) virtual offsets for the probes of `grid` that `found` (gather.gather's answer) says
    are invalid and have a back face near enough; zeros elsewhere."""
    width = cell_width(grid)
    bad = found["back_share"] > BACK_LIMIT
    near = bad & (found["near_t"] <= SEARCH * width)
    out = np.zeros((len(grid), 3))
    out[near] = found["near_d"][near] * (found["near_t"][near] + PUSH * width)[:, None]
    return out


def fill_from_neighbours(grid) -> int:
    """The coefficients of the invalid probes of `grid` set to the mean of their valid neighbours
    (in place); returns how many had none and kept their own."""
    rx, ry, rz = grid.resolution
    dense = np.full(rx * ry * rz, -1, np.int64)
    dense[grid.linear_index] = np.arange(len(grid))
    coefficients = np.ascontiguousarray(grid.coefficients, np.float32)
    occlusion = np.ascontiguousarray(grid.occlusion, np.float32)
    alone = _fill(grid.index, grid.valid, dense, rx, ry, rz, coefficients, occlusion)
    grid.coefficients, grid.occlusion = coefficients, occlusion
    return int(alone)


@numba.njit(cache=True)
def _fill(index, valid, dense, rx, ry, rz, coefficients, occlusion):
    alone = 0
    src_c = coefficients.copy()
    src_o = occlusion.copy()
    for i in range(index.shape[0]):
        if valid[i]:
            continue
        count = 0
        acc = np.zeros((9, 3))
        occ = np.zeros(occlusion.shape[1])
        for dz in range(-1, 2):
            for dy in range(-1, 2):
                for dx in range(-1, 2):
                    x, y, z = index[i, 0] + dx, index[i, 1] + dy, index[i, 2] + dz
                    if x < 0 or y < 0 or z < 0 or x >= rx or y >= ry or z >= rz:
                        continue
                    j = dense[x + rx * (y + ry * z)]
                    if j < 0 or not valid[j]:
                        continue
                    count += 1
                    acc += src_c[j]
                    occ += src_o[j]
        if count == 0:
            alone += 1
            continue
        for k in range(9):
            for c in range(3):
                coefficients[i, k, c] = acc[k, c] / count
        for m in range(occlusion.shape[1]):
            occlusion[i, m] = occ[m] / count
    return alone
