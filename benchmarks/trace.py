"""Photon-tracing throughput of `PhotonTracer` against raw Embree on exactly the same rays.

    python benchmarks/trace.py [--photons N] [--quick] [--json OUT] [--threads T] [--repeats R]

For each scene (the Cornell box and a 100k-triangle room) the tracer runs once with a hook on
`RayCaster.intersect` that records every ray it sends to Embree; then, alternately and `repeats`
times, the tracer runs unhooked (ours) and the recorded rays are re-traced with plain
`EmbreeScene.run(..., output=True)`, one `run` per recorded call, as the tracer makes them, all
calls spread over a pool of the same number of threads (raw: Embree alone, with no dependencies
between calls, so perfectly load-balanced). Both exclude the BVH build; ours includes emission
and everything else a batch needs. The overhead ratio ours/raw − 1 is what we watch: it is
measured side by side in one run, so it holds across machines where absolute timings do not (on
a shared machine, mind the load average printed with it).
"""
from __future__ import annotations

import argparse
import inspect
import json
import os
import platform
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import scenes  # noqa: E402  (puts the repository root on sys.path)

from detp_bake.transport.photons import PhotonTracer  # noqa: E402
from detp_bake.rays import RayCaster  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results" / "trace.json"


def record_rays(scene, photons: int, threads: int, seed: int):
    """Trace once, keeping a float32 copy of each batch of rays the tracer sends to Embree."""
    calls = []
    original = RayCaster.hits  # the tracer's one call into Embree

    def hooked(self, origins, dirs, *args, **kwargs):
        calls.append((np.array(origins, np.float32), np.array(dirs, np.float32)))
        return original(self, origins, dirs, *args, **kwargs)

    RayCaster.hits = hooked
    try:
        tracer = PhotonTracer(scene, photons, scene.default_bounces, seed, threads=threads)
        for _ in tracer.batches():
            pass
    finally:
        RayCaster.hits = original
    return calls, tracer.stats


def time_ours(scene, photons: int, threads: int, seed: int):
    """Wall and CPU (all threads) time of a whole trace (every batch produced), less the ray
    caster's construction."""
    build, build_cpu = [], []
    original = RayCaster.__init__

    def timed_init(self, *args, **kwargs):
        t0, c0 = time.perf_counter(), time.process_time()
        original(self, *args, **kwargs)
        _commit(self.scene)
        build.append(time.perf_counter() - t0)
        build_cpu.append(time.process_time() - c0)

    RayCaster.__init__ = timed_init
    try:
        tracer = PhotonTracer(scene, photons, scene.default_bounces, seed, threads=threads)
        t0, c0 = time.perf_counter(), time.process_time()
        for _ in tracer.batches():
            pass
        seconds = time.perf_counter() - t0 - sum(build)
        cpu = time.process_time() - c0 - sum(build_cpu)
    finally:
        RayCaster.__init__ = original
    return seconds, cpu, tracer.stats


def _commit(embree_scene):
    """embreex builds the BVH lazily, on the first `run`: one ray forces it."""
    embree_scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), output=True)


class RawEmbree:
    """The scene's triangles in a plain EmbreeScene, committed before any timing."""

    def __init__(self, scene, threads: int):
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        self.scene = rtcore_scene.EmbreeScene()
        self.mesh = TriangleMesh(self.scene, np.ascontiguousarray(scene.positions, np.float32))
        _commit(self.scene)
        self.threads = threads
        self.pool = ThreadPoolExecutor(threads)

    def trace(self, calls) -> tuple[float, float]:
        """Wall and CPU seconds to run every recorded call, each one `run` as the tracer makes
        it, all of them spread over the threads."""
        run = self.scene.run
        t0, c0 = time.perf_counter(), time.process_time()
        jobs = [self.pool.submit(run, origins, dirs, output=True) for origins, dirs in calls]
        for j in jobs:
            j.result()
        return time.perf_counter() - t0, time.process_time() - c0

    def close(self):
        self.pool.shutdown()


def measure(name: str, scene, photons: int, threads: int, repeats: int, seed: int = 1) -> dict:
    time_ours(scene, min(photons, 20_000), threads, seed)  # numba cache load, Embree start-up
    calls, stats = record_rays(scene, photons, threads, seed)
    raw = RawEmbree(scene, threads)
    raw.trace(calls[:2])
    ours_s, raw_s, ours_cpu, raw_cpu = [], [], [], []
    for _ in range(repeats):
        s, cpu, st = time_ours(scene, photons, threads, seed)
        ours_s.append(s)
        ours_cpu.append(cpu)
        s, cpu = raw.trace(calls)
        raw_s.append(s)
        raw_cpu.append(cpu)
    raw.close()
    assert st.rays == sum(len(c[0]) for c in calls), "the timed trace sent different rays"
    ours, embree = min(ours_s), min(raw_s)
    paired = sorted(a / b - 1.0 for a, b in zip(ours_s, raw_s))
    return {
        "scene": name, "triangles": scene.triangle_count, "photons": stats.photons,
        "bounces": scene.default_bounces, "rays": stats.rays, "segments": stats.segments,
        "hits": stats.hits, "embree_calls": len(calls), "threads": threads,
        "ours_seconds": ours, "raw_embree_seconds": embree, "overhead": ours / embree - 1.0,
        "overhead_paired_median": paired[len(paired) // 2],
        "ours_cpu_seconds": min(ours_cpu), "raw_embree_cpu_seconds": min(raw_cpu),
        "cpu_overhead": min(ours_cpu) / min(raw_cpu) - 1.0,
        "segments_per_second": stats.segments / ours, "photons_per_second": stats.photons / ours,
        "raw_rays_per_second": stats.rays / embree,
        "ours_seconds_all": ours_s, "raw_embree_seconds_all": raw_s,
        "ours_cpu_seconds_all": ours_cpu, "raw_embree_cpu_seconds_all": raw_cpu,
    }


def environment(threads: int) -> dict:
    import embreex
    import numba

    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=scenes.ROOT,
                                capture_output=True, text=True).stdout.strip()
        dirty = bool(subprocess.run(["git", "status", "--porcelain", "--", "detp_bake"], cwd=scenes.ROOT,
                                    capture_output=True, text=True).stdout.strip())
    except OSError:
        commit, dirty = "", False
    return {"python": platform.python_version(), "numpy": np.__version__, "numba": numba.__version__,
            "embreex": getattr(embreex, "__version__", "?"), "cpus": os.cpu_count(), "threads": threads,
            "machine": platform.machine(), "processor": platform.processor(),
            "git": commit + ("+dirty" if dirty else ""),
            "batch_size": inspect.signature(PhotonTracer).parameters["batch_size"].default}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--photons", type=int, default=None, help="photons per scene (default 1M, 200k with --quick)")
    ap.add_argument("--quick", action="store_true", help="fewer photons and one repeat")
    ap.add_argument("--json", type=Path, default=RESULTS, help=f"results file (default {RESULTS})")
    ap.add_argument("--threads", type=int, default=0, help="threads (default: numba's thread count)")
    ap.add_argument("--repeats", type=int, default=None,
                    help="timed runs per scene, ours and raw alternately (default 5, 1 with --quick)")
    args = ap.parse_args(argv)
    photons = args.photons or (200_000 if args.quick else 1_000_000)
    repeats = args.repeats or (1 if args.quick else 5)
    import numba
    threads = args.threads or numba.config.NUMBA_NUM_THREADS

    cases = [("cornell_box", scenes.cornell_box()), ("dense_room", scenes.dense_room())]
    load = [os.getloadavg()[0]]
    if load[0] > 0.5:
        print(f"warning: load average {load[0]:.2f} before timing: other processes share the cores")
    rows = [measure(name, sc, photons, threads, repeats) for name, sc in cases]
    load.append(os.getloadavg()[0])

    head = f"{'scene':<12} {'tris':>7} {'photons':>9} {'segments':>10} {'ours s':>8} {'raw s':>8} " \
           f"{'overhead':>9} {'paired':>7} {'cpu':>7} {'Mseg/s':>7} {'Mph/s':>6}"
    print(head)
    print("-" * len(head))
    for r in rows:
        print(f"{r['scene']:<12} {r['triangles']:>7} {r['photons']:>9} {r['segments']:>10} "
              f"{r['ours_seconds']:>8.3f} {r['raw_embree_seconds']:>8.3f} {r['overhead']:>+9.1%} "
              f"{r['overhead_paired_median']:>+7.1%} {r['cpu_overhead']:>+7.1%} "
              f"{r['segments_per_second'] / 1e6:>7.2f} {r['photons_per_second'] / 1e6:>6.2f}")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    print(f"overhead = fastest ours / fastest raw - 1 (wall); paired = median over repeats of ours/raw - 1; "
          f"cpu = the same with CPU time of all threads (steadier when other processes share the cores); "
          f"load average {load[0]:.2f} -> {load[1]:.2f}")
    args.json.write_text(json.dumps({"benchmark": "trace", "environment": environment(threads),
                                     "photons": photons, "repeats": repeats, "load_average": load,
                                     "results": rows}, indent=2, allow_nan=False))
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
