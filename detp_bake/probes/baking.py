"""A bake's probes, from its finished lightmaps: placed grids gathered (gather.py), invalid probes
moved out or filled (validity.py), the record filled in (grid.ProbeGrid). run/pipeline.py calls
`bake_probes` once the lightmaps are made; tests and benchmarks call it directly."""
from __future__ import annotations

import time

import numpy as np

from . import gather as gather_mod, validity
from .grid import ProbeGrid


def bake_probes(grids: list[ProbeGrid], scene, caster, images: dict, rays: int, samples: int, seed: int = 0,
                masked=(), offset=None, progress=None, leave_out: bool = True) -> dict:
    """Fill `grids` in place and return report.json's figures. `scene` and `caster` are the bake's
    (a centred scene: `offset` is what was subtracted from world space); `images` the lightmaps
    {name: (H, W, 3) E/π}; `rays` gather rays and `samples` shadow rays per light and probe;
    `masked` the shadowmask lights: each one's arrived share goes to `occlusion`, and its direct
    light is left out of the coefficients with `leave_out` (the shadowmask's subtract mode)."""
    t0 = time.perf_counter()
    shift = np.zeros(3) if offset is None else np.asarray(offset, np.float64)
    lit = gather_mod.lighting(scene, caster, images, samples, seed, masked, leave_out)
    counts = [len(g) for g in grids]
    if not sum(counts):
        return {"count": 0, "invalid": 0, "moved": 0, "rays": int(rays), "seconds": 0.0, "grids": []}
    positions = np.concatenate([g.positions for g in grids]) - shift
    found = gather_mod.gather(lit, positions, rays, progress)
    moved = invalid = 0
    at = 0
    for g, n in zip(grids, counts):
        part = {k: v[at:at + n] for k, v in found.items()}
        m, bad = _finish(g, part, lit, positions[at:at + n], rays)
        moved, invalid, at = moved + m, invalid + bad, at + n
    return {"count": int(sum(counts)), "invalid": int(invalid), "moved": int(moved), "rays": int(rays),
            "shadow_rays": int(samples), "seconds": round(time.perf_counter() - t0, 3),
            "grids": [{"name": g.name, "resolution": list(g.resolution), "count": len(g),
                       "invalid": int((~g.valid).sum())} for g in grids]}


def _finish(grid: ProbeGrid, found: dict, lit, positions: np.ndarray, rays: int) -> tuple[int, int]:
    """One grid's record from its gather; invalid probes moved out and gathered again, those still
    invalid filled from their valid neighbours. Returns (moved, still invalid)."""
    grid.valid = found["back_share"] <= validity.BACK_LIMIT
    push = validity.offsets(grid, found)
    moving = np.flatnonzero(push.any(axis=1))
    coefficients, occlusion = found["coefficients"].copy(), found["occlusion"].copy()
    offset = np.zeros((len(grid), 3))
    if len(moving):
        again = gather_mod.gather(lit, positions[moving] + push[moving], rays)
        ok = again["back_share"] <= validity.BACK_LIMIT
        rows = moving[ok]
        coefficients[rows] = again["coefficients"][ok]
        occlusion[rows] = again["occlusion"][ok]
        offset[rows] = push[rows]
        grid.valid[rows] = True
    grid.coefficients = coefficients.astype(np.float32)
    grid.occlusion = occlusion.astype(np.float32)
    grid.offset = offset.astype(np.float32)
    grid.shadowmask_lights = tuple(lit.masked)
    if not grid.valid.all():
        validity.fill_from_neighbours(grid)
    return int(np.count_nonzero(offset.any(axis=1))), int((~grid.valid).sum())
