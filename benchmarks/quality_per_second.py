"""Issue 33's two real levels, baked through the command line with default settings: a room lit by
many small point lights against the same room with one of them, and a level of many crates on a
ground under a sun. Wall seconds and report.json's phases per bake; for the room, the error of
its lightmaps against a reference bake.

    python benchmarks/quality_per_second.py [--lights 800] [--room-resolution 256]
        [--objects 1500] [--crate-resolution 32] [--code DIR] [--before DIR] [--reference DIR]
        [--json OUT]

The scenes come from benchmarks/big_scenes.py (numpy and foreach_set); the crates lose their
Lightmap UV layers (unless `--level-uvs`), so the exporter makes them. `--code` bakes with another
checkout of the project; `--before DIR` bakes each case with DIR's checkout too, beside it (the
state before a change: a before/after table from one run). `--reference DIR` reuses (or writes,
when missing) the reference room bake: the same room baked by `--reference-code` (else the first
checkout) with `--reference-photons` photons and `--direct-samples` `--reference-samples`. The
error is the relative RMS difference of the lightmaps' pixels (their mean over RGB) against the
reference, over all six surfaces' images. Prints a table, writes JSON (default
benchmarks/results/quality_per_second.json).
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

sys.path.insert(0, str(Path(__file__).resolve().parent))
import big_scenes  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def bake(code, blend, out, extra):
    """One CLI bake with the project at `code`: (report, wall seconds)."""
    env = dict(os.environ, PYTHONPATH=str(code))
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "detp_bake", "bake", str(blend), "--out", str(out), "--force",
                           *extra], env=env, cwd=str(code), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                          text=True)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"bake of {blend} failed ({done.returncode}):\n{done.stderr[-3000:]}")
    return json.loads((Path(out) / "report.json").read_text()), wall


def lightmaps(out) -> dict:
    """{file name: texels (H, W) mean over RGB} of a bake's lightmap files."""
    import OpenImageIO as oiio
    images = {}
    for path in sorted(Path(out).iterdir()):
        if path.suffix.lower() in (".exr", ".hdr") and not path.name.startswith("."):
            buf = oiio.ImageBuf(str(path))
            images[path.name] = np.asarray(buf.get_pixels(oiio.FLOAT))[..., :3].mean(axis=-1)
    return images


def error(out, ref) -> float:
    """Relative RMS difference of the lightmaps in `out` against those in `ref`."""
    a, b = lightmaps(out), lightmaps(ref)
    if sorted(a) != sorted(b) or not a:
        raise SystemExit(f"{out} and {ref} hold different lightmaps: {sorted(a)} / {sorted(b)}")
    diff = np.concatenate([(a[k] - b[k]).ravel() for k in a])
    base = np.concatenate([b[k].ravel() for k in b])
    return float(np.sqrt(np.mean(diff ** 2)) / np.sqrt(np.mean(base ** 2)))


def row(case, report, wall, err=None):
    seconds = {k: round(v, 2) for k, v in report["seconds"].items()}
    r = {"case": case, "wall_s": round(wall, 2), "seconds": seconds}
    if err is not None:
        r["error"] = round(err, 5)
    print(f"{case:28s} {wall:8.1f} s  " + (f"error {100 * err:6.2f} %  " if err is not None else " " * 17) +
          " ".join(f"{k} {v:.1f}" for k, v in seconds.items() if v >= 0.05), flush=True)
    return r


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lights", type=int, default=800)
    ap.add_argument("--room-resolution", type=int, default=256)
    ap.add_argument("--objects", type=int, default=1500)
    ap.add_argument("--crate-resolution", type=int, default=32)
    ap.add_argument("--level-uvs", action="store_true", help="the crates keep their Lightmap UV layers")
    ap.add_argument("--code", default=str(ROOT))
    ap.add_argument("--before", default="", help="another checkout baked beside --code, case by case")
    ap.add_argument("--reference", default="")
    ap.add_argument("--reference-code", default="", help="the checkout that bakes the reference (--code)")
    ap.add_argument("--reference-photons", type=int, default=25_000_000)
    ap.add_argument("--reference-samples", type=int, default=64)
    ap.add_argument("--skip", default="", help="cases to leave out: room,level")
    ap.add_argument("--json", default=str(ROOT / "benchmarks" / "results" / "quality_per_second.json"))
    args = ap.parse_args(argv)
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="detp_bench_blender_"))
    import bpy
    work = Path(tempfile.mkdtemp(prefix="detp_qps_"))
    codes = [("before", args.before), ("after", args.code)] if args.before else [("", args.code)]
    rows = []
    if "room" not in args.skip:
        many = big_scenes.lit_room(bpy, work / "room_many.blend", args.lights)
        one = big_scenes.lit_room(bpy, work / "room_one.blend", 1)
        res = ["--resolution", str(args.room_resolution)]
        ref = Path(args.reference) if args.reference else work / "reference"
        if not (ref / "report.json").is_file():
            report, wall = bake(args.reference_code or codes[0][1], many, ref,
                                res + ["--photons", str(args.reference_photons),
                                       "--direct-samples", str(args.reference_samples)])
            rows.append(row(f"room, {args.lights} lights, reference", report, wall))
        for label, code in codes:
            report, wall = bake(code, one, work / f"one{label}", res)
            rows.append(row(f"{label} room, 1 light".strip(), report, wall))
            report, wall = bake(code, many, work / f"many{label}", res)
            rows.append(row(f"{label} room, {args.lights} lights".strip(), report, wall,
                            error(work / f"many{label}", ref)))
    if "level" not in args.skip:
        level = _level(bpy, work, args.objects, args.level_uvs)
        for label, code in codes:
            report, wall = bake(code, level, work / f"level{label}", ["--resolution", str(args.crate_resolution)])
            rows.append(row(f"{label} level, {args.objects} crates".strip(), report, wall))
    doc = {"cores": os.cpu_count(), "code": str(args.code), "before": args.before, "lights": args.lights,
           "room_resolution": args.room_resolution, "objects": args.objects,
           "crate_resolution": args.crate_resolution, "level_uvs": args.level_uvs,
           "blender": ".".join(map(str, bpy.app.version)), "rows": rows}
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=1))
    print(f"wrote {out}")
    return doc


def _level(bpy, work, objects, uvs) -> Path:
    """The crates' level; without their Lightmap UV layers unless `uvs` (the exporter makes them,
    as for a level fresh from an editor)."""
    level = big_scenes.level(bpy, work / "level.blend", objects)
    if uvs:
        return level
    bpy.ops.wm.open_mainfile(filepath=str(level))
    for mesh in bpy.data.meshes:
        mesh.uv_layers.remove(mesh.uv_layers["Lightmap"])
    bpy.ops.wm.save_as_mainfile(filepath=str(work / "level_no_uvs.blend"))
    return work / "level_no_uvs.blend"

if __name__ == "__main__":
    main()
