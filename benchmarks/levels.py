"""A level as users bring them: one big mesh (walls 8 cm thick on a floor, sealed rooms, door gaps,
pillars, bevelled crates) with its lightmap UVs from Smart UV Project, a sun and a sky. It measures
what the default bake costs phase by phase at big lightmap sizes, and how it races Cycles.

    python benchmarks/levels.py [--quick] [--sizes 1024,2048] [--race-size 512] [--spp 8,32,128]
                                [--reference-spp 512] [--out DIR]

Three parts, each a table:
- phases: the default bake (automatic photons, shadow rays, texel histogram, OIDN) at each of
  `--sizes`: seconds per phase, peak memory, and OIDN alone on one image of the same size (the
  bake denoises direct and indirect light apart: two such runs, plus a small one per walled-off
  region);
- fragments: the Smart UV unwrap's charts (count, median width in texels, border share) as the bake
  reports them, and whether it warned;
- race at `--race-size`: relative RMSE against Cycles at `--reference-spp` (the texels Cycles bakes:
  `BakeResult.centre_masks`), ours with the default photons and 4× them, Cycles + OIDN at `--spp`
  samples (denoised by `denoise_lightmap(filter="RT")`, as benchmarks/quality.py does), with
  seconds; the last column is each method's time over Cycles + OIDN's time at about the same error.

Writes OUT/levels.json and OUT/levels.md (default benchmarks/results); with `--record` also
benchmarks/measured/levels.json, from which the docs' figures are rendered (measured.py). About 10 minutes on 2 cores
with the defaults; `--quick` (sizes 64, race at 32) well under one.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import scenes  # noqa: E402  (puts the repository root on sys.path)

import numpy as np  # noqa: E402

sys.path.insert(0, str(scenes.ROOT / "tests"))
from blender_helpers import lambert, sky_world  # noqa: E402  (the test suite's scene-making helpers)

from detp_bake.lightmap import denoise  # noqa: E402
from detp_bake.run.bake import BakeSettings, compute  # noqa: E402

SUN = (math.radians(50.0), 0.0, math.radians(35.0))  # rotation of the sun object
SUN_STRENGTH = 3.0
SKY = (0.35, 0.45, 0.6)
ROOMS = 5  # rooms a side
ROOM = 6.0  # metres a room
WALL = 0.08
HEIGHT = 3.0


def _box(bm, bmesh, lo, hi):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    from mathutils import Matrix
    size, centre = hi - lo, 0.5 * (lo + hi)
    m = Matrix.Translation(centre.tolist()) @ Matrix.Diagonal((*size.tolist(), 1.0))
    return bmesh.ops.create_cube(bm, size=1.0, matrix=m)["verts"]


def _walls(bm, bmesh):
    """A ROOMS × ROOMS grid of rooms, each wall with a door gap except the corner room's, which is
    sealed and roofed (its floor gets no light)."""
    span = ROOMS * ROOM
    o = -span / 2
    for k in range(ROOMS + 1):
        x = o + k * ROOM
        for j in range(ROOMS):
            y0, y1 = o + j * ROOM, o + (j + 1) * ROOM
            sealed = (k <= 1 and j == 0)
            for a, b in ((y0, y1),) if sealed or k in (0, ROOMS) else ((y0, y0 + 2.4), (y0 + 3.6, y1)):
                _box(bm, bmesh, (x - WALL / 2, a, 0.0), (x + WALL / 2, b, HEIGHT))
                _box(bm, bmesh, (a, x - WALL / 2, 0.0), (b, x + WALL / 2, HEIGHT))
    _box(bm, bmesh, (o - WALL, o - WALL, HEIGHT), (o + ROOM + WALL, o + ROOM + WALL, HEIGHT + WALL))


def _props(bm, bmesh, rng):
    from mathutils import Matrix
    span = ROOMS * ROOM
    for i in range(ROOMS):
        for j in range(ROOMS):
            if i == 0 and j == 0:
                continue
            cx, cy = -span / 2 + (i + 0.5) * ROOM, -span / 2 + (j + 0.5) * ROOM
            for _ in range(8):  # bevelled crates
                s = rng.uniform(0.4, 0.9)
                p = np.array([cx, cy]) + rng.uniform(-2.0, 2.0, 2)
                verts = _box(bm, bmesh, (p[0] - s / 2, p[1] - s / 2, 0.0), (p[0] + s / 2, p[1] + s / 2, s))
                edges = list({e for v in verts for e in v.link_edges})
                bmesh.ops.bevel(bm, geom=edges, offset=0.03, segments=4, affect="EDGES")
            for k in range(4):  # a fluted pillar: four drums of 64 sides
                m = Matrix.Translation((cx + 1.2, cy - 1.2, (k + 0.5) * HEIGHT / 4))
                bmesh.ops.create_cone(bm, cap_ends=True, segments=64, radius1=0.22 - 0.01 * k, radius2=0.2 - 0.01 * k,
                                      depth=HEIGHT / 4, matrix=m)


def make_level(bpy, seed: int = 0):
    """The level as one mesh object "Arena" (and its floor inside it), a sun and a sky world; its
    lightmap UV layer "Lightmap" made by Smart UV Project."""
    import bmesh

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    bm = bmesh.new()
    span = ROOMS * ROOM + 8.0
    bmesh.ops.create_grid(bm, x_segments=8, y_segments=8, size=span / 2)
    _walls(bm, bmesh)
    _props(bm, bmesh, np.random.default_rng(seed))
    bmesh.ops.triangulate(bm, faces=bm.faces[:])
    me = bpy.data.meshes.new("Arena")
    bm.to_mesh(me)
    bm.free()
    me.materials.append(lambert(bpy, "Concrete", (0.6, 0.58, 0.55)))
    obj = bpy.data.objects.new("Arena", me)
    scene.collection.objects.link(obj)
    me.uv_layers.new(name="UVMap")
    me.uv_layers.active = me.uv_layers.new(name="Lightmap")
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.uv.smart_project(angle_limit=math.radians(66.0), island_margin=0.001)
    bpy.ops.object.mode_set(mode="OBJECT")
    sun = bpy.data.lights.new("Sun", "SUN")
    sun.energy = SUN_STRENGTH
    sun.angle = math.radians(0.5)
    sun_obj = bpy.data.objects.new("Sun", sun)
    sun_obj.rotation_euler = SUN
    scene.collection.objects.link(sun_obj)
    sky_world(bpy, scene, SKY)
    return scene, len(me.polygons)


def export(bpy, resolution):
    from detp_bake.blender import export_scene
    return export_scene(bpy.context.scene, bpy.context.evaluated_depsgraph_get(), ["Arena"], "Lightmap", resolution,
                        log=lambda msg: None)


def oidn_alone(size: int, tile: int = 0) -> float:
    """Seconds of one denoise (RTLightmap, high) of a size² image, every texel covered: in the
    bake's tiles (denoise.TILE), or with `tile` as the widest image OIDN gets at once (a size or
    more: OIDN's run on the whole image, tiled by OIDN itself within its maxMemoryMB)."""
    rng = np.random.default_rng(0)
    img = (0.5 + 0.1 * rng.standard_normal((size, size, 3))).astype(np.float32)
    mask = np.ones((size, size), bool)
    denoise.denoise_lightmap(img[:64, :64], mask[:64, :64])  # OIDN's device and weights loaded
    bake_tile, denoise.TILE = denoise.TILE, tile or denoise.TILE
    try:
        t0 = time.perf_counter()
        denoise.denoise_lightmap(img, mask, margin=0)
        return time.perf_counter() - t0
    finally:
        denoise.TILE = bake_tile


def phases(bpy, size: int, log) -> dict:
    sc = export(bpy, size)
    t0 = time.perf_counter()
    r = compute(sc, BakeSettings())
    wall = time.perf_counter() - t0
    lm = r.texels.lightmaps[0]
    row = {"size": size, "texels": len(r.texels), "photons": r.stats.photons, "wall": wall,
           "seconds": {k: round(v, 3) for k, v in r.seconds.items()}, "oidn_alone": oidn_alone(size),
           "oidn_whole": oidn_alone(size, tile=size),
           "peak_mb": r.memory["peak_mb"], "estimate_mb": r.memory["estimate_mb"],
           "charts": {"count": lm.charts, "median_width": lm.chart_width, "border": lm.border},
           "warned": any("charts" in w for w in r.warnings), "noise": r.noise}
    log(f"{size}²: {wall:.1f} s, {row['seconds']}, OIDN alone {row['oidn_alone']:.2f} s "
        f"({row['oidn_whole']:.2f} s untiled)")
    return row


def _error(images, ref, masks) -> float:
    d = np.concatenate([(images[n][m] - ref[n][m]).ravel() for n, m in masks.items()])
    b = np.concatenate([ref[n][m].ravel() for n, m in masks.items()])
    return float(np.sqrt(np.mean(d ** 2)) / np.mean(b))


def time_ratio(row, cycles) -> tuple[float, str]:
    """This row's seconds over Cycles + OIDN's at the same error, read off Cycles' (log-log) error
    curve, and where it lies on it: "" within it; "beyond" past its noisiest point (over that
    point's time: a lower bound); "below" under its least error (over the time of Cycles' most
    samples: an upper bound, Cycles would need longer)."""
    e = np.log([c["error"] for c in cycles])
    t = np.log([c["seconds"] for c in cycles])
    order = np.argsort(e)
    side = "beyond" if row["error"] > max(c["error"] for c in cycles) else \
        "below" if row["error"] < min(c["error"] for c in cycles) else ""
    return row["seconds"] / float(np.exp(np.interp(np.log(row["error"]), e[order], t[order]))), side


def race(bpy, size: int, spps, reference_spp: int, log) -> dict:
    from detp_bake.blender import cycles_bake

    sc = export(bpy, size)
    first = compute(sc, BakeSettings())
    masks = first.centre_masks
    t0 = time.perf_counter()
    ref = cycles_bake(bpy.context.scene, ["Arena"], resolution=size, samples=reference_spp, seed=7)
    log(f"reference: Cycles {reference_spp} spp at {size}² in {time.perf_counter() - t0:.0f} s")
    rows = []
    for scale in (1, 4):
        photons = first.settings.photons * scale
        t0 = time.perf_counter()
        r = compute(export(bpy, size), BakeSettings(photons=photons, seed=1))
        seconds = time.perf_counter() - t0
        rows.append({"method": f"ours {photons / 1e6:.3g}M photons", "seconds": seconds,
                     "error": _error(r.images, ref, masks)})
    for spp in spps:
        t0 = time.perf_counter()
        img = cycles_bake(bpy.context.scene, ["Arena"], resolution=size, samples=spp, seed=1)
        img = {n: denoise.denoise_lightmap(img[n], first.masks[n], filter="RT", margin=0) for n in img}
        rows.append({"method": f"Cycles {spp} spp + OIDN", "seconds": time.perf_counter() - t0,
                     "error": _error(img, ref, masks)})
    cycles = [r for r in rows if r["method"].startswith("Cycles")]
    for row in rows:
        row["ratio"], row["side"] = time_ratio(row, cycles)
        log(f"{row['method']}: {100 * row['error']:.2f} % in {row['seconds']:.1f} s "
            f"({ {'beyond': 'over ', 'below': 'under '}.get(row['side'], '')}{row['ratio']:.2f} of Cycles + OIDN's time)")
    return {"size": size, "reference_spp": reference_spp, "rows": rows}


def markdown(data) -> str:
    out = [f"Level: one mesh of {data['faces']:,} faces, Smart UV Project, sun and sky; {data['cores']} cores.\n",
           "| size | texels | photons | rasterise | validity | direct | trace | estimate | denoise | OIDN alone | "
           "OIDN alone, whole image | total | peak MB |", "|" + "---|" * 13]
    for r in data["phases"]:
        s = r["seconds"]
        out.append(f"| {r['size']}² | {r['texels']:,} | {r['photons'] / 1e6:.3g}M | {s.get('rasterise', 0):.1f} | "
                   f"{s.get('validity', 0):.1f} | "
                   f"{s.get('direct', 0):.1f} | {s.get('trace', 0):.1f} | {s.get('estimate', 0):.1f} | "
                   f"{s.get('denoise', 0):.1f} | {r['oidn_alone']:.1f} | {r.get('oidn_whole', 0):.1f} | "
                   f"{r['wall']:.1f} | {r['peak_mb']:,.0f} |")
    out.append("\n| size | charts | median width (texels) | border texels | warned |\n|---|---|---|---|---|")
    for r in data["phases"]:
        c = r["charts"]
        out.append(f"| {r['size']}² | {c['count']:,} | {c['median_width']:.1f} | {100 * c['border']:.0f} % | "
                   f"{'yes' if r['warned'] else 'no'} |")
    rc = data.get("race")
    if rc:
        out.append(f"\nRace at {rc['size']}² against Cycles at {rc['reference_spp']} spp:\n")
        out.append("| method | error | seconds | time / Cycles + OIDN's at that error |\n|---|---|---|---|")
        for r in rc["rows"]:
            ratio = {"beyond": f"more than {r['ratio']:.2f} (noisier than Cycles' fewest samples)",
                     "below": f"less than {r['ratio']:.2f} (less error than Cycles' most samples)"}.get(
                r.get("side"), f"{r['ratio']:.2f}")
            out.append(f"| {r['method']} | {100 * r['error']:.2f} % | {r['seconds']:.1f} | {ratio} |")
    return "\n".join(out) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="sizes 64, race at 32 (a smoke run)")
    ap.add_argument("--sizes", default="1024,2048")
    ap.add_argument("--race-size", type=int, default=512, help="0: no race against Cycles")
    ap.add_argument("--spp", default="8,32,128")
    ap.add_argument("--reference-spp", type=int, default=512)
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    ap.add_argument("--record", action="store_true",
                    help="also write benchmarks/measured/levels.json, which the docs' figures are rendered from")
    args = ap.parse_args(argv)
    if args.quick:
        args.sizes, args.race_size, args.spp, args.reference_spp = "64", 32, "2,8", 16
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="detp_bench_blender_"))
    import bpy

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    def log(msg):
        print(msg, flush=True)

    _, faces = make_level(bpy)
    data = {"faces": faces, "cores": os.cpu_count(), "phases": []}
    for size in (int(s) for s in args.sizes.split(",")):
        data["phases"].append(phases(bpy, size, log))
    if args.race_size:
        data["race"] = race(bpy, args.race_size, [int(s) for s in args.spp.split(",")], args.reference_spp, log)
    (out / "levels.json").write_text(json.dumps(data, indent=2, allow_nan=False))
    if args.record:
        import measured
        print(f"recorded {measured.record('levels', data)}")
    text = markdown(data)
    (out / "levels.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
