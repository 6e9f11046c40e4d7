"""The race against Cycles on a real room (issue 33): the default bake and Cycles' own bake + OIDN
on the same scene, the same lightmap UVs and the same texels, in one run on one machine; for each,
its error against a long Cycles bake and its seconds, and each of ours as a multiple of the time
Cycles + OIDN takes to reach the same error.

    python benchmarks/race.py [--scene living_room] [--resolution 128] [--photons 0,1e6,2e6,4e6,8e6]
        [--spp 4,8,16,32,64] [--reference-spp 512] [--reference FILE.npz] [--code DIR ...]
        [--json OUT] [--record]

The scene is one of sample_scenes/downloaded/ (or a .blend path). Its meshes get the Lightmap UVs
the bake makes (xatlas), saved once into a work file that every side then reads. The reference,
Cycles at `--reference-spp`, is kept in `--reference` (written when missing) so that runs agree.
Ours: `compute` with the default settings but for the photon count (0: the automatic one), each
`--code` checkout in a child process of its own (`--code A --code B`: before and after a change,
side by side), timed from the export out of Blender to the finished images, after a warm-up bake
(numba's and OIDN's loading is paid once per process, as in the add-on). Cycles: `cycles_bake` at
each `--spp`, then OIDN (RTLightmap, `denoise_lightmap`) per image, as benchmarks/levels.py does.
The error is the relative RMS difference over the texels Cycles bakes (`centre_masks`), all
objects together, against the reference's mean. Left out of it: objects whose reference is under
DARK of the scene's mean (metals: Cycles' diffuse pass has nothing there, the bake lights them as
diffuse) and `--leave-out` (default: the living room's lamp, whose parts sit inside a glass shade
that Cycles lets light through and the bake treats as opaque). Each object's own error is in the JSON.
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

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "sample_scenes" / "downloaded"
DARK = 0.02
LAMP = "base,bulbs,grill,hardware,stainedglass,amberbeads,redgems,steel"


def _blend(scene: str) -> Path:
    path = Path(scene)
    return path if path.suffix == ".blend" else SCENES / f"{scene}.blend"


def _export(bpy, resolution):
    from detp_bake.blender import export_scene
    return export_scene(bpy.context.scene, bpy.context.evaluated_depsgraph_get(), None, None, resolution,
                        log=lambda msg: None)


def worker(args) -> None:
    """A child: the bakes of one checkout (first on sys.path), written to `args.worker` (.npz of
    images, .json of rows)."""
    code = args.code[0]
    sys.path.insert(0, code)
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="detp_race_"))
    import bpy
    from detp_bake.run.bake import BakeSettings, compute
    bpy.ops.wm.open_mainfile(filepath=args.blend)
    compute(_export(bpy, 16), BakeSettings(photons=20_000, seed=3))  # warm-up: kernels and OIDN loaded
    rows, images = [], {}
    for i, photons in enumerate(int(float(p)) for p in args.photons.split(",")):
        t0 = time.perf_counter()
        r = compute(_export(bpy, args.resolution), BakeSettings(photons=photons, seed=1))
        seconds = time.perf_counter() - t0
        rows.append({"photons": int(r.stats.photons), "asked": photons, "seconds": seconds,
                     "phases": {k: round(v, 3) for k, v in r.seconds.items()}})
        for name, img in r.images.items():
            images[f"{i}/{name}"] = img
            images[f"mask/{name}"] = r.centre_masks[name]
            images[f"cover/{name}"] = r.masks[name]
        print(f"  {code}: {r.stats.photons / 1e6:.2f}M photons in {seconds:.1f} s", file=sys.stderr, flush=True)
    np.savez(args.worker + ".npz", **images)
    Path(args.worker + ".json").write_text(json.dumps(rows))


def error(images: dict, ref: dict, masks: dict) -> float:
    d = np.concatenate([(images[n][m] - ref[n][m]).ravel() for n, m in masks.items()])
    b = np.concatenate([ref[n][m].ravel() for n, m in masks.items()])
    return float(np.sqrt(np.mean(d ** 2)) / np.mean(b))


def per_object(images: dict, ref: dict, masks: dict) -> dict:
    return {n: round(error({n: images[n]}, ref, {n: m}), 4) for n, m in masks.items()}


def time_ratio(err: float, seconds: float, cycles: list) -> tuple[float, str]:
    """`seconds` over Cycles + OIDN's at error `err`, read off Cycles' log-log curve; "beyond": past
    its noisiest point (a lower bound), "below": under its least error (an upper bound)."""
    e = np.log([c["error"] for c in cycles])
    t = np.log([c["seconds"] for c in cycles])
    order = np.argsort(e)
    side = "beyond" if err > max(c["error"] for c in cycles) else "below" if err < min(c["error"] for c in cycles) \
        else ""
    return seconds / float(np.exp(np.interp(np.log(err), e[order], t[order]))), side


def _ours(args, code: str, blend: Path, work: Path) -> tuple[list, dict]:
    out = str(work / f"ours{abs(hash(code))}")
    env = dict(os.environ, PYTHONPATH=code)
    subprocess.run([sys.executable, __file__, "--worker", out, "--code", code, "--blend", str(blend),
                    "--resolution", str(args.resolution), "--photons", args.photons], env=env, check=True)
    with np.load(out + ".npz") as z:
        images = {k: z[k] for k in z.files}
    return json.loads(Path(out + ".json").read_text()), images


def _prepare(bpy, args, work: Path) -> tuple[Path, list]:
    """The scene saved with its lightmap UVs (made by this checkout's export), and its objects."""
    bpy.ops.wm.open_mainfile(filepath=str(_blend(args.scene)))
    sc = _export(bpy, args.resolution)
    blend = work / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend), copy=True)
    return blend, [o.name for o in sc.objects]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="living_room")
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--photons", default="0,1e6,2e6,4e6,8e6")
    ap.add_argument("--spp", default="4,8,16,32,64")
    ap.add_argument("--reference-spp", type=int, default=512)
    ap.add_argument("--reference", default="")
    ap.add_argument("--code", action="append", default=[])
    ap.add_argument("--leave-out", default=LAMP, help="objects left out of the error (comma-separated)")
    ap.add_argument("--json", default=str(ROOT / "benchmarks" / "results" / "race.json"))
    ap.add_argument("--record", action="store_true", help="also into benchmarks/measured/race.json (measured.py)")
    ap.add_argument("--worker", default="", help=argparse.SUPPRESS)
    ap.add_argument("--blend", default="", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        return worker(args)
    codes = args.code or [str(ROOT)]
    sys.path.insert(0, str(ROOT))
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="detp_race_"))
    import bpy
    from detp_bake.blender import cycles_bake
    from detp_bake.lightmap import denoise
    work = Path(tempfile.mkdtemp(prefix="detp_race_"))
    blend, _ = _prepare(bpy, args, work)
    ours = {code: _ours(args, code, blend, work) for code in codes}
    first = next(iter(ours.values()))[1]
    names = sorted(k.split("/", 1)[1] for k in first if k.startswith("mask/"))
    covers = {n: first[f"cover/{n}"] for n in names}
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    scene = bpy.context.scene
    ref_path = Path(args.reference) if args.reference else work / "reference.npz"
    if ref_path.is_file():
        with np.load(ref_path) as z:
            ref = {n: z[n] for n in names}
    else:
        t0 = time.perf_counter()
        ref = cycles_bake(scene, names, resolution=args.resolution, samples=args.reference_spp, seed=7)
        print(f"reference: Cycles {args.reference_spp} spp in {time.perf_counter() - t0:.0f} s", flush=True)
        ref_path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(ref_path, **ref)
    all_masks = {n: first[f"mask/{n}"] for n in names}
    level = np.mean(np.concatenate([ref[n][m].ravel() for n, m in all_masks.items()]))
    left_out = set(args.leave_out.split(",")) if args.leave_out else set()
    masks = {n: m for n, m in all_masks.items() if n not in left_out and ref[n][m].mean() > DARK * level}
    print(f"error over {', '.join(masks)}", flush=True)
    cycles = []
    denoise.denoise_lightmap(np.zeros((32, 32, 3), np.float32), np.ones((32, 32), bool))  # OIDN loaded
    for spp in (int(s) for s in args.spp.split(",")):
        t0 = time.perf_counter()
        img = cycles_bake(scene, names, resolution=args.resolution, samples=spp, seed=1)
        img = {n: denoise.denoise_lightmap(img[n], covers[n], filter="RT", margin=0) for n in img}
        cycles.append({"method": f"Cycles {spp} spp + OIDN", "spp": spp, "seconds": time.perf_counter() - t0,
                       "error": error(img, ref, masks), "objects": per_object(img, ref, masks)})
        print(f"{cycles[-1]['method']:34s} {100 * cycles[-1]['error']:6.2f} % {cycles[-1]['seconds']:7.1f} s",
              flush=True)
    rows = list(cycles)
    for code, (runs, images) in ours.items():
        for i, run in enumerate(runs):
            got = {n: images[f"{i}/{n}"] for n in names}
            row = {"method": f"ours {run['photons'] / 1e6:.2f}M photons" + (" (auto)" if run["asked"] == 0 else ""),
                   "code": code, **run, "error": error(got, ref, masks), "objects": per_object(got, ref, masks)}
            row["ratio"], row["side"] = time_ratio(row["error"], row["seconds"], cycles)
            rows.append(row)
            print(f"{row['method']:34s} {100 * row['error']:6.2f} % {row['seconds']:7.1f} s  "
                  f"{ {'beyond': '>', 'below': '<'}.get(row['side'], '')}{row['ratio']:.2f} x Cycles + OIDN  [{code}]",
                  flush=True)
    doc = {"scene": args.scene, "resolution": args.resolution, "reference_spp": args.reference_spp,
           "cores": os.cpu_count(), "blender": ".".join(map(str, bpy.app.version)), "objects": sorted(masks), "left_out": sorted(set(names) - set(masks)),
           "codes": codes, "rows": rows}
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=1))
    print(f"wrote {out}")
    if args.record:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        import measured
        print(f"recorded {measured.record('race', doc)}")
    return doc


if __name__ == "__main__":
    main()
