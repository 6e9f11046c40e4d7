"""Shadow rays shared among lights by what each gives a texel (direct.light_shares) against the
same rays for every light: error and wall seconds of the direct pass alone, side by side.

    python benchmarks/lights.py [--scenes l_room,window_room] [--resolution 64] [--samples 8,16,32]
                                [--reference 256] [--json OUT]

For each scene, every texel's direct irradiance with `--direct-samples` of each list entry, with and
without the sharing, two seeds each (the faster of the two is timed), and its relative RMSE over the
texels whose centre lies on the surface against the same pass at `--reference` samples without
sharing. Both share that reference, so the comparison is of noise per second. The column
`rmse·√s` is the error times the square root of the seconds: equal for two methods that reach
the same error in the same time. Writes JSON (default benchmarks/results/lights.json).
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

from detp_bake.transport.direct import direct_irradiance  # noqa: E402
from detp_bake.rays import RayCaster  # noqa: E402
from detp_bake.lightmap.texels import rasterise  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="l_room,window_room")
    ap.add_argument("--resolution", type=int, default=64)
    ap.add_argument("--samples", default="8,16,32")
    ap.add_argument("--reference", type=int, default=256)
    ap.add_argument("--json", default=str(Path(__file__).resolve().parent / "results" / "lights.json"))
    args = ap.parse_args(argv)
    threads = numba.get_num_threads()
    print(f"{os.cpu_count()} cores, {threads} threads", flush=True)
    print(f"{'scene':>12} {'samples':>7} {'shared':>6} {'rays':>10} {'seconds':>8} {'RMSE %':>7} {'rmse·√s':>8}")
    rows = []
    for name in args.scenes.split(","):
        with scenes.quiet_stdout():
            sc = scenes.blend_scene(name, args.resolution)
        sc, _ = sc.recentred()
        for obj in sc.objects:
            if obj.bake and obj.resolution <= 0:
                obj.resolution = args.resolution
        texels = rasterise(sc)
        caster = RayCaster(sc.positions)
        ref, _ = direct_irradiance(sc, texels, caster, args.reference, 99, threads, select=False)
        mask = texels.centre_inside & (ref.sum(axis=1) > 0)
        base = float(ref[mask].sum(axis=1).mean())
        for samples in [int(x) for x in args.samples.split(",")]:
            for select in (False, True):
                seconds, info, e = [], None, None
                for seed in (1, 2):
                    t0 = time.perf_counter()
                    e, info = direct_irradiance(sc, texels, caster, samples, seed, threads, select=select)
                    seconds.append(time.perf_counter() - t0)
                err = float(np.sqrt(np.mean((e[mask].sum(axis=1) - ref[mask].sum(axis=1)) ** 2)) / base)
                row = {"scene": name, "samples": samples, "shared": select, "lights": info["lights"],
                       "shared_lights": info["shared"], "rays": info["rays"], "seconds": min(seconds), "rmse": err}
                rows.append(row)
                print(f"{name:>12} {samples:>7} {str(select):>6} {info['rays']:>10,} {min(seconds):>8.3f} "
                      f"{100 * err:>7.2f} {100 * err * np.sqrt(min(seconds)):>8.3f}", flush=True)
    summary = []
    for r in rows:
        if r["shared"]:
            other = next(o for o in rows if o["scene"] == r["scene"] and o["samples"] == r["samples"]
                         and not o["shared"])
            gain = (other["rmse"] ** 2 * other["seconds"]) / (r["rmse"] ** 2 * r["seconds"])
            summary.append({"scene": r["scene"], "samples": r["samples"], "efficiency": gain})
            print(f"{r['scene']}, {r['samples']} samples: shared rays are {gain:.2f}× as efficient "
                  f"(1/(RMSE²·time), same reference)")
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"cores": os.cpu_count(), "threads": threads, "resolution": args.resolution,
                               "reference": args.reference, "rows": rows, "summary": summary},
                               indent=1, allow_nan=False))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
