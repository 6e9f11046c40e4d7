"""The paper's quasi-static claim: over a frame range, the hybrid (static discs indexed once, moving
texels by the sphere cache) against disc_index and sphere_cache rebuilt every frame.

    python benchmarks/frames.py [--scene quasi_static | patio_cart] [--frames 1-24] [--photons 500000]
                                [--resolution 64] [--radius-texels 1.5 4] [--direct photons] [--out DIR]

Every frame of sample_scenes/quasi_static.blend (or of the patio with a cart crossing it, built in
memory by sample_scenes/make_patio_cart.py) is exported through the Blender adapter and its
photons go to the three estimators at once (bake.compute_many), so they see the same segments; each
estimator's time is its build (index, discs, sphere levels) plus its estimation, per frame. Prints a
table per disc radius and writes frames.json into --out (default benchmarks/results/). One run:
read the ratios, not the seconds.
"""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import scenes  # noqa: E402  (puts the repository root on sys.path)

from detp_bake import options  # noqa: E402
from detp_bake.run import bake as bake_mod  # noqa: E402
from detp_bake.estimators import EstimatorSettings, FrameState  # noqa: E402
from detp_bake.run.frames import find_motion, lights_signature, object_signatures, parse_frames  # noqa: E402

NAMES = ("hybrid", "disc_index", "sphere_cache")
COLUMNS = ("hybrid", "hybrid_di", "disc_index", "sphere_cache")  # hybrid_di: moving texels by a disc index


def frame_scenes(frames, resolution, name="quasi_static"):
    import bpy
    from detp_bake.blender import frame_exporter

    if name == "patio_cart":  # not kept as a .blend: built here
        sys.path.insert(0, str(scenes.SAMPLES))
        import make_patio_cart
        make_patio_cart.build_patio_cart()
    else:
        bpy.ops.wm.open_mainfile(filepath=str(scenes.SAMPLES / f"{name}.blend"))
    scene_at = frame_exporter(bpy.context.scene, None, None, resolution, log=lambda msg: None)
    return {f: scene_at(f) for f in frames}


def run(scenes_by_frame, radius_texels, args):
    sigs = [object_signatures(s) for s in scenes_by_frame.values()]
    motion = find_motion(sigs, [lights_signature(s) for s in scenes_by_frame.values()])
    state, state_di = FrameState(moving=frozenset(motion.moving)), FrameState(moving=frozenset(motion.moving))
    settings = bake_mod.BakeSettings(photons=args.photons, direct=args.direct, denoise=False, threads=args.threads,
                                     estimator_settings=EstimatorSettings(radius_texels=radius_texels))
    settings_di = replace(settings, estimator="hybrid", estimator_settings=replace(settings.estimator_settings,
                                                                                  hybrid_moving="disc_index"))
    rows = []
    for frame, scene in scenes_by_frame.items():
        names = [n for n in NAMES if not (args.no_sphere_cache and n == "sphere_cache")]
        results = bake_mod.compute_many(scene, settings, names, frame_state=state)
        row = {"frame": frame, "trace": results[NAMES[0]].seconds["trace"]}
        for name, r in results.items():
            row[name] = r.seconds["build"] + r.seconds["estimate"]
            row[f"{name}_build"] = r.seconds["build"]
        di = bake_mod.compute(scene, settings_di, frame_state=state_di)  # the same photons again
        row["hybrid_di"] = di.seconds["build"] + di.seconds["estimate"]
        row["rerouted"] = results["hybrid"].counters["rerouted_texels"]
        row["moving_texels"] = results["hybrid"].counters["moving_texels"]
        rows.append(row)
        print(f"  frame {frame}: " + ", ".join(f"{n} {row[n]:.3f} s" for n in COLUMNS if n in row), flush=True)
    return {"radius_texels": radius_texels, "moving": motion.moving, "frames": rows,
            "totals": {n: sum(r.get(n, float("nan")) for r in rows) for n in COLUMNS},
            "texels": len(results["hybrid"].texels)}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scene", default="quasi_static", choices=("quasi_static", "patio_cart"))
    p.add_argument("--frames", default="1-24")
    p.add_argument("--photons", type=int, default=500_000)
    p.add_argument("--resolution", type=int, default=64)
    p.add_argument("--radius-texels", type=float, nargs="+", default=[1.5, 4.0])
    p.add_argument("--direct", default="photons", choices=options.DIRECT_MODES,
                   help="photons: the paper's mode, the estimators see every segment (default)")
    p.add_argument("--threads", type=int, default=0)
    p.add_argument("--no-sphere-cache", action="store_true", help="leave out sphere_cache (slow at large sizes)")
    p.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = p.parse_args(argv)
    frames = parse_frames(args.frames).frames()
    by_frame = frame_scenes(frames, args.resolution, args.scene)
    # Warm numba's caches so the first frame is not a compile.
    warm = next(iter(by_frame.values()))
    for moving in ("sphere_cache", "disc_index"):
        bake_mod.compute_many(warm, bake_mod.BakeSettings(photons=2_000, denoise=False, direct=args.direct,
                                                          estimator_settings=EstimatorSettings(hybrid_moving=moving)),
                              NAMES, frame_state=FrameState(moving=frozenset(warm.objects[-1:] and
                                                                             [warm.objects[-1].name])))
    out = {"scene": args.scene, "photons": args.photons, "resolution": args.resolution, "direct": args.direct,
           "runs": []}
    for r in args.radius_texels:
        print(f"discs of {r} texels:", flush=True)
        out["runs"].append(run(by_frame, r, args))
    print(f"\n{args.scene}, {len(frames)} frames, {args.photons:,} photons per frame, {args.resolution}² lightmaps, "
          f"direct {args.direct}; seconds of build + estimation over the range (tracing is shared)")
    print("| disc radius | hybrid (sphere cache for movers) | hybrid (disc index for movers) | disc_index | "
          "sphere_cache | best hybrid / best other |")
    print("|---|---|---|---|---|---|")
    for run_ in out["runs"]:
        t = run_["totals"]
        best = min(t["disc_index"], t["sphere_cache"]) if t["sphere_cache"] == t["sphere_cache"] else t["disc_index"]
        print(f"| {run_['radius_texels']:g} texels | {t['hybrid']:.2f} | {t['hybrid_di']:.2f} | {t['disc_index']:.2f} | "
              f"{t['sphere_cache']:.2f} | {min(t['hybrid'], t['hybrid_di']) / best:.2f} |")
    target = Path(args.out)
    target.mkdir(parents=True, exist_ok=True)
    name = "frames.json" if args.scene == "quasi_static" else f"frames_{args.scene}.json"
    (target / name).write_text(json.dumps(out, indent=2, allow_nan=False))
    print(target / name)


if __name__ == "__main__":
    main()
