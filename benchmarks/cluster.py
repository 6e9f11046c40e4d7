"""Throughput of distributed bakes (detp_bake/run/distributed.py) against the in-process bake. (Not
named distributed.py: with benchmarks/ first on sys.path it would shadow Dask's `distributed`.)

    python benchmarks/cluster.py [--photons N] [--workers 1 2 ...] [--estimator disc_index] [--json OUT]

Bakes the Cornell box (sampled direct light, so the photons carry indirect light only) in this
process on all cores, then on a LocalCluster of each worker count in turn (one thread per worker,
the cores shared between them), and reports photons per second through tracing and estimation
(the bake's trace phase: direct light and the estimator's build are the same on both paths and left
out), the overhead of the distributed path at equal cores, and whether the lightmaps are identical
(they must be). The cluster's start-up is timed apart. On a shared machine mind the load average.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import scenes  # noqa: E402  (puts the repository root on sys.path)

from detp_bake.run.bake import BakeSettings, compute  # noqa: E402
from detp_bake.run.distributed import Cluster  # noqa: E402


def trace_seconds(result) -> float:
    """Seconds from the first photon to the last block added (trace + estimate, wall clock)."""
    return result.cluster.get("seconds") or result.seconds["trace"] + result.seconds["estimate"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--photons", type=int, default=2_000_000)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--estimator", default="disc_index")
    parser.add_argument("--resolution", type=int, default=64)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    cores = os.cpu_count() or 1
    sc = scenes.cornell_box(args.resolution)
    settings = BakeSettings(estimator=args.estimator, photons=args.photons, denoise=False)
    compute(sc, BakeSettings(estimator=args.estimator, photons=20_000, denoise=False))  # compile, warm caches
    t0 = time.perf_counter()
    here = compute(sc, settings)
    rows = [{"path": "in-process", "workers": 0, "cores": cores, "seconds": trace_seconds(here),
             "total_seconds": time.perf_counter() - t0, "identical": True}]
    for n in args.workers:
        t0 = time.perf_counter()
        with Cluster(workers=n) as cluster:
            start = time.perf_counter() - t0
            compute(sc, BakeSettings(estimator=args.estimator, photons=20_000, denoise=False), cluster=cluster)
            t0 = time.perf_counter()
            far = compute(sc, settings, cluster=cluster)
            rows.append({"path": "LocalCluster", "workers": n, "cores": min(n, cores), "seconds": trace_seconds(far),
                         "total_seconds": time.perf_counter() - t0, "startup_seconds": start,
                         "units": far.cluster["units"], "identical": bool(np.array_equal(here.value, far.value))})
    base = rows[0]["seconds"] * rows[0]["cores"]  # core-seconds in process
    print(f"{args.photons:,} photons, {args.estimator}, {cores} cores, load {os.getloadavg()[0]:.2f}")
    print(f"{'path':14} {'workers':>7} {'cores':>5} {'Mphotons/s':>10} {'overhead':>9} {'units':>5} identical")
    for r in rows:
        r["photons_per_second"] = args.photons / r["seconds"]
        r["overhead"] = r["seconds"] * r["cores"] / base - 1.0 if r["workers"] else 0.0
        print(f"{r['path']:14} {r['workers']:7d} {r['cores']:5d} {r['photons_per_second'] / 1e6:10.3f} "
              f"{100 * r['overhead']:8.1f}% {r.get('units', '-')!s:>5} {r['identical']}")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps({"photons": args.photons, "cores": cores, "rows": rows}, indent=2,
                                               allow_nan=False))


if __name__ == "__main__":
    main()
