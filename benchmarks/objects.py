"""Per object against Cycles: every object's mean lightmap value, ours over Cycles', split into
direct and indirect light so that a bias can be traced to the part that makes it.

    python benchmarks/objects.py [--quick] [--scenes patio,tree] [--resolution 128]
                                 [--photons 16000000] [--paper-photons 8000000]
                                 [--spp 128] [--direct-spp 64] [--out DIR]

For each scene every mesh is baked at `--resolution`² per object:
- Cycles' own bake (`blender.cycles_bake`: Diffuse, DIRECT+INDIRECT, no COLOR, adaptive
  sampling off), once with the scene's diffuse bounces (`--spp`) and once with bounces = 0
  (`--direct-spp`: direct light only), each as two halves with seeds 1 and 2 whose difference
  gives Cycles' own noise. Cached under OUT/cache, keyed by the .blend's bytes, the settings and
  the Blender version (Cycles 4.5 and 5.x do not bake the same numbers everywhere).
- ours with the default settings (`direct="sampled"`: shadow rays, the estimator on indirect light,
  OIDN) and in the paper's mode (`direct="photons"`, with `disc_index`), each with the scene's bounces and with
  bounces = 0. Each is baked as two halves of `--photons` (`--paper-photons` in the paper's mode)
  / 2 with seeds 1 and 2: their mean is the result, their difference the noise of its per-object
  mean. The crowns and the branches are small: most indirect photons land elsewhere, and 16M
  photons leave about 1 % noise on their means.

Means are over the texels Cycles bakes: those whose centre lies on a UV triangle
(`BakeResult.centre_masks`) and that Cycles' full bake did not leave at exactly 0 (a texel centre
exactly on a chart's edge, which Cycles' rasteriser skips, and faces buried in other geometry,
where no light arrives). All channels together. Columns, each ours / Cycles − 1:
`full` (what a user gets), `direct` (bounces = 0 on both sides), `indirect` (full − direct on
both sides), for the default and the paper's mode; `noise` is the larger of ours' and Cycles'
noise on the full mean (one standard deviation, from the halves); `ind.` Cycles' indirect share.

Writes OUT/objects.json and OUT/objects.md. The default run (128² per object, 8M photons, Cycles
at 128 / 64 spp) takes about 15 minutes on 2 cores when the Cycles references are cached, and
about 10 more to bake them the first time. At 32²-64² per object the texels of these scenes are
0.2-0.6 m wide: Cycles averages each texel over its square (within the texel's triangle) and we
read it at its centre, which moves the means of objects crossed by straight shadow edges by up to
5 % at 32² (under 1 % at 128²); compare at 128² or finer.
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
import scenes  # noqa: E402  (puts the repository root on sys.path)

import numpy as np  # noqa: E402

from detp_bake.run.bake import BakeSettings, compute  # noqa: E402

CONFIGS = {
    "default": dict(resolution=128, photons=16_000_000, paper_photons=8_000_000, spp=128, direct_spp=64),
    "quick": dict(resolution=16, photons=40_000, paper_photons=40_000, spp=8, direct_spp=4),
}
MODES = ("sampled", "photons")  # ours: the default (shadow rays + estimator) and the paper's mode
ESTIMATORS = {"sampled": BakeSettings.estimator, "photons": "disc_index"}  # the paper's mode is DETP's
SEEDS = (1, 2)


def cycles_references(bpy, scene_name, names, resolution, spp, direct_spp, cache: Path, log):
    """{"full": [half_a, half_b], "direct": [half_a, half_b]}, each half {object: (H, W, 3)}, and
    the seconds spent baking (None when cached)."""
    from detp_bake import blender
    blend = scenes.SAMPLES / f"{scene_name}.blend"
    key = hashlib.sha256(blend.read_bytes() + json.dumps(
        ["objects", bpy.app.version_string, resolution, spp, direct_spp, SEEDS, sorted(names)]).encode())
    path = cache / f"objects-{scene_name}-{key.hexdigest()[:16]}.npz"
    if path.exists():
        data = np.load(path)
        return {part: [{n: data[f"{part}:{h}:{n}"] for n in names} for h in range(len(SEEDS))]
                for part in ("full", "direct")}, None
    log(f"{scene_name}: Cycles at {spp} spp (direct only: {direct_spp} spp), {resolution}² per object, "
        f"{len(names)} objects, two halves each (cached for later runs)")
    t0 = time.perf_counter()
    refs = {}
    for part, samples, bounces in (("full", spp, None), ("direct", direct_spp, 0)):
        refs[part] = []
        for seed in SEEDS:
            with scenes.quiet_stdout():
                refs[part].append(blender.cycles_bake(bpy.context.scene, names, resolution=resolution,
                                                            samples=max(1, samples // len(SEEDS)),
                                                            bounces=bounces, seed=seed))
    seconds = time.perf_counter() - t0
    cache.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **{f"{part}:{h}:{n}": img[n] for part, halves in refs.items()
                                 for h, img in enumerate(halves) for n in names})
    return refs, seconds


def ours(scene, mode, bounces, photons, resolution, log):
    """Two half bakes (seeds 1, 2): ([images per half], centre masks, seconds)."""
    halves, seconds, masks = [], 0.0, None
    for seed in SEEDS:
        # With shadow rays and no bounce the photons carry nothing: trace as few as allowed.
        n = 1 if (mode == "sampled" and bounces == 0) else max(1, photons // len(SEEDS))
        t0 = time.perf_counter()
        r = compute(scene, BakeSettings(photons=n, resolution=resolution, direct=mode, bounces=bounces, seed=seed,
                                        estimator=ESTIMATORS[mode]))
        seconds += time.perf_counter() - t0
        halves.append(r.images)
        masks = r.centre_masks
    log(f"  ours, {mode} direct, bounces {'scene' if bounces is None else bounces}: {seconds:.1f} s")
    return halves, masks, seconds


def object_means(halves, masks, names):
    """Per object, the mean over the masked texels of each half, (len(SEEDS),) arrays."""
    return {n: np.array([float(np.mean(h[n][masks[n]], dtype=np.float64)) for h in halves]) for n in names}


def ratio(a, b):
    return float(a / b - 1.0) if b > 0 else float("nan")


def bench_scene(scene_name, cfg, cache, log):
    import bpy
    res = cfg["resolution"]
    scene = scenes.blend_scene(scene_name, res)
    names = [o.name for o in scene.objects if o.bake]
    refs, cycles_seconds = cycles_references(bpy, scene_name, names, res, cfg["spp"], cfg["direct_spp"], cache, log)
    runs, seconds, masks = {}, {}, None
    for mode in MODES:
        for bounces in (None, 0):
            key = (mode, "full" if bounces is None else "direct")
            photons = cfg["photons"] if mode == "sampled" else cfg["paper_photons"]
            runs[key], masks, seconds["/".join(key)] = ours(scene, mode, bounces, photons, res, log)
    # The texels Cycles bakes: centre on the surface, and not left at 0 by its full bake.
    keep = {n: masks[n] & (np.mean([h[n] for h in refs["full"]], axis=0).max(axis=2) > 0.0) for n in names}
    cyc = {part: object_means(refs[part], keep, names) for part in ("full", "direct")}
    our = {key: object_means(halves, keep, names) for key, halves in runs.items()}
    rows = []
    for n in names:
        c_full, c_dir = cyc["full"][n].mean(), cyc["direct"][n].mean()
        c_noise = abs(cyc["full"][n][0] - cyc["full"][n][1]) / 2 / c_full if c_full > 0 else float("nan")
        row = {"object": n, "texels": int(keep[n].sum()), "cycles": c_full, "cycles_direct": c_dir,
               "indirect_share": ratio(c_full - c_dir, c_full) + 1.0, "cycles_noise": c_noise}
        for mode in MODES:
            full, direct = our[(mode, "full")][n], our[(mode, "direct")][n]
            row[mode] = {"full": ratio(full.mean(), c_full), "direct": ratio(direct.mean(), c_dir),
                         "indirect": ratio(full.mean() - direct.mean(), c_full - c_dir),
                         "noise": float(abs(full[0] - full[1]) / 2 / full.mean()) if full.mean() > 0 else float("nan")}
        rows.append(row)
    return {"scene": scene_name, "triangles": int(scene.triangle_count), "objects": len(names),
            "resolution": res, "rows": rows, "seconds": seconds, "cycles_seconds": cycles_seconds}


def _pct(x):
    return "n/a" if not np.isfinite(x) else f"{100 * x:+.1f} %"


def markdown(result) -> str:
    head = ("| object | texels | full | direct | indirect | photons mode: full | direct | indirect | noise | ind. |\n"
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    lines = [head]
    for r in result["rows"]:
        s, p = r["sampled"], r["photons"]
        noise = max(s["noise"], r["cycles_noise"])
        lines.append(f"| {r['object']} | {r['texels']:,} | {_pct(s['full'])} | {_pct(s['direct'])} | "
                     f"{_pct(s['indirect'])} | {_pct(p['full'])} | {_pct(p['direct'])} | {_pct(p['indirect'])} | "
                     f"{100 * noise:.1f} % | {100 * r['indirect_share']:.0f} % |")
    worst = max(result["rows"], key=lambda r: abs(r["sampled"]["full"]))
    lines.append(f"\nWorst object (default settings): {worst['object']} {_pct(worst['sampled']['full'])}; "
                 f"objects over 2 %: {sum(abs(r['sampled']['full']) > 0.02 for r in result['rows'])} "
                 f"of {len(result['rows'])}.")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="seconds: checks that the script works")
    ap.add_argument("--scenes", default="patio,tree")
    ap.add_argument("--resolution", type=int, default=None)
    ap.add_argument("--photons", type=int, default=None, help="ours: photons per bake (two halves of half each)")
    ap.add_argument("--paper-photons", type=int, default=None, help="the same in the paper's mode")
    ap.add_argument("--spp", type=int, default=None, help="Cycles' samples for the full reference")
    ap.add_argument("--direct-spp", type=int, default=None, help="Cycles' samples for the direct-only reference")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = ap.parse_args(argv)
    cfg = dict(CONFIGS["quick" if args.quick else "default"])
    for k in ("resolution", "photons", "paper_photons", "spp", "direct_spp"):
        if getattr(args, k) is not None:
            cfg[k] = getattr(args, k)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()

    def log(msg):
        print(f"[{time.perf_counter() - t_start:7.1f} s] {msg}", flush=True)

    import numba
    log(f"{os.cpu_count()} cores, {numba.get_num_threads()} threads; {cfg}")
    results, texts = [], []
    for name in args.scenes.split(","):
        res = bench_scene(name, cfg, out / "cache", log)
        title = f"### {name} ({res['triangles']:,} triangles, {res['objects']} objects, {res['resolution']}² each)"
        text = title + "\n\n" + markdown(res)
        print(text + "\n", flush=True)
        results.append(res)
        texts.append(text)
    import bpy
    doc = {"cores": os.cpu_count(), "threads": numba.get_num_threads(), "blender": bpy.app.version_string,
           "config": cfg, "seconds": time.perf_counter() - t_start, "results": results}
    (out / "objects.json").write_text(json.dumps(doc, indent=1, allow_nan=False))
    (out / "objects.md").write_text("\n\n".join(texts) + "\n")
    log(f"wrote {out / 'objects.json'} and {out / 'objects.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
