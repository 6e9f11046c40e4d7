"""Big scenes do not fall over: a level of many objects (one lightmap each, and in atlases) and a
room with many point lights, each baked through the command line, every file checked, and what
each costs written down.

    python benchmarks/big_scenes.py [--objects 1500] [--lights 800] [--resolution 16]
                                    [--photons 200000] [--texel-density 8] [--atlas-size 1024]
                                    [--json OUT]

The level: `--objects` boxes (12 triangles, their own mesh and Lightmap UVs each: six tiles) on a
ground plane under a sun. The room: a floor, a ceiling and four walls under a grid of `--lights`
point lights. Each bake runs in its own process (`python -m detp_bake bake`, its peak resident
memory read from wait4); report.json gives the seconds per phase and the bake's own memory
estimate. Checked: exit code 0, one lightmap file per baked object (per atlas in atlas mode), each
on disk and non-empty. Prints a table, writes JSON (default benchmarks/results/big_scenes.json).
The scenes are built with numpy and foreach_set (no loop per face).
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
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

# A unit box's six faces as quads of its eight corners, and each face's tile in a 3 × 2 UV grid
# (a 10 % margin around each tile).
_CORNERS = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], float) - [0.5, 0.5, 0.0]
_FACES = np.array([[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]])
_TILE = np.array([[0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.1, 0.9]])


def _mesh(bpy, name, co, quads, uv):
    """A mesh object of quads; `uv`: one row per corner of every quad."""
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(co))
    mesh.vertices.foreach_set("co", np.asarray(co, np.float32).ravel())
    mesh.loops.add(quads.size)
    mesh.loops.foreach_set("vertex_index", quads.astype(np.int32).ravel())
    mesh.polygons.add(len(quads))
    mesh.polygons.foreach_set("loop_start", np.arange(0, quads.size, 4, dtype=np.int32))
    mesh.polygons.foreach_set("loop_total", np.full(len(quads), 4, np.int32))
    mesh.uv_layers.new(name="Lightmap").data.foreach_set("uv", np.asarray(uv, np.float32).ravel())
    mesh.update(calc_edges=True)
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _quad(bpy, name, corners):
    return _mesh(bpy, name, corners, np.array([[0, 1, 2, 3]]), [[0, 0], [1, 0], [1, 1], [0, 1]])


def level(bpy, path, objects):
    """`objects` boxes of different sizes on a square ground, under a sun; saved as `path`."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    side = int(np.ceil(np.sqrt(objects)))
    half = 1.5 * side / 2
    _quad(bpy, "Ground", [[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]])
    rng = np.random.default_rng(1)
    tiles = np.concatenate([(_TILE + [i % 3, i // 3]) / [3, 2] for i in range(6)])
    for i in range(objects):
        size = rng.uniform(0.3, 1.0, 3)
        at = np.array([1.5 * (i % side) - half + 0.75, 1.5 * (i // side) - half + 0.75, 0.0])
        _mesh(bpy, f"Box{i:04d}", _CORNERS * size + at, _FACES, tiles)
    sun = bpy.data.lights.new("Sun", "SUN")
    sun.energy = 3.0
    obj = bpy.data.objects.new("Sun", sun)
    obj.rotation_euler = (0.6, 0.2, 0.3)
    bpy.context.scene.collection.objects.link(obj)
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


def lit_room(bpy, path, lights):
    """A 20 × 10 × 3 m room (six quads, their own objects) under a grid of `lights` point lights."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    w, d, h = 10.0, 5.0, 3.0
    c = {k: np.array(v, float) for k, v in dict(a=[-w, -d, 0], b=[w, -d, 0], e=[w, d, 0], f=[-w, d, 0]).items()}
    up = np.array([0, 0, h])
    for name, quad in {"Floor": [c["a"], c["b"], c["e"], c["f"]],
                       "Ceiling": [c["a"] + up, c["f"] + up, c["e"] + up, c["b"] + up],
                       "South": [c["a"], c["a"] + up, c["b"] + up, c["b"]],
                       "North": [c["f"], c["e"], c["e"] + up, c["f"] + up],
                       "West": [c["a"], c["f"], c["f"] + up, c["a"] + up],
                       "East": [c["b"], c["b"] + up, c["e"] + up, c["e"]]}.items():
        _quad(bpy, name, quad)
    nx = int(np.ceil(np.sqrt(2 * lights)))
    for i in range(lights):
        light = bpy.data.lights.new(f"Lamp{i:03d}", "POINT")
        light.energy = 5.0
        obj = bpy.data.objects.new(f"Lamp{i:03d}", light)
        obj.location = (-w + (i % nx + 0.5) * 2 * w / nx, -d + (i // nx + 0.5) * 2 * d / int(np.ceil(lights / nx)),
                        h - 0.3)
        bpy.context.scene.collection.objects.link(obj)
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


def bake(blend, out, extra, timeout=3600):
    """One bake through the command line in its own process: its report, peak and wall time."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    t0 = time.perf_counter()
    with tempfile.TemporaryFile("w+") as err:
        proc = subprocess.Popen([sys.executable, "-m", "detp_bake", "bake", str(blend), "--out", str(out), "--force",
                                 *extra], env=env, stdout=subprocess.DEVNULL, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
        err.seek(0)
        text = err.read()
    code = os.waitstatus_to_exitcode(status)
    if code != 0:
        raise SystemExit(f"bake of {blend} failed ({code}):\n{text[-3000:]}")
    report = json.loads((Path(out) / "report.json").read_text())
    return report, usage.ru_maxrss * 1024, time.perf_counter() - t0


def checked(report, out, expect):
    """Every baked object's (or atlas') lightmap on disk and non-empty; how many."""
    files = [Path(f) for o in report["objects"] for f in o.get("files", [])]
    files += [Path(f) for a in report.get("atlases", []) for f in a.get("files", [])]
    files = sorted(set(files))
    missing = [str(f) for f in files if not f.is_file() or f.stat().st_size == 0]
    if missing or len(files) < expect:
        raise SystemExit(f"{out}: {len(files)} lightmap files, {expect} expected; missing {missing[:5]}")
    return len(files)


def row(name, report, peak, wall, files):
    return {"case": name, "files": files, "wall_s": round(wall, 2),
            "seconds": {k: round(v, 2) for k, v in report["seconds"].items()},
            "triangles": report.get("export", {}).get("triangles"),
            "estimate_mb": report["memory"]["estimate_mb"], "bake_peak_mb": report["memory"]["peak_mb"],
            "process_peak_mb": round(peak / 1e6, 1)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", type=int, default=1500)
    ap.add_argument("--lights", type=int, default=800)
    ap.add_argument("--resolution", type=int, default=16)
    ap.add_argument("--photons", type=int, default=200_000)
    ap.add_argument("--texel-density", type=float, default=8.0)
    ap.add_argument("--atlas-size", type=int, default=1024)
    ap.add_argument("--json", default=str(ROOT / "benchmarks" / "results" / "big_scenes.json"))
    args = ap.parse_args(argv)
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="detp_bench_blender_"))
    import bpy
    work = Path(tempfile.mkdtemp(prefix="detp_big_scenes_"))
    common = ["--photons", str(args.photons)]
    rows = []
    t0 = time.perf_counter()
    blend = level(bpy, work / "level.blend", args.objects)
    built = time.perf_counter() - t0
    cases = [("level, one lightmap each", blend, ["--resolution", str(args.resolution)], args.objects + 1),
             ("level, atlases", blend, ["--lightmaps", "atlas", "--texel-density", str(args.texel_density),
                                         "--atlas-size", str(args.atlas_size)], 1),
             ("room, point lights", lit_room(bpy, work / "room.blend", args.lights),
              ["--resolution", str(args.resolution)], 6)]
    for i, (name, scene, extra, expect) in enumerate(cases):
        out = work / f"out{i}"
        report, peak, wall = bake(scene, out, common + extra)
        rows.append(row(name, report, peak, wall, checked(report, out, expect)))
        r = rows[-1]
        print(f"{name:26s} {r['files']:5d} files  {r['wall_s']:7.1f} s  process peak {r['process_peak_mb']:7.0f} MB"
              f"  estimate {r['estimate_mb']:6.0f} MB  " +
              " ".join(f"{k} {v:.1f}" for k, v in r["seconds"].items() if v >= 0.05), flush=True)
    doc = {"cores": os.cpu_count(), "objects": args.objects, "lights": args.lights, "resolution": args.resolution,
           "photons": args.photons, "texel_density": args.texel_density, "build_level_s": round(built, 2),
           "blender": ".".join(map(str, bpy.app.version)), "rows": rows}
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=1))
    print(f"wrote {out}")
    return doc


if __name__ == "__main__":
    main()
