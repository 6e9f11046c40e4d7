"""Lightmap quality against time: our estimators and Cycles' own bake, against a converged Cycles
reference, on the same texels.

    python benchmarks/quality.py [--quick | --full] [--scenes cornell_box,patio] [--out DIR]

The reference is Cycles' Diffuse bake (DIRECT+INDIRECT, no COLOR, adaptive sampling off) at a high
sample count, in this process, cached under OUT/cache keyed by a hash of the .blend and the
settings. For each estimator a sweep of photon counts, for Cycles a sweep of sample counts; every
run records wall seconds and relative RMSE (and mean bias) over texels whose centre lies on the
surface. Prints the table, the time each method needs to reach 10 % and 5 % RMSE, writes
quality.json, quality.md and a log-log error/time plot per scene.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import plots  # noqa: E402
import scenes  # noqa: E402  (puts the repository root on sys.path)

import numba  # noqa: E402
import numpy as np  # noqa: E402

from detp_bake.bake import BakeSettings, compute  # noqa: E402

CONFIGS = {
    "quick": dict(resolution=16, reference_spp=32, photons=[10_000, 30_000], spp=[4, 8],
                  estimators=["disc_index", "photon_map"]),
    "short": dict(resolution=64, reference_spp=1024, photons=[100_000, 300_000, 1_000_000, 3_000_000],
                  spp=[4, 16, 64, 256], estimators=["disc_index", "sphere_cache", "photon_map"]),
    "full": dict(resolution=128, reference_spp=4096, photons=[100_000, 300_000, 1_000_000, 3_000_000, 10_000_000],
                 spp=[4, 16, 64, 256, 1024], estimators=["disc_index", "sphere_cache", "photon_map"]),
}


def reference(bpy, blender_scene, label, cfg, cache: Path):
    path = scenes.ROOT / "sample_scenes" / f"{label}.blend"
    key = hashlib.sha256(path.read_bytes() + json.dumps([cfg["resolution"], cfg["reference_spp"]]).encode())
    file = cache / f"{label}-{key.hexdigest()[:16]}.npz"
    if file.exists():
        return dict(np.load(file)), None
    names = [o.name for o in bpy.context.scene.objects if o.type == "MESH" and o.visible_get()]
    t0 = time.perf_counter()
    ref = blender_scene.cycles_bake(bpy.context.scene, names, resolution=cfg["resolution"], samples=cfg["reference_spp"])
    seconds = time.perf_counter() - t0
    cache.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(file, **ref)
    return ref, seconds


def error(images, ref, masks):
    a = np.concatenate([images[n][masks[n]] for n in masks])
    b = np.concatenate([ref[n][masks[n]] for n in masks])
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.mean(b)), float(a.mean() / b.mean() - 1)


def time_to(points, target):
    """Seconds to reach `target` RMSE, interpolated on log-log axes; None if never reached."""
    pts = sorted(points)
    for (t0, e0), (t1, e1) in zip(pts, pts[1:]):
        if e0 > target >= e1:
            f = np.log(e0 / target) / np.log(e0 / e1)
            return float(np.exp(np.log(t0) + f * (np.log(t1) - np.log(t0))))
    if pts and pts[0][1] <= target:
        return float(pts[0][0])
    return None


def bench_scene(label, cfg, cache):
    scene = scenes.blend_scene(label, cfg["resolution"])
    import bpy
    from detp_bake import blender_scene
    ref, ref_seconds = reference(bpy, blender_scene, label, cfg, cache)
    rows = []
    compute(scene, BakeSettings(photons=1000))  # load compiled kernels outside the timings
    for name in cfg["estimators"]:
        for photons in cfg["photons"]:
            t0 = time.perf_counter()
            r = compute(scene, BakeSettings(estimator=name, photons=photons, resolution=cfg["resolution"]))
            seconds = time.perf_counter() - t0
            rmse, bias = error(r.images, ref, r.centre_masks)
            rows.append({"method": name, "photons": photons, "seconds": seconds, "rmse": rmse, "bias": bias})
            masks = r.centre_masks
            print(f"{label:12} {name:13} {photons:>10,} photons {seconds:8.2f} s  RMSE {100 * rmse:5.1f} %  "
                  f"bias {100 * bias:+5.1f} %", flush=True)
    names = list(masks)
    for spp in cfg["spp"]:
        t0 = time.perf_counter()
        cyc = blender_scene.cycles_bake(bpy.context.scene, names, resolution=cfg["resolution"], samples=spp, seed=7)
        seconds = time.perf_counter() - t0
        rmse, bias = error(cyc, ref, masks)
        rows.append({"method": "cycles", "samples": spp, "seconds": seconds, "rmse": rmse, "bias": bias})
        print(f"{label:12} {'cycles':13} {spp:>10,} spp     {seconds:8.2f} s  RMSE {100 * rmse:5.1f} %  "
              f"bias {100 * bias:+5.1f} %", flush=True)
    reach = {}
    for method in dict.fromkeys(r["method"] for r in rows):
        pts = [(r["seconds"], r["rmse"]) for r in rows if r["method"] == method]
        reach[method] = {"10%": time_to(pts, 0.10), "5%": time_to(pts, 0.05)}
    return {"scene": label, "resolution": cfg["resolution"], "reference_spp": cfg["reference_spp"],
            "reference_seconds": ref_seconds, "threads": numba.get_num_threads(), "rows": rows, "reach": reach}


def markdown(res):
    fmt = lambda s: "not reached" if s is None else f"{s:.1f} s"
    lines = [f"### {res['scene']} ({res['resolution']}² per object, reference {res['reference_spp']} spp, "
             f"{res['threads']} threads)", "", "| method | time to 10 % RMSE | time to 5 % RMSE |", "|---|---:|---:|"]
    for method, t in res["reach"].items():
        lines.append(f"| {method} | {fmt(t['10%'])} | {fmt(t['5%'])} |")
    return "\n".join(lines)


def plot(res, out):
    plt = plots.pyplot()
    if plt is None:
        return None
    fig, ax = plt.subplots(figsize=(6, 4.5))
    for method in dict.fromkeys(r["method"] for r in res["rows"]):
        pts = sorted((r["seconds"], r["rmse"]) for r in res["rows"] if r["method"] == method)
        ax.loglog(*zip(*pts), "o-", label=method)
    for level in (0.10, 0.05):
        ax.axhline(level, color="grey", lw=0.5, ls=":")
    ax.set(xlabel="wall seconds", ylabel="relative RMSE vs converged Cycles", title=res["scene"])
    ax.legend()
    fig.tight_layout()
    path = out / f"quality_{res['scene']}.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return str(path)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    group = ap.add_mutually_exclusive_group()
    group.add_argument("--quick", action="store_true", help="seconds: checks that the script works")
    group.add_argument("--full", action="store_true", help="the full sweeps")
    ap.add_argument("--scenes", default="cornell_box,patio")
    ap.add_argument("--estimators", default=None, help="comma-separated subset of the configuration's estimators")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = ap.parse_args(argv)
    cfg = dict(CONFIGS["quick" if args.quick else "full" if args.full else "short"])
    if args.estimators:
        cfg["estimators"] = args.estimators.split(",")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = []
    for label in args.scenes.split(","):
        res = bench_scene(label, cfg, out / "cache")
        res["plot"] = plot(res, out)
        results.append(res)
        print(markdown(res), "\n", flush=True)
    (out / "quality.json").write_text(json.dumps({"cores": os.cpu_count(), "config": cfg, "results": results}, indent=1))
    (out / "quality.md").write_text("\n\n".join(markdown(r) for r in results) + "\n")
    print(f"wrote {out / 'quality.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
