"""Reproducing the paper's claims (García et al., CEIG 2005) on the tree and patio scenes.

    python benchmarks/paper.py [--quick | --full] [--scenes tree,patio] [--out DIR]

With the same photons for every estimator:
1. estimation time of sphere_cache and disc_index against disc radius (0.5 to 8 texels), with counters;
2. a Q sweep (0.3 to 0.9) for the sphere cache;
3. scaling: time against texel count n_P (lightmap size swept) and segment count n_R (photons swept),
   with fitted exponents set beside the slides' laws: O(n_R·∛n_P) when the disc is about a texel
   (radius in texels), O(n_R·n_P) for large discs (a fixed radius in metres).
Writes paper.json, paper.md (the Markdown tables) and PNG plots into --out (default
benchmarks/results/). Each configuration runs once: ratios within one run are what to read.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import plots  # noqa: E402
import scenes  # noqa: E402  (puts the repository root on sys.path)
from estimators import run, trace, warm_up  # noqa: E402

import numba  # noqa: E402
import numpy as np  # noqa: E402

from detp_bake.lightmap import texels as texels_mod  # noqa: E402
from detp_bake.estimators import Context  # noqa: E402

CONFIGS = {
    "quick": dict(photons=20_000, resolution=32, radii=[0.5, 1.5, 8.0], qs=[0.4, 0.65, 0.9],
                  sizes=[16, 32], photon_steps=[10_000, 20_000]),
    "short": dict(photons=300_000, resolution=64, radii=[0.5, 1.0, 2.0, 4.0, 8.0], qs=[0.3, 0.5, 0.6, 0.65, 0.7, 0.9],
                  sizes=[32, 64, 128], photon_steps=[100_000, 300_000, 1_000_000]),
    "full": dict(photons=1_000_000, resolution=128, radii=[0.5, 1.0, 2.0, 4.0, 8.0],
                 qs=[0.3, 0.4, 0.5, 0.6, 0.65, 0.7, 0.8, 0.9], sizes=[64, 128, 256, 512, 1024],
                 photon_steps=[100_000, 300_000, 1_000_000, 3_000_000]),
}


def _with_resolution(scene, res):
    for obj in scene.objects:
        obj.resolution = res
    return scene


def radius_and_q(scene, cfg):
    tracer, batches = trace(_with_resolution(scene, cfg["resolution"]), cfg["photons"])
    texels = texels_mod.rasterise(scene)
    ctx = Context(scene_radius=tracer.escape_radius, expected_segments=tracer.stats.segments)
    warm_up(texels, batches, ctx)
    radius = []
    for r in cfg["radii"]:
        for name in ("sphere_cache", "disc_index"):
            seconds, est = run(name, texels, batches, ctx, radius_texels=r)
            radius.append({"estimator": name, "radius_texels": r, "seconds": seconds, **est.counters})
    q = []
    for value in cfg["qs"]:
        seconds, est = run("sphere_cache", texels, batches, ctx, radius_texels=1.0, q=value)
        q.append({"q": value, "seconds": seconds, **est.counters})
    return {"texels": len(texels), "segments": tracer.stats.segments, "trace_seconds": tracer.stats.seconds,
            "radius": radius, "q": q}


def scaling(scene, cfg, world_radius):
    """Time against n_P (texels) at 1 texel radius and at a fixed large radius, and against n_R."""
    rows = []
    tracer, batches = trace(scene, cfg["photon_steps"][-1])
    for res in cfg["sizes"]:
        texels = texels_mod.rasterise(_with_resolution(scene, res))
        ctx = Context(scene_radius=tracer.escape_radius, expected_segments=tracer.stats.segments)
        for name in ("sphere_cache", "disc_index"):
            for mode, settings in (("texel", {"radius_texels": 1.0}), ("large", {"radius": world_radius})):
                seconds, est = run(name, texels, batches, ctx, **settings)
                rows.append({"sweep": "n_P", "mode": mode, "estimator": name, "n_P": len(texels),
                             "n_R": tracer.stats.segments, "seconds": seconds})
    texels = texels_mod.rasterise(_with_resolution(scene, cfg["sizes"][len(cfg["sizes"]) // 2]))
    for photons in cfg["photon_steps"]:
        tr, bs = trace(scene, photons, seed=1)
        ctx = Context(scene_radius=tr.escape_radius, expected_segments=tr.stats.segments)
        for name in ("sphere_cache", "disc_index"):
            seconds, est = run(name, texels, bs, ctx, radius_texels=1.0)
            rows.append({"sweep": "n_R", "mode": "texel", "estimator": name, "n_P": len(texels),
                         "n_R": tr.stats.segments, "seconds": seconds})
    return rows


def fit(rows, sweep, mode, name, key):
    pts = [(r[key], r["seconds"]) for r in rows if r["sweep"] == sweep and r["mode"] == mode and r["estimator"] == name]
    if len(pts) < 2:
        return float("nan")
    x, y = np.log([p[0] for p in pts]), np.log([max(p[1], 1e-9) for p in pts])
    return float(np.polyfit(x, y, 1)[0])


def markdown(label, res):
    lines = [f"### {label}: {res['texels']:,} texels, {res['segments']:,} segments, {res['threads']} threads",
             "", "| disc radius (texels) | sphere_cache s | disc_index s | disc_index saves |",
             "|---:|---:|---:|---:|"]
    by = {(r["estimator"], r["radius_texels"]): r for r in res["radius"]}
    for rt in sorted({r["radius_texels"] for r in res["radius"]}):
        s, d = by[("sphere_cache", rt)]["seconds"], by[("disc_index", rt)]["seconds"]
        lines.append(f"| {rt} | {s:.3f} | {d:.3f} | {100 * (1 - d / s):.0f} % |")
    lines += ["", "| Q | sphere_cache s | rebuilds | ray–sphere tests |", "|---:|---:|---:|---:|"]
    for r in res["q"]:
        lines.append(f"| {r['q']} | {r['seconds']:.3f} | {r['sphere_rebuilds']:,} | {r['ray_sphere_tests']:,} |")
    lines += ["", "| fitted exponent | sphere_cache | disc_index | slides |", "|---|---:|---:|---|"]
    for sweep, mode, key, law in (("n_P", "texel", "n_P", "1/3"), ("n_P", "large", "n_P", "1"),
                                  ("n_R", "texel", "n_R", "1")):
        e = [fit(res["scaling"], sweep, mode, n, key) for n in ("sphere_cache", "disc_index")]
        what = {"texel": "disc ≈ texel", "large": "large disc"}[mode]
        lines.append(f"| time ∝ {key}^a, {what} | {e[0]:.2f} | {e[1]:.2f} | {law} |")
    return "\n".join(lines)


def plot_scene(label, res, out):
    plt = plots.pyplot()
    if plt is None:
        return []
    fig, ax = plt.subplots(1, 3, figsize=(14, 4))
    for name in ("sphere_cache", "disc_index"):
        pts = sorted((r["radius_texels"], r["seconds"]) for r in res["radius"] if r["estimator"] == name)
        ax[0].plot(*zip(*pts), "o-", label=name)
        for mode, style in (("texel", "o-"), ("large", "s--")):
            p = sorted((r["n_P"], r["seconds"]) for r in res["scaling"]
                       if r["sweep"] == "n_P" and r["mode"] == mode and r["estimator"] == name)
            ax[2].loglog(*zip(*p), style, label=f"{name}, {mode} disc")
    ax[0].set(xlabel="disc radius (texels)", ylabel="seconds", xscale="log", yscale="log", title="radius")
    q = sorted((r["q"], r["seconds"]) for r in res["q"])
    ax[1].plot(*zip(*q), "o-")
    ax[1].set(xlabel="Q", ylabel="seconds", title="sphere cache Q")
    ax[2].set(xlabel="texels n_P", ylabel="seconds", title="scaling with n_P")
    ax[0].legend()
    ax[2].legend(fontsize=7)
    fig.suptitle(f"{label}: {res['segments']:,} segments, {res['threads']} threads")
    fig.tight_layout()
    path = out / f"paper_{label}.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return [str(path)]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    group = ap.add_mutually_exclusive_group()
    group.add_argument("--quick", action="store_true", help="seconds: checks that the script works")
    group.add_argument("--full", action="store_true", help="the full sweeps (an hour or more on 2 cores)")
    ap.add_argument("--scenes", default="tree,patio")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = ap.parse_args(argv)
    cfg = CONFIGS["quick" if args.quick else "full" if args.full else "short"]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results, text = {}, []
    for label in args.scenes.split(","):
        scene = scenes.blend_scene(label, cfg["resolution"])
        res = radius_and_q(scene, cfg)
        centre, radius = scene.bounds()
        res["scaling"] = scaling(scene, cfg, world_radius=radius / 50)
        res["threads"] = numba.get_num_threads()
        res["plots"] = plot_scene(label, res, out)
        results[label] = res
        text.append(markdown(label, res))
        print(text[-1], "\n", flush=True)
    (out / "paper.json").write_text(json.dumps({"cores": os.cpu_count(), "config": cfg, "results": results},
                                                   indent=1, allow_nan=False))
    (out / "paper.md").write_text("\n\n".join(text) + "\n")
    print(f"wrote {out / 'paper.json'}, {out / 'paper.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
