"""Atlases against one lightmap per object at the same texel density: texels, fill and bake time.

    python benchmarks/atlas.py [--scenes patio,tree] [--density 24] [--atlas-size 2048]
                               [--photons 500000] [--json OUT]

Per object, each lightmap is sized for the density (texels.resolution_for_density) and rounded up to
a power of two, as users size them; atlases pack every object's islands (Smart UV Project, as the
panel's *Atlas Charts › Smart UV*) at the density. Both are baked with the same photons in one run
(ratios, not seconds, are what carry over between machines). Texels are the images' pixels; fill
is covered texels over the atlases' pixels. Prints a table, writes JSON (default
benchmarks/results/atlas.json).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import scenes  # noqa: E402  (puts the repository root on sys.path)

from detp_bake.lightmap import texels as texels_mod  # noqa: E402
from detp_bake.run.bake import BakeSettings, compute  # noqa: E402


def _per_object(name: str, density: float, settings: BakeSettings) -> dict:
    scene = scenes.blend_scene(name)
    for obj in scene.objects:
        if obj.bake:
            sl = obj.triangles
            side = texels_mod.resolution_for_density(scene.positions[sl], scene.uvs[sl], density)
            obj.resolution = 1 << (side - 1).bit_length()
    t0 = time.perf_counter()
    r = compute(scene, settings)
    return {"seconds": time.perf_counter() - t0, "images": len(r.texels.lightmaps),
            "pixels": sum(lm.width * lm.height for lm in r.texels.lightmaps), "covered": len(r.texels)}


def _atlases(name: str, settings: BakeSettings) -> dict:
    import bpy
    from detp_bake.blender import export_scene

    scenes.blend_scene(name)  # opens the file
    scene = export_scene(bpy.context.scene, atlas=settings, log=lambda m: None)
    t0 = time.perf_counter()
    r = compute(scene, settings)
    pixels = sum(lm.width * lm.height for lm in r.texels.lightmaps)
    return {"seconds": time.perf_counter() - t0, "images": len(r.texels.lightmaps), "pixels": pixels,
            "covered": len(r.texels), "fill": len(r.texels) / pixels,
            "sizes": [lm.width for lm in r.texels.lightmaps]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default="patio,tree")
    ap.add_argument("--density", type=float, default=24.0)
    ap.add_argument("--atlas-size", type=int, default=2048)
    ap.add_argument("--photons", type=int, default=500_000)
    ap.add_argument("--charts", default="layout", choices=("layout", "islands", "smart"))
    ap.add_argument("--json", default=str(Path(__file__).resolve().parent / "results" / "atlas.json"))
    args = ap.parse_args()
    common = dict(photons=args.photons, seed=1, texel_density=args.density, atlas_size=args.atlas_size,
                  atlas_charts=args.charts)
    rows = []
    print(f"{'scene':8} {'per-object px':>14} {'atlas px':>10} {'ratio':>6} {'fill':>6} {'atlases':>8} "
          f"{'s per-object':>12} {'s atlas':>8}")
    for name in args.scenes.split(","):
        per = _per_object(name, args.density, BakeSettings(**common))
        at = _atlases(name, BakeSettings(lightmaps="atlas", **common))
        row = {"scene": name, "density": args.density, "per_object": per, "atlas": at,
               "pixel_ratio": at["pixels"] / per["pixels"]}
        rows.append(row)
        print(f"{name:8} {per['pixels']:>14,} {at['pixels']:>10,} {row['pixel_ratio']:>6.2f} {at['fill']:>6.2f} "
              f"{at['images']:>8} {per['seconds']:>12.1f} {at['seconds']:>8.1f}", flush=True)
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"cores": os.cpu_count(), "rows": rows}, indent=2, allow_nan=False))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
