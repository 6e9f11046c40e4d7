"""The cost of directional lightmaps (--directional sh) and of a shadowmask over a plain bake, in
one run: the same scene, photons and seed baked plain, with sh, with a one-light shadowmask and
with both, for the texel histogram (denoised) and disc_index (not).

    python benchmarks/directional.py [--triangles 20000] [--resolution 128] [--photons 2000000]
                                     [--estimators texel_histogram,disc_index] [--json OUT]

Prints a table (seconds of the whole compute, of the direct light, the estimate, the denoiser and
the directional images; the memory estimate) and writes JSON (default
benchmarks/results/directional.json). Each setting is baked twice and the second timing kept
(compiled kernels loaded by then).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks.scenes import dense_room  # noqa: E402
from detp_bake.run.bake import BakeSettings, compute  # noqa: E402

CASES = {"none": {}, "sh": {"directional": "sh"}, "shadowmask": {"shadowmask": ("Bulb",)},
         "sh+shadowmask": {"directional": "sh", "shadowmask": ("Bulb",)}}


def run(triangles: int, resolution: int, photons: int, names) -> list:
    rows = []
    for estimator in names:
        base = BakeSettings(estimator=estimator, photons=photons, seed=1, denoise=estimator == "texel_histogram")
        for case, extra in CASES.items():
            settings = replace(base, **extra)
            for _ in range(2):
                scene = dense_room(triangles)
                for obj in scene.objects:
                    obj.resolution = resolution
                t0 = time.perf_counter()
                result = compute(scene, settings)
                seconds = time.perf_counter() - t0
            s = result.seconds
            rows.append({"estimator": estimator, "case": case, "seconds": round(seconds, 3),
                         "direct": round(s.get("direct", 0.0), 3), "estimate": round(s.get("estimate", 0.0), 3),
                         "denoise": round(s.get("denoise", 0.0), 3), "directional": round(s.get("directional", 0.0), 3),
                         "memory_estimate_mb": result.memory["estimate_mb"], "texels": len(result.texels)})
    for row in rows:
        plain = next(r for r in rows if r["estimator"] == row["estimator"] and r["case"] == "none")
        row["over_none"] = round(row["seconds"] / plain["seconds"], 3)
        row["memory_over_none"] = round(row["memory_estimate_mb"] / plain["memory_estimate_mb"], 3)
    return rows


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--triangles", type=int, default=20_000)
    p.add_argument("--resolution", type=int, default=128)
    p.add_argument("--photons", type=int, default=2_000_000)
    p.add_argument("--estimators", default="texel_histogram,disc_index")
    p.add_argument("--json", default=str(ROOT / "benchmarks" / "results" / "directional.json"))
    args = p.parse_args(argv)
    rows = run(args.triangles, args.resolution, args.photons, args.estimators.split(","))
    head = f"{'estimator':16} {'case':14} {'s':>7} {'x none':>7} {'direct':>7} {'estim.':>7} {'denoise':>7} " \
           f"{'dir.':>6} {'MB est.':>8} {'x none':>7}"
    print(head)
    for r in rows:
        print(f"{r['estimator']:16} {r['case']:14} {r['seconds']:7.2f} {r['over_none']:7.2f} {r['direct']:7.2f} "
              f"{r['estimate']:7.2f} {r['denoise']:7.2f} {r['directional']:6.2f} {r['memory_estimate_mb']:8.1f} "
              f"{r['memory_over_none']:7.2f}")
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"args": vars(args), "rows": rows}, indent=2, allow_nan=False))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
