"""Sites (the indirect estimate on every second texel, detp_bake/lightmap/sites.py) against every texel, by
lightmap size: wall seconds and error of the default bake with `indirect_spacing` 1 and 2.

    python benchmarks/sites.py [--scene l_room] [--resolutions 64,128,256] [--photons 250000,1000000]
                               [--seeds 2] [--reference 16000000] [--json OUT]

Error: relative RMSE over the texels whose centre lies on the surface, against a bake of the same
scene with every texel estimated and `--reference` photons (another seed). Both spacings share that
reference's bias against Cycles (DETP's own), so the comparison measures what the sites add: the
blend's blur and the noise of fewer estimates. Runs alternate between the spacings, so a slow spell
on a shared machine hits both; read the ratios. Writes JSON (default benchmarks/results/sites.json).
This is where `sites.AUTO_FROM` comes from.
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

from detp_bake.run.bake import BakeSettings, compute  # noqa: E402

ESTIMATOR = "disc_index"  # sites serve the disc estimators (the texel histogram estimates every texel)


def rmse(result, ref) -> float:
    diff, base = [], []
    for lm in result.texels.lightmaps:
        m = ref.centre_masks[lm.name]
        diff.append((result.images[lm.name][m] - ref.images[lm.name][m]).ravel())
        base.append(ref.images[lm.name][m].ravel())
    d, b = np.concatenate(diff), np.concatenate(base)
    return float(np.sqrt(np.mean(d.astype(np.float64) ** 2)) / np.mean(b))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="l_room")
    ap.add_argument("--resolutions", default="64,128,256")
    ap.add_argument("--photons", default="250000,1000000")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--reference", type=int, default=16_000_000)
    ap.add_argument("--json", default=str(Path(__file__).resolve().parent / "results" / "sites.json"))
    args = ap.parse_args(argv)
    photon_counts = [int(p) for p in args.photons.split(",")]
    rows = []
    print(f"{os.cpu_count()} cores, {numba.get_num_threads()} threads; scene {args.scene}", flush=True)
    print(f"{'res':>5} {'photons':>10} {'spacing':>7} {'sites':>8} {'texels':>8} {'wall s':>7} {'RMSE %':>7}")
    for res in [int(r) for r in args.resolutions.split(",")]:
        with scenes.quiet_stdout():
            sc = scenes.blend_scene(args.scene, res)
        ref = compute(sc, BakeSettings(estimator=ESTIMATOR, photons=args.reference, resolution=res, indirect_spacing=1,
                                       seed=99))
        for spacing in (1, 2):  # kernels loaded outside the timings
            compute(sc, BakeSettings(estimator=ESTIMATOR, photons=2000, resolution=res, indirect_spacing=spacing))
        for photons in photon_counts:
            for seed in range(1, args.seeds + 1):
                for spacing in (1, 2):
                    t0 = time.perf_counter()
                    r = compute(sc, BakeSettings(estimator=ESTIMATOR, photons=photons, resolution=res,
                                                 indirect_spacing=spacing, seed=seed))
                    wall = time.perf_counter() - t0
                    row = {"resolution": res, "photons": photons, "spacing": spacing, "seed": seed, "seconds": wall,
                           "rmse": rmse(r, ref), "sites": r.direct["indirect_sites"], "texels": len(r.texels),
                           "phases": {k: round(v, 4) for k, v in r.seconds.items()}, "load": os.getloadavg()[0]}
                    rows.append(row)
                    print(f"{res:>5} {photons:>10,} {spacing:>7} {row['sites']:>8,} {row['texels']:>8,} "
                          f"{wall:>7.2f} {100 * row['rmse']:>7.2f}", flush=True)
    print("\nspacing 2 against 1, means over seeds: time ratio, RMSE ratio")
    summary = []
    for res in sorted({r["resolution"] for r in rows}):
        for photons in photon_counts:
            pick = lambda s, k: np.mean([r[k] for r in rows if (r["resolution"], r["photons"], r["spacing"]) == (res, photons, s)])
            t, e = pick(2, "seconds") / pick(1, "seconds"), pick(2, "rmse") / pick(1, "rmse")
            summary.append({"resolution": res, "photons": photons, "time_ratio": t, "rmse_ratio": e})
            print(f"{res:>5}² {photons:>10,} photons: time {t:.2f}, RMSE {e:.3f}")
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"scene": args.scene, "cores": os.cpu_count(), "reference_photons": args.reference,
                               "rows": rows, "summary": summary}, indent=1, allow_nan=False))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
