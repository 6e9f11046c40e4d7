"""Where probes go: the scene's Light Probe Volumes, each a full grid, or an automatic grid over the
baked objects' bounds that keeps only the probes near geometry; and what they will cost, known
before the bake (the panel's count and memory, run/memory.py's estimate).

The automatic grid: cubic cells of side `spacing` (metres), as many as cover the baked objects'
box grown by one spacing on every side, centred on it (a floor gets a layer of probes above and
below it, none on it); a probe sits at each cell's centre and is kept when some triangle
(of any object, baked or not) lies within NEAR cells' widths of it, measured exactly (the nearest
point of each triangle). Far from every surface the light changes slowly and nothing stands there
to be lit; a moving object between kept probes still has probes at both sides of it.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from ..errors import BakeError
from .grid import ProbeGrid

AUTO_NAME = "auto"
NEAR = 1.0  # an automatic grid's probe is kept within this many spacings of a surface
MAX_PROBES = 4_000_000  # more is a typing slip in the spacing, not a level
# What a probe costs: its record (cell, validity, offset, nine RGB float32s, four occlusions) and
# the gather's per-probe sums (float64 coefficients, back faces, nearest back face, occlusion).
PROBE_BYTES = 12 + 1 + 12 + 108 + 16 + (216 + 8 + 32 + 64)
# The gather's rays in flight (gather.CHUNK_RAYS of them: origin, direction, Embree's answer).
GATHER_SCRATCH = (1 << 18) * 64


def auto_grid(scene, spacing: float) -> ProbeGrid:
    """The automatic grid over the baked objects' box, probes near geometry only (see the module)."""
    if not spacing > 0.0 or not math.isfinite(spacing):
        raise BakeError(f"setting 'probe_spacing' = {spacing!r}: must be a positive length")
    lo, hi, res = _box(scene, spacing)
    size = np.asarray(res, np.float64) * spacing
    centre = 0.5 * (lo + hi)
    matrix = np.eye(4)
    matrix[:3, :3] = np.diag(0.5 * size)
    matrix[:3, 3] = centre
    keep = np.zeros(tuple(res[::-1]), np.bool_)  # z, y, x
    if scene.triangle_count:
        _mark_near(np.ascontiguousarray(scene.positions, np.float64), centre - 0.5 * size, spacing,
                   NEAR * spacing, keep)
    z, y, x = np.nonzero(keep)
    return ProbeGrid(AUTO_NAME, matrix, res, np.stack([x, y, z], axis=1))


def cells(lo, hi, spacing: float) -> int:
    """Cells of an automatic grid over the box lo … hi (before the near rule)."""
    return int(np.prod([max(1, int(math.ceil((h - l + 2 * spacing) / spacing - 1e-9))) for l, h in zip(lo, hi)]))


def _box(scene, spacing):
    baked = [o for o in scene.objects if o.bake and o.triangle_count]
    if not baked:
        raise BakeError("probes: no baked object to place an automatic grid around")
    pts = np.concatenate([scene.positions[o.triangles].reshape(-1, 3) for o in baked]).astype(np.float64)
    lo, hi = pts.min(axis=0) - spacing, pts.max(axis=0) + spacing
    res = tuple(max(1, int(math.ceil((h - l) / spacing - 1e-9))) for l, h in zip(lo, hi))
    count = res[0] * res[1] * res[2]
    if count > MAX_PROBES:
        raise BakeError(f"setting 'probe_spacing' = {spacing:g} m: the automatic grid over the baked objects "
                        f"({(hi - lo).round(2).tolist()} m) would have {count:,} cells, over {MAX_PROBES:,}: "
                        "use a wider spacing")
    return lo, hi, res


def volume_grids(volumes) -> list[ProbeGrid]:
    """One full grid per Light Probe Volume (scene.ProbeVolume: name, matrix, resolution)."""
    return [grid_of(v) for v in volumes]


def grid_of(v) -> ProbeGrid:
    """The full grid of one Light Probe Volume, or a BakeError naming it."""
    res = tuple(int(r) for r in v.resolution)
    if min(res) < 1:
        raise BakeError(f"light probe volume '{v.name}': its resolution {res} must be at least 1 on each axis")
    if res[0] * res[1] * res[2] > MAX_PROBES:
        raise BakeError(f"light probe volume '{v.name}': {res[0] * res[1] * res[2]:,} probes is over "
                        f"{MAX_PROBES:,}: lower its resolution")
    m = np.asarray(v.matrix, np.float64)
    if not np.isfinite(m).all() or abs(np.linalg.det(m[:3, :3])) <= 1e-12:
        raise BakeError(f"light probe volume '{v.name}': its transform has a zero scale")
    return ProbeGrid.full(v.name, m, res)


def grids_for(scene, mode: str, spacing: float) -> list[ProbeGrid]:
    """The grids a bake with `probes` = mode places: none (off), the automatic grid (auto), or the
    scene's Light Probe Volumes (volumes: a clear error when it has none)."""
    if mode == "off":
        return []
    if mode == "auto":
        return [auto_grid(scene, spacing)]
    volumes = list(getattr(scene, "probe_volumes", ()) or ())
    if not volumes:
        raise BakeError("setting 'probes' = 'volumes': the scene has no Light Probe Volume object (add one, "
                        "or use --probes auto)")
    return volume_grids(volumes)


def cost(grids, shadowmask_lights: int = 0) -> tuple[int, int]:
    """(probes, bytes) of `grids`: the count and memory the panel shows before a bake (the
    records, the gather's per-probe sums and its rays in flight)."""
    count = sum(len(g) for g in grids)
    return count, cost_of(count, shadowmask_lights)


def cost_of(count: int, shadowmask_lights: int = 0) -> int:
    """Bytes of `count` probes: see `cost`."""
    return count * (PROBE_BYTES + 8 * shadowmask_lights) + (GATHER_SCRATCH if count else 0)


@numba.njit(cache=True)
def _mark_near(tri, origin, spacing, near, keep):
    """keep[z, y, x] where the centre of cell (x, y, z) lies within `near` of a triangle."""
    rz, ry, rx = keep.shape
    res = (rx, ry, rz)
    near2 = near * near
    for t in range(tri.shape[0]):
        lo = np.empty(3, np.int64)
        hi = np.empty(3, np.int64)
        for c in range(3):
            a = min(tri[t, 0, c], tri[t, 1, c], tri[t, 2, c]) - near - origin[c]
            b = max(tri[t, 0, c], tri[t, 1, c], tri[t, 2, c]) + near - origin[c]
            lo[c] = max(int(math.floor(a / spacing - 0.5)), 0)
            hi[c] = min(int(math.ceil(b / spacing - 0.5)), res[c] - 1)
        for z in range(lo[2], hi[2] + 1):
            for y in range(lo[1], hi[1] + 1):
                for x in range(lo[0], hi[0] + 1):
                    if keep[z, y, x]:
                        continue
                    px = origin[0] + (x + 0.5) * spacing
                    py = origin[1] + (y + 0.5) * spacing
                    pz = origin[2] + (z + 0.5) * spacing
                    if _distance2(tri, t, px, py, pz) <= near2:
                        keep[z, y, x] = True


@numba.njit(cache=True, inline="always")
def _distance2(tri, t, px, py, pz):
    """Squared distance from p to triangle t (the closest point by its Voronoi regions)."""
    ax, ay, az = tri[t, 0, 0], tri[t, 0, 1], tri[t, 0, 2]
    abx, aby, abz = tri[t, 1, 0] - ax, tri[t, 1, 1] - ay, tri[t, 1, 2] - az
    acx, acy, acz = tri[t, 2, 0] - ax, tri[t, 2, 1] - ay, tri[t, 2, 2] - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return apx * apx + apy * apy + apz * apz
    bpx, bpy, bpz = px - tri[t, 1, 0], py - tri[t, 1, 1], pz - tri[t, 1, 2]
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return bpx * bpx + bpy * bpy + bpz * bpz
    cpx, cpy, cpz = px - tri[t, 2, 0], py - tri[t, 2, 1], pz - tri[t, 2, 2]
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return cpx * cpx + cpy * cpy + cpz * cpz
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        qx, qy, qz = ax + v * abx, ay + v * aby, az + v * abz
    else:
        vb = d5 * d2 - d1 * d6
        if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
            w = d2 / (d2 - d6)
            qx, qy, qz = ax + w * acx, ay + w * acy, az + w * acz
        else:
            va = d3 * d6 - d5 * d4
            if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
                w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
                bx, by, bz = tri[t, 1, 0], tri[t, 1, 1], tri[t, 1, 2]
                qx = bx + w * (tri[t, 2, 0] - bx)
                qy = by + w * (tri[t, 2, 1] - by)
                qz = bz + w * (tri[t, 2, 2] - bz)
            else:
                denom = 1.0 / max(va + vb + vc, 1e-300)
                v = vb * denom
                w = vc * denom
                qx, qy, qz = ax + abx * v + acx * w, ay + aby * v + acy * w, az + abz * v + acz * w
    dx, dy, dz = px - qx, py - qy, pz - qz
    return dx * dx + dy * dy + dz * dz
