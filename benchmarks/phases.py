"""What a default bake costs phase by phase on the two levels of issue 33, this tree beside an
earlier one (`--before`: a checkout or an unpacked `git archive`), in one run on one machine.

    python benchmarks/phases.py [--before DIR] [--repeat 2] [--arena-size 1024] [--crates 1500]
                                [--crate-size 32] [--trace-photons 2000000] [--json OUT] [--quick]

- arena: the level of benchmarks/levels.py (one mesh of 46,244 faces, Smart UV Project, sun and
  sky) at `--arena-size`, the defaults. The issue's "downloaded arena" (58,737 triangles) is not
  in the repository; this is the project's own level of the same kind.
- crates: benchmarks/big_scenes.py's level, `--crates` boxes on a ground under a sun, one lightmap
  of `--crate-size`² each, the defaults; the export is timed too.
- tracing: photons a second and rays a second of the arena's tracer on one thread and on every
  core, and Embree alone (`RayCaster.hits`) on the same rays, one call per stream as the tracer
  makes them: the bound the tracer works against.

Each bake runs in a child process that imports detp_bake from the tree it measures (with that
tree's numba cache), bakes the scene once small to load its kernels, then bakes it `--repeat`
times, alternating the trees, so that a shared machine's load falls on both. A table gives the
median seconds per phase (wall), the process's CPU seconds, peak MB and photons, before, after,
and their ratio; and how far the after images lie from the before ones (relative RMS over the
covered texels, and whether they are equal bit for bit). Writes JSON (default
benchmarks/results/phases.json). Several minutes a repeat on 2 cores at the defaults.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
PHASES = ("export", "rasterise", "validity", "fragments", "direct", "trace", "estimate", "denoise")


def _build(case: str, blend: str, crates: int) -> None:
    """The case's level saved as `blend`: both trees bake the same file (the level's bevels are
    made in an order that changes from process to process, and with it the triangles' order)."""
    sys.path.insert(0, str(HERE))
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="detp_phases_"))
    import bpy

    if case == "arena":
        import levels
        levels.make_level(bpy)
        bpy.ops.wm.save_as_mainfile(filepath=blend)
    else:
        import big_scenes
        big_scenes.level(bpy, Path(blend), crates)


def _child(case: str, code: Path, size: int, blend: str, images: str) -> dict:
    """One case baked in this process with the detp_bake of `code`: a small bake first (kernels),
    then the timed one. Saves its images to `images` (npz) and returns its figures."""
    sys.path.insert(0, str(code))
    sys.path.insert(1, str(HERE))
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="detp_phases_"))
    import bpy

    from detp_bake.blender import export_scene
    from detp_bake.run.bake import BakeSettings, compute

    bpy.ops.wm.open_mainfile(filepath=blend)
    names = [o.name for o in bpy.context.scene.objects if o.type == "MESH"]

    def export(resolution):
        t0 = time.perf_counter()
        sc = export_scene(bpy.context.scene, bpy.context.evaluated_depsgraph_get(), names,
                          "Lightmap", resolution, log=lambda msg: None)
        return sc, time.perf_counter() - t0

    compute(export(max(size // 16, 8))[0], BakeSettings())  # the kernels loaded (or compiled)
    sc, export_s = export(size)
    t0, c0 = time.perf_counter(), time.process_time()
    r = compute(sc, BakeSettings())
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    np.savez(images, **{f"{k}|img": v for k, v in r.images.items()},
             **{f"{k}|mask": v for k, v in r.masks.items()})
    return {"wall": wall + export_s, "cpu": cpu, "seconds": {**r.seconds, "export": export_s},
            "peak_mb": r.memory.get("peak_mb"), "photons": r.stats.photons, "texels": len(r.texels),
            "noise": r.noise}


def _trace_child(code: Path, size: int, photons: int, blend: str) -> dict:
    """Photons and rays a second of the arena's tracer on 1 thread and on every core, and Embree
    alone on the rays of its first batch."""
    sys.path.insert(0, str(code))
    sys.path.insert(1, str(HERE))
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="detp_phases_"))
    import bpy

    from detp_bake.rays import RayCaster
    from detp_bake.run.settings import BakeSettings
    from detp_bake.transport.photons import PhotonTracer
    import levels  # after detp_bake: it puts this tree on sys.path

    bpy.ops.wm.open_mainfile(filepath=blend)
    s = BakeSettings()
    sc = levels.export(bpy, size)
    caster = RayCaster(sc.positions)
    out = {}
    cores = os.cpu_count() or 1
    for threads in sorted({1, cores}):
        bounces = sc.default_bounces if s.bounces is None else s.bounces
        tracer = PhotonTracer(sc, photons, bounces, s.seed, 200_000, threads, caster=caster,
                              indirect_only=s.direct == "sampled")
        for _ in tracer.batches(indices=range(1)):  # kernels, buffers
            pass
        tracer.stats.rays = tracer.stats.photons = 0
        tracer.stats.embree_seconds = 0.0
        t0, c0 = time.perf_counter(), time.process_time()
        for batch in tracer.batches(indices=range(1, tracer.batch_count)):
            pass
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        st = tracer.stats
        out[f"{threads} thread{'s' * (threads > 1)}"] = {
            "photons_per_s": st.photons / wall, "rays_per_s": st.rays / wall, "rays_per_cpu_s": st.rays / cpu,
            "embree_share": st.embree_seconds / max(wall * threads, 1e-9)}
    out["embree alone, 1 thread"] = _embree_alone(caster, batch)
    return out


def _embree_alone(caster, batch) -> dict:
    """Rays a second of Embree's closest-hit calls alone on a batch's segments, in streams of the
    tracer's size (16,384 rays a call)."""
    o = np.ascontiguousarray(batch.seg_origin, np.float32)
    d = np.ascontiguousarray(batch.seg_dir, np.float32)
    n = len(o)
    t0 = time.perf_counter()
    for a in range(0, n, 16384):
        far = np.full(min(16384, n - a), 1e37, np.float32)
        caster.hits(o[a:a + 16384], d[a:a + 16384], far)
    return {"rays_per_s": n / (time.perf_counter() - t0)}


def _run_child(args, tree: Path, case: str, images: str, blend: str) -> dict:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", case, "--code", str(tree),
           "--arena-size", str(args.arena_size), "--crates", str(args.crates), "--crate-size",
           str(args.crate_size), "--trace-photons", str(args.trace_photons), "--images", images, "--blend", blend]
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tree / ".cache" / "numba")}
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    if done.returncode:
        raise SystemExit(f"{case} on {tree} failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def _difference(before: str, after: str) -> dict:
    """How far the after images lie from the before ones over the covered texels."""
    a, b = np.load(before), np.load(after)
    names = [k[:-4] for k in a.files if k.endswith("|img")]
    equal = all(np.array_equal(a[f"{n}|img"], b[f"{n}|img"]) for n in names)
    d = np.concatenate([(b[f"{n}|img"] - a[f"{n}|img"])[a[f"{n}|mask"]].ravel() for n in names])
    ref = np.concatenate([a[f"{n}|img"][a[f"{n}|mask"]].ravel() for n in names])
    return {"equal": bool(equal), "relative_rms": float(np.sqrt(np.mean(d.astype(np.float64) ** 2)) / np.mean(ref))}


def _median(rows, key):
    vals = [r[key] if key in ("wall", "cpu") else r["seconds"].get(key, 0.0) for r in rows]
    return float(np.median(vals))


def table(data: dict) -> str:
    out = []
    for case, runs in data["cases"].items():
        size = data["arena_size"] if case == "arena" else data["crate_size"]
        b, a = runs["before"], runs["after"]
        out.append(f"\n{case} at {size}² ({a[0]['texels']:,} texels, {a[0]['photons'] / 1e6:.3g}M photons after, "
                   f"{b[0]['photons'] / 1e6:.3g}M before), median of {len(a)}; seconds:\n")
        out.append("| phase | before | after | after / before |\n|---|---|---|---|")
        for key in PHASES + ("wall", "cpu"):
            x, y = _median(b, key), _median(a, key)
            label = {"wall": "**total (wall)**", "cpu": "CPU seconds of the bake"}.get(key, key)
            out.append(f"| {label} | {x:.2f} | {y:.2f} | {y / x if x else float('nan'):.2f} |")
        out.append(f"| peak MB | {b[0]['peak_mb']:.0f} | {a[0]['peak_mb']:.0f} | |")
        diff = runs["images"]
        out.append(f"\nimages after against before: {'equal bit for bit' if diff['equal'] else 'differ'}, "
                   f"relative RMS {100 * diff['relative_rms']:.4f} %")
    for tree, rates in data.get("tracing", {}).items():
        out.append(f"\ntracing, arena ({tree}): " + "; ".join(
            f"{k}: {v['rays_per_s'] / 1e6:.2f}M rays/s" + (f", {v['photons_per_s'] / 1e6:.2f}M photons/s"
                                                            if "photons_per_s" in v else "")
            for k, v in rates.items()))
    return "\n".join(out) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--before", default="", help="a tree to measure beside this one (none: this one only)")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--arena-size", type=int, default=1024)
    ap.add_argument("--crates", type=int, default=1500)
    ap.add_argument("--crate-size", type=int, default=32)
    ap.add_argument("--trace-photons", type=int, default=2_000_000)
    ap.add_argument("--cases", default="arena,crates,tracing")
    ap.add_argument("--quick", action="store_true", help="arena at 128², 60 crates, 400k photons traced")
    ap.add_argument("--json", default=str(HERE / "results" / "phases.json"))
    ap.add_argument("--child", default="", help=argparse.SUPPRESS)
    ap.add_argument("--code", default=str(ROOT), help=argparse.SUPPRESS)
    ap.add_argument("--images", default="", help=argparse.SUPPRESS)
    ap.add_argument("--blend", default="", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.quick:  # smaller defaults; what is given stays
        ap.set_defaults(arena_size=128, crates=60, trace_photons=400_000)
        args = ap.parse_args(argv)
    if args.child:
        code = Path(args.code)
        if args.child.startswith("build-"):
            _build(args.child[6:], args.blend, args.crates)
            got = {}
        elif args.child == "tracing":
            got = _trace_child(code, args.arena_size, args.trace_photons, args.blend)
        else:
            got = _child(args.child, code, args.arena_size if args.child == "arena" else args.crate_size,
                         args.blend, args.images)
        print(json.dumps(got, allow_nan=True))
        return
    trees = {"after": ROOT} | ({"before": Path(args.before).resolve()} if args.before else {})
    work = Path(tempfile.mkdtemp(prefix="detp_phases_"))
    data = {"cores": os.cpu_count(), "arena_size": args.arena_size, "crate_size": args.crate_size,
            "crates": args.crates, "cases": {}, "tracing": {}}
    cases = args.cases.split(",")
    blends = {case: str(work / f"{case}.blend") for case in ("arena", "crates")}
    for case in sorted({{"tracing": "arena"}.get(c, c) for c in cases}):
        _run_child(args, ROOT, f"build-{case}", "", blends[case])
    for case in [c for c in cases if c != "tracing"]:
        runs = {name: [] for name in trees}
        for rep in range(args.repeat):
            for name, tree in (trees.items() if rep % 2 == 0 else reversed(trees.items())):
                runs[name].append(_run_child(args, tree, case, str(work / f"{case}-{name}.npz"), blends[case]))
                print(f"{case} {name}: {runs[name][-1]['wall']:.1f} s", {k: round(v, 2) for k, v in
                                                                         runs[name][-1]["seconds"].items()}, flush=True)
        if "before" not in runs:
            runs["before"] = runs["after"]
        runs["images"] = _difference(str(work / f"{case}-before.npz"), str(work / f"{case}-after.npz")) \
            if args.before else {"equal": True, "relative_rms": 0.0}
        data["cases"][case] = runs
    if "tracing" in args.cases:
        for name, tree in trees.items():
            data["tracing"][name] = _run_child(args, tree, "tracing", "", blends["arena"])
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).write_text(json.dumps(data, indent=2, default=float))
    print(table(data))


if __name__ == "__main__":
    main()
