"""Estimator timing on the same photons: sphere cache against disc index over disc radii, a Q
sweep for the sphere cache, the photon map beside them, and estimation against tracing time.

    python benchmarks/estimators.py [--quick] [--photons N] [--scenes cornell,dense] [--json OUT]
    python benchmarks/estimators.py --profile [--resolutions 128,512] [--radii 1.5,4] [--baseline REV]
    python benchmarks/estimators.py --build-scale [--planes 1x1024,4x1024,1x2048] [--baseline REV]

--profile: where disc_index spends its time on the Cornell box, per lightmap size, disc radius and
segment set (every segment, or indirect only: what a bake with sampled direct light feeds it):
clearance pass, build, query steps (segment order, binning, splatting), node tests per segment,
disc tests per crossing, and the ratio of estimation to tracing the same photons. --build-scale:
seconds per million discs for the build and the clearance pass on flat planes of texels.
--baseline REV runs the estimators and texels module of git revision REV beside the working tree's,
alternating repeats, so the before/after ratios come from one run (read ratios, not seconds, on a
shared machine; the load average is printed).

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

from detp_bake.lightmap import texels as texels_mod  # noqa: E402
from detp_bake.estimators import Context, EstimatorSettings, create  # noqa: E402
from detp_bake.transport.photons import PhotonTracer  # noqa: E402

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
            "segments": tracer.stats.segments, "trace_seconds": tracer.stats.seconds,
            "threads": numba.get_num_threads(),
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



# --- disc_index, step by step (--profile, --build-scale) -------------------------------------------

def load_baseline(rev):
    """The detp_bake package of git revision `rev`, importable as `detp_bake_base` (its own numba
    cache): (estimators.create, texels.tangent_clearance)."""
    import importlib
    import subprocess
    import tarfile
    import tempfile

    root = Path(tempfile.mkdtemp(prefix="detp_baseline_"))
    data = subprocess.run(["git", "archive", rev, "detp_bake"], cwd=scenes.ROOT, check=True, capture_output=True).stdout
    with tarfile.open(fileobj=__import__("io").BytesIO(data)) as tar:
        tar.extractall(root)
    (root / "detp_bake").rename(root / "detp_bake_base")
    sys.path.insert(0, str(root))
    est = importlib.import_module("detp_bake_base.estimators")
    tex = importlib.import_module("detp_bake_base.texels")
    return est.create, tex.tangent_clearance


def _clock():
    return time.perf_counter(), time.process_time()


def _since(t):
    return time.perf_counter() - t[0], time.process_time() - t[1]


def _disc_run(create_fn, clearance_fn, texels, positions, batches, context, radius_texels):
    """One disc_index bake of the batches: seconds (wall, cpu) of clearance, build, query, counters."""
    from detp_bake.estimators.discs import SLAB, disc_radius

    settings = EstimatorSettings(radius_texels=radius_texels)
    radius = disc_radius(texels, settings)
    t = _clock()
    clearance = clearance_fn(texels, positions, radius, 0.5 * SLAB * radius)
    tc = _since(t)
    ctx = Context(scene_radius=context.scene_radius, expected_segments=context.expected_segments, clearance=clearance)
    t = _clock()
    est = create_fn("disc_index", texels, settings, context=ctx)
    tb = _since(t)
    t = _clock()
    for b in batches:
        est.add(b)
    out = est.finish()
    return {"clearance": tc, "build": tb, "query": _since(t), "counters": out.counters, "irradiance": out.irradiance}


def _alternate(runs, repeat):
    """{name: fn}: run each `repeat` times, alternating; per name the fastest of each timing."""
    best = {}
    for _ in range(max(1, repeat)):
        for name, fn in runs.items():
            r = fn()
            b = best.setdefault(name, r)
            for k in ("clearance", "build", "query"):
                b[k] = tuple(min(x, y) for x, y in zip(b[k], r[k]))
    return best


def _row(r, discs, segments, trace_seconds):
    c = r["counters"]
    row = {"clearance_s": r["clearance"][0], "clearance_cpu_s": r["clearance"][1], "build_s": r["build"][0],
           "build_cpu_s": r["build"][1], "query_s": r["query"][0], "query_cpu_s": r["query"][1],
           "build_s_per_mdisc": r["build"][0] / discs * 1e6, "clearance_s_per_mdisc": r["clearance"][0] / discs * 1e6,
           "query_s_per_mseg": r["query"][0] / max(segments, 1) * 1e6,
           "estimate_over_trace": (r["build"][0] + r["query"][0]) / trace_seconds,
           "node_tests_per_segment": c.get("ray_node_tests", 0) / max(segments, 1),
           "disc_tests_per_crossing": c.get("ray_disc_tests", 0) / max(c.get("crossings", 1), 1),
           "crossings": c.get("crossings", 0)}
    row.update({k: v for k, v in c.items() if k.startswith("seconds_") or k in ("clusters", "bvh_nodes", "bvh_depth")})
    return row


def profile(resolutions, radii, photons, baseline, repeat):
    """disc_index on the Cornell box: every (lightmap size, segment set, radius), ours and the baseline's."""
    from detp_bake.lightmap.texels import tangent_clearance

    methods = {"new": (create, tangent_clearance)}
    if baseline:
        methods["baseline"] = load_baseline(baseline)
    rows = []
    print(f"load average {os.getloadavg()[0]:.1f}; {numba.get_num_threads()} threads; seconds are the best of "
          f"{repeat} alternating runs (wall), node tests per segment, disc tests per crossing")
    for res in resolutions:
        scene = scenes.cornell_box(resolution=res)
        texels = texels_mod.rasterise(scene)
        for indirect in (False, True):
            tracer = PhotonTracer(scene, photons, scene.default_bounces, 0, indirect_only=indirect)
            batches = list(tracer.batches())
            segments = tracer.stats.segments
            context = Context(scene_radius=tracer.escape_radius, expected_segments=segments)
            warm_up(texels, batches, context)
            for r in radii:
                runs = {name: (lambda c=c, tc=tc: _disc_run(c, tc, texels, scene.positions, batches, context, r))
                        for name, (c, tc) in methods.items()}
                for fn in runs.values():
                    fn()  # compile or load every kernel outside the timings
                best = _alternate(runs, repeat)
                segs = "indirect" if indirect else "all"
                print(f"\n== {res}²: {len(texels):,} discs, {segs} segments ({segments:,}), r = {r} texels; "
                      f"tracing {tracer.stats.seconds:.2f} s; load {os.getloadavg()[0]:.1f}")
                for name, b in best.items():
                    row = _row(b, len(texels), segments, tracer.stats.seconds)
                    row.update(method=name, resolution=res, segments_set=segs, radius_texels=r, discs=len(texels),
                               segments=segments, trace_s=tracer.stats.seconds)
                    rows.append(row)
                    steps = ", ".join(f"{k[8:]} {v:.2f}" for k, v in row.items()
                                      if k.startswith("seconds_") and k not in ("seconds_build", "seconds_query"))
                    print(f"{name:>9}: clearance {row['clearance_s']:.2f} s, build {row['build_s']:.2f} s "
                          f"({row['build_s_per_mdisc']:.2f} s/M discs), query {row['query_s']:.2f} s "
                          f"({row['query_s_per_mseg']:.2f} s/M segments), estimate/trace "
                          f"{row['estimate_over_trace']:.1f}; {row['node_tests_per_segment']:.0f} node tests/segment, "
                          f"{row['disc_tests_per_crossing']:.2f} disc tests/crossing" + (f"; {steps}" if steps else ""))
                if "baseline" in best:
                    a, b = best["baseline"], best["new"]
                    same = a["counters"]["crossings"] == b["counters"]["crossings"]
                    ea, eb = a["irradiance"], b["irradiance"]
                    diff = float(np.max(np.abs(ea - eb) / np.maximum(np.abs(ea), 1e-300)))
                    print(f"    baseline/new: clearance {a['clearance'][0] / b['clearance'][0]:.2f}x, build "
                          f"{a['build'][0] / b['build'][0]:.2f}x, query {a['query'][0] / b['query'][0]:.2f}x "
                          f"(cpu {a['query'][1] / b['query'][1]:.2f}x); same crossings: {same}, "
                          f"max rel. diff {diff:.1e}")
    return {"cores": os.cpu_count(), "threads": numba.get_num_threads(), "photons": photons, "rows": rows}


def planes_texels(count, size):
    """`count` parallel 1 m² planes 1 m apart, each a size² lightmap: texels and their triangles."""
    from detp_bake.lightmap.texels import Lightmap, TexelSet

    g = (np.arange(size) + 0.5) / size
    x, y = np.meshgrid(g, g, indexing="xy")
    pos = np.concatenate([np.c_[x.ravel(), y.ravel(), np.full(size * size, float(k))] for k in range(count)])
    n = len(pos)
    nrm = np.tile([0.0, 0.0, 1.0], (n, 1))
    lms = [Lightmap(f"plane{k}", k, size, size, k * size * size, size * size, 1.0 / size) for k in range(count)]
    texels = TexelSet(pos, nrm, np.zeros(n, np.int32), np.tile(np.arange(size * size), count), np.full(n, size ** -2.0),
                      np.ones(n, bool), lms)
    quad = np.array([[[0, 0, 0], [1, 0, 0], [1, 1, 0]], [[0, 0, 0], [1, 1, 0], [0, 1, 0]]], np.float32)
    tris = np.concatenate([quad + [0, 0, k] for k in range(count)])
    return texels, tris


def build_scale(planes, radii, baseline, repeat):
    """Seconds per million discs of the clearance pass and the build, on flat planes of texels."""
    from detp_bake.estimators.discs import SLAB, disc_radius
    from detp_bake.lightmap.texels import tangent_clearance

    methods = {"new": (create, tangent_clearance)}
    if baseline:
        methods["baseline"] = load_baseline(baseline)
    rows = []
    print(f"load average {os.getloadavg()[0]:.1f}; {numba.get_num_threads()} threads")
    small, small_tris = planes_texels(1, 16)
    for create_fn, clear_fn in methods.values():  # compile or load the kernels
        _disc_run(create_fn, clear_fn, small, small_tris, [], Context(), 1.5)
    for count, size in planes:
        texels, tris = planes_texels(count, size)
        for r in radii:
            best = {}
            for _ in range(max(1, repeat)):
                for name, (create_fn, clear_fn) in methods.items():
                    settings = EstimatorSettings(radius_texels=r)
                    radius = disc_radius(texels, settings)
                    t = _clock()
                    clearance = clear_fn(texels, tris, radius, 0.5 * SLAB * radius)
                    tc = _since(t)
                    t = _clock()
                    create_fn("disc_index", texels, settings, context=Context(clearance=clearance))
                    tb = _since(t)
                    b = best.setdefault(name, {"clearance": tc, "build": tb})
                    b["clearance"], b["build"] = min(b["clearance"], tc), min(b["build"], tb)
            for name, b in best.items():
                row = {"method": name, "planes": count, "size": size, "discs": len(texels), "radius_texels": r,
                       "clearance_s": b["clearance"][0], "build_s": b["build"][0], "build_cpu_s": b["build"][1],
                       "clearance_s_per_mdisc": b["clearance"][0] / len(texels) * 1e6,
                       "build_s_per_mdisc": b["build"][0] / len(texels) * 1e6}
                rows.append(row)
                print(f"{count}x{size}² ({len(texels) / 1e6:.1f}M discs) r={r} {name:>9}: "
                      f"build {row['build_s']:.2f} s "
                      f"({row['build_s_per_mdisc']:.2f} s/M), clearance {row['clearance_s']:.2f} s "
                      f"({row['clearance_s_per_mdisc']:.2f} s/M); load {os.getloadavg()[0]:.1f}")
    return {"cores": os.cpu_count(), "threads": numba.get_num_threads(), "rows": rows}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="tiny run (seconds) that checks the script works")
    ap.add_argument("--photons", type=int, default=None)
    ap.add_argument("--scenes", default="cornell,dense")
    ap.add_argument("--json", default=None, help="default: benchmarks/results/<mode>.json")
    ap.add_argument("--profile", action="store_true", help="disc_index step by step on the Cornell box")
    ap.add_argument("--build-scale", action="store_true", help="build and clearance seconds per million discs")
    ap.add_argument("--resolutions", default="128,512")
    ap.add_argument("--radii", default="1.5,4")
    ap.add_argument("--planes", default="1x1024,4x1024,1x2048", help="COUNTxSIZE lightmaps, comma separated")
    ap.add_argument("--baseline", default=None, help="git revision to run beside the working tree")
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args(argv)
    results_dir = Path(__file__).resolve().parent / "results"
    if args.profile or args.build_scale:
        radii = [float(r) for r in args.radii.split(",")]
        if args.profile:
            res = profile([int(r) for r in args.resolutions.split(",")], radii, args.photons or 1_000_000,
                          args.baseline, args.repeat)
        else:
            planes = [tuple(int(x) for x in p.split("x")) for p in args.planes.split(",")]
            res = build_scale(planes, radii, args.baseline, args.repeat)
        out = Path(args.json or results_dir / ("disc_index_profile.json" if args.profile else "disc_index_build.json"))
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(res, indent=1, allow_nan=False))
        print(f"\nwrote {out}")
        return 0
    args.json = args.json or str(results_dir / "estimators.json")
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
    out.write_text(json.dumps({"cores": os.cpu_count(), "results": results}, indent=1, allow_nan=False))
    print(f"\nwrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
