"""Light probes: the two estimators against a reference, error and seconds, and what a 16³ grid
adds to a 1024² bake (docs/probes.md).

    python benchmarks/probes.py [--scene cornell_box] [--resolution 64] [--photons 2000000]
                                [--rays 64,256,1024,4096] [--sphere-photons 1000000,4000000]
                                [--reference 32768] [--cost-resolution 1024] [--json OUT]

A 4×4×4 grid inside the scene's box. The reference is the final gather with `--reference` rays per
probe from the lightmaps of a bake of `--photons`. (a) the final gather with each `--rays` from the
same lightmaps; (b) photon segments crossing each probe's sphere (photon_sphere.py), from the
indirect photons of a bake of each `--sphere-photons` (the bake's own batches: their tracing is the
bake's, the column `trace s` says what it took), plus its direct light by shadow rays and a gather
of the sky and emitters of 256 rays. Error: the relative RMS over the probes and six normals of the
irradiance E/π the SH reconstructs, against the reference. `err²·s`: equal for two estimators that
reach the same error in the same time; lower is better. Then the cost: a bake of one object at
`--cost-resolution`² with and without a 16³ Light Probe Volume over the scene (default rays).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import scenes  # noqa: E402  (puts the repository root on sys.path)

import numpy as np  # noqa: E402

from detp_bake.probes import gather as gather_mod, photon_sphere, sh9, validity  # noqa: E402
from detp_bake.probes.grid import ProbeGrid  # noqa: E402
from detp_bake.rays import RayCaster  # noqa: E402
from detp_bake.run.bake import BakeSettings, compute  # noqa: E402
from detp_bake.scene import ProbeVolume  # noqa: E402
from detp_bake.transport.photons import PhotonTracer  # noqa: E402

AXES = np.vstack([np.eye(3), -np.eye(3)])


def _box_grid(scene, res, shrink=0.8) -> ProbeGrid:
    pts = scene.positions.reshape(-1, 3)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    m = np.eye(4)
    m[:3, :3] = np.diag(0.5 * shrink * (hi - lo))
    m[:3, 3] = 0.5 * (lo + hi)
    return ProbeGrid.full("bench", m, res)


def _error(coefficients, reference, valid) -> float:
    ours = sh9.irradiance(coefficients[valid][:, None], AXES[None])
    ref = sh9.irradiance(reference[valid][:, None], AXES[None])
    return float(np.sqrt(np.mean((ours - ref) ** 2)) / np.mean(np.abs(ref)))


def _gather(scene, caster, images, grid, rays, samples=16, found=None):
    lit = gather_mod.lighting(scene, caster, images, samples, seed=1)
    t0 = time.perf_counter()
    answer = gather_mod.gather(lit, grid.positions, rays)
    if found is not None:
        found.update(answer)
    return answer["coefficients"], time.perf_counter() - t0


def _spheres(scene, caster, grid, photons, bounces, radius, clear):
    """(coefficients, seconds of the spheres and the direct part, seconds of tracing)."""
    tracer = PhotonTracer(scene, photons, bounces, seed=0, indirect_only=True, caster=caster)
    spheres = photon_sphere.SphereGather([grid], radius=radius, clear=clear)
    spent, t0 = 0.0, time.perf_counter()
    for batch in tracer.batches():
        t1 = time.perf_counter()
        spheres.add(batch)
        spent += time.perf_counter() - t1
    trace = time.perf_counter() - t0 - spent
    direct, seconds = _gather(scene, caster, {}, grid, 256)  # no lightmaps: sky, emitters, lights
    return spheres.coefficients() + direct, spent + seconds, trace


def compare(args) -> list:
    with scenes.quiet_stdout():
        scene = scenes.blend_scene(args.scene, args.resolution)
    scene, _ = scene.recentred()
    # Many bounces: a probe reading a lightmap adds one (docs/probes.md), the spheres do not.
    result = compute(scene, BakeSettings(photons=args.photons, seed=1, bounces=16))
    caster = RayCaster(scene.positions)
    grid = _box_grid(scene, (4, 4, 4))
    _gather(scene, caster, result.images, grid, 16)  # compiled before timing
    found = {}
    reference, ref_seconds = _gather(scene, caster, result.images, grid, args.reference, found=found)
    # Probes inside the boxes (validity.py would move them) are left out of the error.
    valid = found["back_share"] <= validity.BACK_LIMIT
    rows = [{"estimator": "reference gather", "setting": f"{args.reference} rays", "seconds": ref_seconds,
             "error": 0.0}]
    for rays in (int(r) for r in args.rays.split(",")):
        c, seconds = _gather(scene, caster, result.images, grid, rays)
        rows.append({"estimator": "final gather", "setting": f"{rays} rays", "seconds": seconds,
                     "error": _error(c, reference, valid)})
    _spheres(scene, caster, grid, 20_000, result.bounces, photon_sphere.RADIUS, found["nearest"])  # compile
    for photons in (int(p) for p in args.sphere_photons.split(",")):
        for radius in (0.25, photon_sphere.RADIUS):
            c, seconds, trace = _spheres(scene, caster, grid, photons, result.bounces, radius, found["nearest"])
            rows.append({"estimator": "photon spheres", "setting": f"{photons / 1e6:g}M photons, r {radius:g} cell",
                         "seconds": seconds, "trace_seconds": trace, "error": _error(c, reference, valid)})
    valid_count[0] = int(valid.sum())
    return rows


valid_count = [0]


def cost(args) -> dict:
    """A bake of the scene's first baked object at --cost-resolution², without probes and with a 16³
    volume over the scene (the default probe rays)."""
    with scenes.quiet_stdout():
        scene = scenes.blend_scene(args.scene, args.cost_resolution)
    first = next(o for o in scene.objects if o.bake)
    for o in scene.objects:
        o.bake = o is first
    grid = _box_grid(scene, (16, 16, 16))
    out = {"object": first.name, "resolution": args.cost_resolution}
    volume = [ProbeVolume("bench", grid.matrix, (16, 16, 16))]
    runs = (("without", [], "off"), ("with", volume, "volumes"))
    for label, volumes, mode in runs[::-1]:  # compiled and loaded first: a session's first bake pays that once
        scene.probe_volumes = volumes
        compute(scene, BakeSettings(probes=mode, photons=100_000, resolution=16, seed=1))
    for label, volumes, mode in runs + runs:  # each twice, the faster counts (a shared machine)
        scene.probe_volumes = volumes
        t0 = time.perf_counter()
        r = compute(scene, BakeSettings(probes=mode, seed=1))
        seconds = time.perf_counter() - t0
        out[f"{label}_seconds"] = min(seconds, out.get(f"{label}_seconds", seconds))
        out[f"{label}_photons"] = r.stats.photons
        if r.probe_info:
            out["probe_seconds"] = min(r.probe_info["seconds"], out.get("probe_seconds", 1e9))
            out["probes"], out["invalid"] = r.probe_info["count"], r.probe_info["invalid"]
    out["added"] = out["with_seconds"] / out["without_seconds"] - 1.0
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="cornell_box")
    ap.add_argument("--resolution", type=int, default=64)
    ap.add_argument("--photons", type=int, default=2_000_000)
    ap.add_argument("--rays", default="64,256,1024,4096")
    ap.add_argument("--sphere-photons", default="1000000,4000000")
    ap.add_argument("--reference", type=int, default=32768)
    ap.add_argument("--cost-resolution", type=int, default=1024)
    ap.add_argument("--skip-cost", action="store_true")
    ap.add_argument("--only-cost", action="store_true")
    ap.add_argument("--json", default=str(Path(__file__).resolve().parent / "results" / "probes.json"))
    args = ap.parse_args(argv)
    rows = [] if args.only_cost else compare(args)
    print(f"{'estimator':<16} {'setting':<28} {'seconds':>8} {'trace s':>8} {'error':>8} {'err²·s':>10}")
    for r in rows:
        print(f"{r['estimator']:<16} {r['setting']:<28} {r['seconds']:8.3f} {r.get('trace_seconds', 0):8.2f} "
              f"{r['error']:8.4f} {r['error'] ** 2 * r['seconds']:10.3g}")
    doc = {"scene": args.scene, "probes": 64, "measured": valid_count[0], "rows": rows}
    if rows:
        print(f"({valid_count[0]} of 64 probes outside the boxes are measured)")
    if not args.skip_cost:
        doc["cost"] = c = cost(args)
        print(f"cost: {c['object']} at {c['resolution']}²: {c['without_seconds']:.1f} s without probes, "
              f"{c['with_seconds']:.1f} s with {c['probes']} ({c['invalid']} invalid; the probes {c['probe_seconds']:.2f} s): "
              f"{100 * c['added']:+.1f} % wall, the probe stage {100 * c['probe_seconds'] / c['without_seconds']:.1f} % "
              "of the bake without")
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).write_text(json.dumps(doc, indent=2))


if __name__ == "__main__":
    main()
