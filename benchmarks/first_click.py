"""The first click: a new Blender session's first bake of the Cornell box, from the click to the
first photon batch traced (export, kernel compile or load, rasterise, direct light, disc build).

    python benchmarks/first_click.py [--json OUT] [--photons N]

Every case is a fresh process (the bpy wheel: a new Blender session) that registers the
extension, opens the Cornell box and runs the Bake operator's job, timed from the click to the
job's first "trace" progress event:
  cold           numba's cache empty: every kernel compiles at the click (a first session ever);
  cold, warm-up  the same, but the extension's warm-up (detp_bake/run/warmup.py) ran when it was
                 enabled and finished before the click;
  warm           the cache filled by an earlier session (the extension keeps it in its user
                 folder): kernels load at the click;
  warm, warm-up  a filled cache and the warm-up done before the click (the usual case).
The warm-up's own seconds are reported too: they run in the background while Blender starts.
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

ROOT = Path(__file__).resolve().parents[1]
RESULTS = Path(__file__).resolve().parent / "results" / "first_click.json"
CASES = (("cold", False, False), ("cold, warm-up", False, True), ("warm", True, False), ("warm, warm-up", True, True))


def child(photons: int, warm_up: bool) -> dict:
    """One Blender session: register, open, (warm up,) click, wait for tracing to start."""
    sys.path.insert(0, str(ROOT / "tests"))
    t_start = time.perf_counter()
    import bpy
    from test_addon import _import_addon  # the repository root as the extension package
    addon = _import_addon()
    addon.register()
    from detp_bake.run import job as job_mod, warmup
    from detp_bake_addon.operators.bake import BakeJob
    out = {"import_register": time.perf_counter() - t_start}
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "sample_scenes" / "cornell_box.blend"))
    s = bpy.context.scene.detp_bake
    s.photons, s.output_directory, s.live_preview = photons, tempfile.mkdtemp(), False
    if warm_up:
        warmup.start()
        warmup.wait()
        out["warm_up"] = warmup.seconds
    t0 = time.perf_counter()  # the click
    job = BakeJob(bpy.context)
    job.prepare(bpy.context)
    out["export"] = time.perf_counter() - t0
    for event in job.job.events():
        if isinstance(event, job_mod.Phase) and event.phase == "trace" and "to_trace" not in out:
            out["to_trace"] = time.perf_counter() - t0
        if isinstance(event, job_mod.Status) and event.phase == "trace" and "first_batch" not in out:
            out["first_batch"] = time.perf_counter() - t0
        job.handle([event])
    out["bake"] = time.perf_counter() - t0
    assert job.finish(lambda kind, msg: None) == {"FINISHED"}
    addon.unregister()
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photons", type=int, default=200_000)
    ap.add_argument("--json", default=str(RESULTS))
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--warm-up", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.photons, args.warm_up), allow_nan=False))
        return 0
    rows = []
    for name, warm_cache, warm_up in CASES:
        cache = Path(tempfile.mkdtemp(prefix="detp_first_click_"))
        env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(ROOT),
                   BLENDER_USER_RESOURCES=tempfile.mkdtemp())
        cmd = [sys.executable, __file__, "--child", "--photons", str(args.photons)]
        if warm_cache:  # an earlier session filled the cache
            subprocess.run(cmd, env=env, check=True, capture_output=True)
        if warm_up:
            cmd.append("--warm-up")
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
        if proc.returncode:
            print(proc.stderr[-3000:], file=sys.stderr)
            return proc.returncode
        row = json.loads(proc.stdout.strip().splitlines()[-1])
        row["case"] = name
        rows.append(row)
        print(f"{name:14s}  click→tracing {row['to_trace']:6.2f} s  (export {row['export']:.2f} s, first batch "
              f"{row['first_batch']:.2f} s, whole bake {row['bake']:.2f} s"
              + (f"; warm-up {row['warm_up']:.2f} s before the click" if "warm_up" in row else "") + ")", flush=True)
    doc = {"cores": os.cpu_count(), "load_average": os.getloadavg()[0], "photons": args.photons,
           "python": sys.version.split()[0], "rows": rows}
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).write_text(json.dumps(doc, indent=2, allow_nan=False))
    print(f"load average {doc['load_average']:.1f}, {doc['cores']} cores; {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
