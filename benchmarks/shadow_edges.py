"""Shadow edges against Cycles (issue 33, item 3): the courtyard's sun alone (no sky, no bounce), our
shadow rays against Cycles' own bake of the same texels, per texel, with the error over the texels
a shadow edge crosses apart from the rest.

    python benchmarks/shadow_edges.py [--resolution 64] [--samples 4,16,64] [--reference-spp 1024]
        [--sun-angle DEG] [--reference FILE.npz] [--code DIR] [--json OUT]

Without sky and bounces a texel's value is the sun's irradiance over the texel's footprint; Cycles
averages it over its jittered samples, so with many samples it is the covered share. A texel is on
an edge when the reference there lies between EDGE_LOW and EDGE_HIGH of the brightest texel of its
3 × 3 neighbourhood in the same image. Errors are relative RMS per texel (over the reference's
mean on those texels), all baked objects together, for each `--samples` (shadow rays per texel).
`--sun-angle` sets the sun's angular diameter (the scene's is 0.5°, a light with extent: `samples`
rays per texel; 0 makes it sharp: four first rays, more where they disagree).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OBJECTS = ("Floor", "NorthWall", "WestWall", "EastWall", "Pillars", "Beam", "Boulder")
EDGE_LOW, EDGE_HIGH = 0.15, 0.85


def edges(ref: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Texels of `mask` whose reference value lies between EDGE_LOW and EDGE_HIGH of its 3 × 3
    neighbourhood's brightest texel."""
    v = np.where(mask, ref.mean(axis=-1), 0.0)
    pad = np.pad(v, 1)
    high = np.max([pad[1 + dy:1 + dy + v.shape[0], 1 + dx:1 + dx + v.shape[1]]
                   for dy in (-1, 0, 1) for dx in (-1, 0, 1)], axis=0)
    return mask & (v > EDGE_LOW * high) & (v < EDGE_HIGH * high)


def error(images, ref, masks) -> float:
    d = np.concatenate([(images[n][m] - ref[n][m]).ravel() for n, m in masks.items()])
    b = np.concatenate([ref[n][m].ravel() for n, m in masks.items()])
    return float(np.sqrt(np.mean(d ** 2)) / np.mean(b))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=64)
    ap.add_argument("--samples", default="4,16,64")
    ap.add_argument("--reference-spp", type=int, default=1024)
    ap.add_argument("--sun-angle", type=float, default=None, help="degrees; default: the scene's")
    ap.add_argument("--reference", default="")
    ap.add_argument("--code", default=str(ROOT))
    ap.add_argument("--json", default=str(ROOT / "benchmarks" / "results" / "shadow_edges.json"))
    args = ap.parse_args(argv)
    sys.path.insert(0, args.code)
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="detp_edges_"))
    import bpy
    from detp_bake.blender import cycles_bake, export_scene
    from detp_bake.run.bake import BakeSettings, compute
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "sample_scenes" / "courtyard.blend"))
    scene = bpy.context.scene
    scene.world = None  # the sun alone
    if args.sun_angle is not None:
        import math
        for ob in scene.objects:
            if ob.type == "LIGHT" and ob.data.type == "SUN":
                ob.data.angle = math.radians(args.sun_angle)
    names = list(OBJECTS)
    res = args.resolution
    ref_path = Path(args.reference) if args.reference else None
    if ref_path is not None and ref_path.is_file():
        with np.load(ref_path) as z:
            ref = {n: z[n] for n in names}
    else:
        t0 = time.perf_counter()
        ref = cycles_bake(scene, names, uv_name="Lightmap", resolution=res, samples=args.reference_spp, bounces=0,
                          seed=7)
        print(f"reference: Cycles {args.reference_spp} spp in {time.perf_counter() - t0:.0f} s", flush=True)
        if ref_path is not None:
            np.savez(ref_path, **ref)
    rows = []
    for samples in (int(s) for s in args.samples.split(",")):
        sc = export_scene(scene, bpy.context.evaluated_depsgraph_get(), names, "Lightmap", res, log=lambda m: None)
        t0 = time.perf_counter()
        r = compute(sc, BakeSettings(bounces=0, photons=10_000, denoise=False, direct_samples=samples, seed=1))
        seconds = time.perf_counter() - t0
        masks = r.centre_masks
        edge = {n: edges(ref[n], masks[n]) for n in names}
        rest = {n: masks[n] & ~edge[n] for n in names}
        row = {"samples": samples, "seconds": seconds, "edge_texels": int(sum(m.sum() for m in edge.values())),
               "texels": int(sum(m.sum() for m in masks.values())), "edge_error": error(r.images, ref, edge),
               "rest_error": error(r.images, ref, rest), "all_error": error(r.images, ref, masks),
               "mean": float(np.mean(np.concatenate([r.images[n][masks[n]].ravel() for n in names]))
                             / np.mean(np.concatenate([ref[n][masks[n]].ravel() for n in names])) - 1.0)}
        row["objects"] = {n: round(error({n: r.images[n]}, ref, {n: edge[n]}), 4) for n in names if edge[n].any()}
        rows.append(row)
        print(f"{samples:4d} rays: edge texels {row['edge_texels']:5d} error {100 * row['edge_error']:6.2f} %, "
              f"others {100 * row['rest_error']:6.2f} %, all {100 * row['all_error']:6.2f} %, "
              f"mean {100 * row['mean']:+.2f} %, {seconds:.1f} s; edges by object: "
              + ", ".join(f"{n} {100 * v:.1f} %" for n, v in row["objects"].items()), flush=True)
    doc = {"resolution": res, "reference_spp": args.reference_spp, "sun_angle": args.sun_angle, "code": args.code,
           "rows": rows}
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
