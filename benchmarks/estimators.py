"""Estimator timing on the same photons: sphere cache against disc index over disc radii, a Q
sweep for the sphere cache, the photon map beside them, and estimation against tracing time.

    python benchmarks/estimators.py [--quick] [--photons N] [--scenes cornell,dense] [--json OUT]

Every method sees the very same photon batches (traced once), so the columns compare only the
estimators. Prints a table per scene and writes JSON (default benchmarks/results/estimators.json).
Questions it answers (issue: DETP estimators): does disc indexing take up to 50 % less time than the
sphere cache for small discs (the paper), is the best Q in 0.6-0.7, is disc_index at 1.5 texels at
least 2x faster than sphere_cache, and is estimation no slower than tracing the same photons?
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

import numba  # noqa: E402
import numpy as np  # noqa: E402

from detp_bake import texels as texels_mod  # noqa: E402
from detp_bake.estimators import Context, EstimatorSettings, create  # noqa: E402
from detp_bake.photons import PhotonTracer  # noqa: E402

RADII = [0.5, 1.0, 1.5, 2.0, 4.0, 8.0]
QS = [0.3, 0.4, 0.5, 0.6, 0.65, 0.7, 0.8, 0.9]


def trace(scene, photons, seed=0):
    tracer = PhotonTracer(scene, photons, scene.default_bounces, seed)
    batches = list(tracer.batches())
    return tracer, batches


def run(name, texels, batches, context, **settings):
    t0 = time.perf_counter()
    est = create(name, texels, EstimatorSettings(**settings), context=context)
    for b in batches:
        est.add(b)
    out = est.finish()
    return time.perf_counter() - t0, out


def warm_up(texels, batches, context):
    """Compile (or load from cache) every kernel on a sliver of the data, outside the timings."""
    small = texels_mod.TexelSet(texels.position[:64], texels.normal[:64], texels.triangle[:64], texels.pixel[:64],
                                texels.area[:64], texels.centre_inside[:64], texels.lightmaps)
    small.lightmaps = [texels_mod.Lightmap("warm", 0, 8, 8, 0, 64, texels.lightmaps[0].texel_size)]
    for name in ("sphere_cache", "disc_index", "photon_map"):
        run(name, small, batches[:1], context)


def bench_scene(label, scene, photons, radii, qs):
    tracer, batches = trace(scene, photons)
    texels = texels_mod.rasterise(scene)
    context = Context(scene_radius=tracer.escape_radius, expected_segments=tracer.stats.segments)
    warm_up(texels, batches, context)
    rows = []
    for r in radii:
        for name in ("sphere_cache", "disc_index"):
            seconds, est = run(name, texels, batches, context, radius_texels=r)
            rows.append({"scene": label, "estimator": name, "radius_texels": r, "q": 0.65, "seconds": seconds,
                         **est.counters})
    q_rows = []
    for q in qs:
        seconds, est = run("sphere_cache", texels, batches, context, radius_texels=1.5, q=q)
        q_rows.append({"scene": label, "estimator": "sphere_cache", "radius_texels": 1.5, "q": q,
                       "seconds": seconds, **est.counters})
    seconds, est = run("photon_map", texels, batches, context, k=100)
    pm = {"scene": label, "estimator": "photon_map", "k": 100, "seconds": seconds, **est.counters}
    return {"scene": label, "triangles": scene.triangle_count, "texels": len(texels), "photons": photons,
            "segments": tracer.stats.segments, "trace_seconds": tracer.stats.seconds, "threads": numba.get_num_threads(),
            "radius_sweep": rows, "q_sweep": q_rows, "photon_map": pm}


def report(res):
    print(f"\n== {res['scene']}: {res['triangles']:,} triangles, {res['texels']:,} texels, "
          f"{res['photons']:,} photons, {res['segments']:,} segments, {res['threads']} threads; "
          f"tracing {res['trace_seconds']:.2f} s")
    print(f"{'radius (texels)':>15} {'sphere_cache s':>15} {'disc_index s':>13} {'disc/sphere':>12} "
          f"{'sphere tests':>13} {'node tests':>12} {'crossings':>11}")
    by = {(r["estimator"], r["radius_texels"]): r for r in res["radius_sweep"]}
    for rt in sorted({r["radius_texels"] for r in res["radius_sweep"]}):
        s, d = by[("sphere_cache", rt)], by[("disc_index", rt)]
        print(f"{rt:>15} {s['seconds']:>15.3f} {d['seconds']:>13.3f} {d['seconds'] / s['seconds']:>12.2f} "
              f"{s['ray_sphere_tests']:>13,} {d['ray_node_tests']:>12,} {d['crossings']:>11,}")
    print(f"{'Q':>15} {'sphere_cache s':>15} {'rebuilds':>13} {'sphere tests':>13}")
    for r in res["q_sweep"]:
        print(f"{r['q']:>15} {r['seconds']:>15.3f} {r['sphere_rebuilds']:>13,} {r['ray_sphere_tests']:>13,}")
    best = min(res["q_sweep"], key=lambda r: r["seconds"])
    d15 = by.get(("disc_index", 1.5))
    s15 = by.get(("sphere_cache", 1.5))
    print(f"photon_map (k=100): {res['photon_map']['seconds']:.3f} s")
    print(f"best Q: {best['q']}; at 1.5 texels disc_index is {s15['seconds'] / d15['seconds']:.1f}x faster than "
          f"sphere_cache and takes {d15['seconds'] / res['trace_seconds']:.2f}x the tracing time")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="tiny run (seconds) that checks the script works")
    ap.add_argument("--photons", type=int, default=None)
    ap.add_argument("--scenes", default="cornell,dense")
    ap.add_argument("--json", default=str(Path(__file__).resolve().parent / "results" / "estimators.json"))
    args = ap.parse_args(argv)
    photons = args.photons or (20_000 if args.quick else 1_000_000)
    radii = [1.5, 4.0] if args.quick else RADII
    qs = [0.5, 0.65] if args.quick else QS
    results = []
    for label in args.scenes.split(","):
        if label == "cornell":
            scene = scenes.cornell_box(resolution=32 if args.quick else 128)
        elif label == "dense":
            scene = scenes.dense_room(5_000 if args.quick else 100_000)
            for obj in scene.objects:
                obj.resolution = 32 if args.quick else 256
        else:
            raise SystemExit(f"unknown scene {label!r}")
        res = bench_scene(label, scene, photons, radii, qs)
        report(res)
        results.append(res)
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"cores": os.cpu_count(), "results": results}, indent=1))
    print(f"\nwrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
