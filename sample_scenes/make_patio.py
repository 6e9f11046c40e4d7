"""Build the detp_bake sample scene "patio": an arcaded courtyard under sun and sky.

The paper this project implements (García et al., CEIG 2005) times its estimators on a tree
and a patio ("Patio", 122,318 triangles); this scene stands in for the patio, with exactly
TRIANGLES = 122,318 triangles.  Z up, metres, the courtyard centred on the origin:

- a 16 x 16 m tiled floor and four 7 m high walls around it (inner faces only);
- a gallery on all four sides: sixteen turned stone columns (lathed base, shaft with entasis,
  astragal and capital, square plinth and abacus) 2.75 m apart carry a band 0.5 m thick pierced by
  semicircular arches, under a flat roof 2.75 m deep that meets the walls at 5 m;
- in the open court: a two-basin fountain with its water surfaces, four benches facing it and four
  planters with small orange trees (a trunk and a round crown of flat leaves).

The crowns' leaves take what is left of the triangle budget once everything else is built, so the
total is exact.  Light: a sun of strength 3 at 50 degrees elevation and a constant sky-blue world
(0.35, 0.45, 0.6), strength 1; the gallery is lit mostly by light bounced off the court.

Objects (20): Floor, Walls, Roof, Arcade{South,East,North,West} and Columns{...} (one of each per
gallery side), Fountain, Water, Benches, Planters, Trunks and Crown1..Crown4.  Every mesh has a
texture UV layer "UVMap" (first, active) and a "Lightmap" layer of unrolled and projected charts,
packed by the helpers of make_tree.py (see there why not Lightmap Pack).  Deterministic.

Usage (with the bpy module, Blender 4.5 or 5.x):
    python sample_scenes/make_patio.py [OUTPUT.blend]
"""

import math
import os
import random
import sys

import bpy
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from make_tree import (MeshBuilder, generate, add_camera, add_leaves, add_object, add_sun,  # noqa: E402
                       make_material, normalised, set_render, set_world, tube)

TRIANGLES = 122_318
SEED = 2005
HALF = 8.0  # the walls stand at |x| = HALF and |y| = HALF
WALL_HEIGHT = 7.0
ARCADE = 5.5  # column axes at |x| or |y| = ARCADE
BAND = 0.25  # half the thickness of the arcade band
BAY = 2.75  # column spacing
ARCH_RADIUS = 1.0
SPRING = 3.0  # the arches spring from the abaci at this height
ROOF_UNDER, ROOF_TOP = 4.8, 5.0
ARCH_SEGMENTS = 48
COLUMN_SIDES = 32
FOUNTAIN_SIDES = 96
LATHE_CHART_ARC = 2.0  # metres around a lathed surface per lightmap chart, at most
FLOOR_GRID = 64  # 0.25 m tiles
SIDES = ("South", "East", "North", "West")  # local frame: the south gallery, court towards +Y
STUCCO = (0.75, 0.70, 0.62)
STONE = (0.68, 0.64, 0.56)
TILES = (0.55, 0.42, 0.34)
ROOF = (0.60, 0.36, 0.26)
WATER = (0.20, 0.30, 0.34)
WOOD = (0.45, 0.32, 0.22)
TERRACOTTA = (0.62, 0.36, 0.24)
BARK = (0.30, 0.23, 0.20)
FOLIAGE = (0.22, 0.42, 0.20)
SKY = (0.35, 0.45, 0.6)
SUN_STRENGTH = 3.0
SUN_ELEVATION_DEG = 50.0
SUN_AZIMUTH_DEG = 120.0
DEFAULT_OUTPUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "patio.blend")


# --------------------------------------------------------------------------- geometry

def turn(points, side):
    """Points of the local (south) frame turned to gallery `side` (0..3, a quarter turn each)."""
    c, s = [(1, 0), (0, 1), (-1, 0), (0, -1)][side]
    p = np.asarray(points, np.float64).reshape(-1, 3)
    return np.stack([c * p[:, 0] - s * p[:, 1], s * p[:, 0] + c * p[:, 1], p[:, 2]], axis=1)


def quad_grid(builder, corner, u_edge, v_edge, nu, nv, side=0):
    """nu x nv quads over corner + s*u_edge + t*v_edge, facing u x v: one chart."""
    corner, u_edge, v_edge = (np.asarray(x, np.float64) for x in (corner, u_edge, v_edge))
    s, t = np.meshgrid(np.linspace(0, 1, nu + 1), np.linspace(0, 1, nv + 1))  # row j: t[j]
    verts = corner + s.ravel()[:, None] * u_edge + t.ravel()[:, None] * v_edge
    lu, lv = np.linalg.norm(u_edge), np.linalg.norm(v_edge)
    chart = np.stack([s.ravel() * lu, t.ravel() * lv], axis=1)
    faces = [(j * (nu + 1) + i, j * (nu + 1) + i + 1, (j + 1) * (nu + 1) + i + 1, (j + 1) * (nu + 1) + i)
             for j in range(nv) for i in range(nu)]
    return builder.add(turn(verts, side), faces, [[chart[v] for v in f] for f in faces], smooth=False)


def box(builder, centre, size, side=0, bottom=True):
    """Axis-aligned box (in the local frame) with outward faces, one chart per face."""
    c, h = np.asarray(centre, np.float64), 0.5 * np.asarray(size, np.float64)
    x, y, z = np.eye(3)
    # (corner, u edge, v edge) with u x v pointing out of the box.
    faces = [(c + [-h[0], -h[1], h[2]], 2 * h[0] * x, 2 * h[1] * y),    # top
             (c + [-h[0], -h[1], -h[2]], 2 * h[0] * x, 2 * h[2] * z),   # -Y
             (c + [h[0], h[1], -h[2]], -2 * h[0] * x, 2 * h[2] * z),    # +Y
             (c + [-h[0], h[1], -h[2]], -2 * h[1] * y, 2 * h[2] * z),   # -X
             (c + [h[0], -h[1], -h[2]], 2 * h[1] * y, 2 * h[2] * z)]    # +X
    if bottom:
        faces.append((c + [-h[0], h[1], -h[2]], 2 * h[0] * x, -2 * h[1] * y))
    return sum(quad_grid(builder, corner, u, v, 1, 1, side) for corner, u, v in faces)


def lathe(builder, segments, sides, centre=(0.0, 0.0, 0.0)):
    """Surfaces of revolution about the vertical axis through `centre`.  Each segment, a list of
    (r, z) profile points, is smooth; segments meet at hard edges.  A segment is unrolled into
    charts (sectors of at most LATHE_CHART_ARC metres around, so that a wide basin does not set
    the scale of a whole lightmap), or projected from above when it is flat and reaches near the
    axis.  The faces look towards (dz, -dr) of the profile's direction: go up the outside, inwards
    across a top.  A point with r = 0 closes the segment with a fan.  Triangles per segment:
    2*sides per step, sides per step next to the axis."""
    centre = np.asarray(centre, np.float64)
    angles = 2.0 * np.pi * np.arange(sides) / sides
    ring_dir = np.stack([np.cos(angles), np.sin(angles), np.zeros(sides)], axis=1)
    chord = 2.0 * np.sin(np.pi / sides)
    total = 0
    for profile in segments:
        profile = np.asarray(profile, np.float64)
        r, z = profile[:, 0], profile[:, 1]
        flat = np.ptp(z) < 1e-9 and r.min() < 0.5 * r.max()
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(profile, axis=0), axis=1))])
        first = np.concatenate([[0], np.cumsum([1 if ri == 0.0 else sides for ri in r])])
        verts = np.concatenate([centre + ri * ring_dir[:1 if ri == 0.0 else sides] + [0.0, 0.0, zi]
                                for ri, zi in zip(r, z)])
        n_sectors = 1 if flat else max(1, math.ceil(chord * sides * r.max() / LATHE_CHART_ARC))
        bounds = [round(sides * k / n_sectors) for k in range(n_sectors + 1)]

        def vid(i, j):
            return first[i] if r[i] == 0.0 else first[i] + j % sides

        faces, uvs, chart_faces = [], [], []
        for j0, j1 in zip(bounds[:-1], bounds[1:]):
            middle = 0.5 * (j0 + j1)
            for i in range(len(profile) - 1):
                for j in range(j0, j1):
                    quad = [(i, j), (i, j + 1), (i + 1, j + 1), (i + 1, j)]
                    keep = [c for k, c in enumerate(quad) if vid(*c) not in [vid(*q) for q in quad[:k]]]
                    faces.append(tuple(vid(*c) for c in keep))
                    if flat:
                        uvs.append([verts[vid(*c)][:2] - centre[:2] for c in keep])
                    else:
                        uvs.append([((jj - middle) * chord * r[ii], arc[ii]) for ii, jj in keep])
            chart_faces.append((j1 - j0) * (len(profile) - 1))
        total += builder.add(verts, faces, uvs, smooth=True, chart_faces=chart_faces)
    return total


def curve(f, t0, t1, n):
    """n + 1 profile points (r, z) = f(t) for t from t0 to t1."""
    return [f(t) for t in np.linspace(t0, t1, n + 1)]


def column(builder, x, y):
    """A turned column standing on the floor at (x, y), its abacus topping out at SPRING."""
    total = box(builder, (x, y, 0.1), (0.5, 0.5, 0.2), bottom=False)  # plinth
    total += box(builder, (x, y, SPRING - 0.06), (0.6, 0.6, 0.12))  # abacus
    base = curve(lambda t: (0.17 + 0.05 * math.sin(t), 0.2 + 0.05 * (1 - math.cos(t))), 0.0, math.pi, 12)
    shaft = curve(lambda t: (0.17 - 0.03 * t + 0.012 * math.sin(math.pi * t), 0.3 + 2.3 * t), 0.0, 1.0, 24)
    astragal = curve(lambda t: (0.14 + 0.025 * math.sin(t), 2.6 + 0.03 * (1 - math.cos(t))), 0.0, math.pi, 8)
    bell = curve(lambda t: (0.14 + 0.14 * t ** 2, 2.66 + 0.22 * t), 0.0, 1.0, 10)
    return total + lathe(builder, [base, shaft, astragal, bell], COLUMN_SIDES, (x, y, 0.0))


def arch_face(builder, x0, x1, xc, y, z_bottom, z_top, facing, side):
    """The face at y of one bay of the arcade band: rectangle [x0, x1] x [z_bottom, z_top] less the
    half disc of ARCH_RADIUS on (xc, z_bottom); looking towards +Y when facing > 0.  A strip of
    ARCH_SEGMENTS quads between the arch and the rectangle's edge (its corners on strip lines)."""
    n, rad = ARCH_SEGMENTS, ARCH_RADIUS
    phi = np.pi * np.arange(n + 1) / n
    inner = np.stack([xc - rad * np.cos(phi), z_bottom + rad * np.sin(phi)], axis=1)
    # Outer edge: up the left side, across the top, down the right side; the two top corners sit
    # on the strip lines nearest to their angle as seen from the arch's centre.
    k_left = int(round(n * math.atan2(z_top - z_bottom, xc - x0) / math.pi))
    k_right = n - int(round(n * math.atan2(z_top - z_bottom, x1 - xc) / math.pi))
    outer = []
    for k in range(n + 1):
        if k <= k_left:
            outer.append((x0, z_bottom + (z_top - z_bottom) * k / k_left))
        elif k <= k_right:
            outer.append((x0 + (x1 - x0) * (k - k_left) / (k_right - k_left), z_top))
        else:
            outer.append((x1, z_top - (z_top - z_bottom) * (k - k_right) / (n - k_right)))
    pts = np.concatenate([inner, np.array(outer)])
    verts = np.stack([pts[:, 0], np.full(len(pts), y), pts[:, 1]], axis=1)
    faces = []
    for k in range(n):
        quad = (k, n + 1 + k, n + 2 + k, k + 1)  # arch, edge, edge, arch: looks towards +Y
        faces.append(quad if facing > 0 else quad[::-1])
    return builder.add(turn(verts, side), faces, [[pts[v] for v in f] for f in faces], smooth=False)


def intrados(builder, xc, y_front, y_back, side):
    """The underside of one arch, from the band's front face to its back face (faces down/in)."""
    n, rad = ARCH_SEGMENTS, ARCH_RADIUS
    phi = np.pi * np.arange(n + 1) / n
    x, z = xc - rad * np.cos(phi), SPRING + rad * np.sin(phi)
    verts = np.concatenate([np.stack([x, np.full(n + 1, y_front), z], axis=1),
                            np.stack([x, np.full(n + 1, y_back), z], axis=1)])
    arc = rad * phi
    depth = y_front - y_back
    faces = [(k, k + 1, n + 2 + k, n + 1 + k) for k in range(n)]
    chart = [(a, 0.0) for a in arc] + [(a, depth) for a in arc]
    return builder.add(turn(verts, side), faces, [[chart[v] for v in f] for f in faces], smooth=True)


def arcade(builder, side):
    """The arcade band of one gallery side.  Pinwheel: each side's band runs from its outer corner
    (x = -ARCADE - BAND) to the next side's band (x = ARCADE - BAND), so the four never overlap."""
    y_front, y_back = -ARCADE + BAND, -ARCADE - BAND
    x_start, x_end = -ARCADE - BAND, ARCADE - BAND
    total = 0
    for b in range(4):
        left, right = -ARCADE + b * BAY, -ARCADE + (b + 1) * BAY
        xc = 0.5 * (left + right)
        front = (max(left, -ARCADE + BAND), min(right, x_end))
        back = (x_start if b == 0 else left, min(right, x_end))
        total += arch_face(builder, *front, xc, y_front, SPRING, ROOF_TOP, +1, side)
        total += arch_face(builder, *back, xc, y_back, SPRING, ROOF_UNDER, -1, side)
        total += intrados(builder, xc, y_front, y_back, side)
        # The bottom of the pier left of this arch, on the abacus.
        pier = (x_start if b == 0 else xc - BAY + ARCH_RADIUS, xc - ARCH_RADIUS)
        total += quad_grid(builder, (pier[0], y_back, SPRING), (0.0, y_front - y_back, 0.0),
                           (pier[1] - pier[0], 0.0, 0.0), 1, 1, side)
    # The pier bottom right of the last arch up to the next band, and the band's outer end.
    last = -ARCADE + 3.5 * BAY + ARCH_RADIUS
    total += quad_grid(builder, (last, y_back, SPRING), (0.0, y_front - y_back, 0.0),
                       (x_end - last, 0.0, 0.0), 1, 1, side)
    total += quad_grid(builder, (x_start, y_front, SPRING), (0.0, y_back - y_front, 0.0),
                       (0.0, 0.0, ROOF_UNDER - SPRING), 1, 1, side)
    return total


def roof(builder, side):
    """The gallery roof of one side (pinwheel like the band): top and underside."""
    inner_top, inner_under = ARCADE - BAND, ARCADE + BAND
    total = quad_grid(builder, (-HALF, -HALF, ROOF_TOP), (inner_top + HALF, 0.0, 0.0),
                      (0.0, HALF - inner_top, 0.0), 8, 2, side)
    total += quad_grid(builder, (-HALF, -inner_under, ROOF_UNDER), (inner_under + HALF, 0.0, 0.0),
                       (0.0, inner_under - HALF, 0.0), 8, 2, side)
    return total


def fountain(stone, water):
    """A round basin with a pedestal and an upper bowl, and the two water surfaces."""
    basin_out = curve(lambda t: (1.55 + 0.08 * t + 0.03 * math.sin(2 * math.pi * t), 0.45 * t), 0.0, 1.0, 12)
    rim = curve(lambda t: (1.63 + 0.04 * math.sin(t), 0.45 + 0.05 * (1 - math.cos(t))), 0.0, math.pi, 10)
    rim_top = [(1.63, 0.55), (1.45, 0.55)]
    basin_in = [(1.45, 0.55), (1.45, 0.35)]
    pedestal = curve(lambda t: (0.22 - 0.06 * t + 0.05 * math.sin(3 * math.pi * t) ** 2, 0.35 + 0.85 * t),
                     0.0, 1.0, 30)
    bowl_under = curve(lambda t: (0.16 + 0.6 * t, 1.2 + 0.25 * t ** 2), 0.0, 1.0, 16)
    bowl_rim = curve(lambda t: (0.76 + 0.03 * math.sin(t), 1.45 + 0.04 * (1 - math.cos(t))), 0.0, math.pi, 8)
    bowl_in = curve(lambda t: (0.76 - 0.1 * t, 1.53 - 0.1 * t ** 2), 0.0, 1.0, 6)
    finial = curve(lambda t: (0.08 * math.sin(math.pi * (1 - t)) + 0.04 * (1 - t), 1.43 + 0.45 * t),
                   0.0, 1.0, 16)
    triangles = lathe(stone, [basin_out, rim, rim_top, basin_in, pedestal, bowl_under, bowl_rim,
                              bowl_in, finial], FOUNTAIN_SIDES)
    triangles += lathe(water, [[(1.45, 0.35), (0.9, 0.35), (0.2, 0.35)]], FOUNTAIN_SIDES)
    triangles += lathe(water, [[(0.66, 1.43), (0.3, 1.43), (0.04, 1.43)]], FOUNTAIN_SIDES)
    return triangles


def bench(builder, side):
    """A stone-footed wooden bench 3.2 m from the fountain, facing it."""
    y = -3.2
    total = box(builder, (0.0, y, 0.455), (1.6, 0.42, 0.07), side)
    for x in (-0.65, 0.65):
        total += box(builder, (x, y, 0.21), (0.1, 0.38, 0.42), side, bottom=False)
    return total


def planter(builder, centre):
    """A terracotta pot with soil at z = 0.62 (the soil is one flat chart)."""
    wall = curve(lambda t: (0.42 + 0.16 * t + 0.02 * math.sin(math.pi * t), 0.7 * t), 0.0, 1.0, 8)
    lip = curve(lambda t: (0.6 + 0.03 * math.sin(t), 0.7 + 0.03 * (1 - math.cos(t))), 0.0, math.pi, 6)
    inside = [(0.6, 0.76), (0.54, 0.76), (0.53, 0.62)]
    soil = [(0.53, 0.62), (0.0, 0.62)]
    return lathe(builder, [wall, lip, inside, soil], 32, centre)


def crown(builder, rng, centre, radius, count):
    """`count` leaves in a round crown: bases in a shell of the ball, pointing outwards-ish."""
    draws = np.array([[rng.gauss(0, 1), rng.gauss(0, 1), rng.gauss(0, 1), rng.uniform(0.55, 1.0),
                       rng.gauss(0, 1), rng.gauss(0, 1), rng.gauss(0, 1), rng.uniform(0.8, 1.2)]
                      for _ in range(count)]).reshape(count, 8)
    direction = normalised(draws[:, 0:3])
    base = np.asarray(centre) + radius * np.cbrt(draws[:, 3:4]) * direction * [1.0, 1.0, 0.85]
    axis = normalised(direction + 0.8 * draws[:, 4:7] / np.sqrt(3.0))
    helper = np.where(np.abs(axis[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    side = normalised(np.cross(axis, helper))
    return add_leaves(builder, base, axis, side, 0.1 * draws[:, 7], 0.05 * draws[:, 7])


def build_patio(triangles=TRIANGLES, seed=SEED, lightmaps=True):
    """Reset to an empty factory scene and build the patio in it, with exactly `triangles`
    triangles (fewer: smaller crowns).  `lightmaps=False` skips the "Lightmap" UV layers."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    rng = random.Random(seed)
    mat = {name: make_material(name, colour) for name, colour in [
        ("Stucco", STUCCO), ("Stone", STONE), ("Tiles", TILES), ("RoofTiles", ROOF), ("Water", WATER),
        ("Wood", WOOD), ("Terracotta", TERRACOTTA), ("Bark", BARK), ("Foliage", FOLIAGE)]}
    parts = []  # (name, builder, material)

    def part(name, material):
        builder = MeshBuilder()
        parts.append((name, builder, mat[material]))
        return builder

    floor = part("Floor", "Tiles")
    used = quad_grid(floor, (-HALF, -HALF, 0.0), (2 * HALF, 0.0, 0.0), (0.0, 2 * HALF, 0.0),
                     FLOOR_GRID, FLOOR_GRID)
    walls, roof_builder = part("Walls", "Stucco"), part("Roof", "RoofTiles")
    for side in range(4):  # inner faces of the walls, looking into the court
        used += quad_grid(walls, (HALF, -HALF, 0.0), (-2 * HALF, 0.0, 0.0), (0.0, 0.0, WALL_HEIGHT),
                          32, 14, side)
        used += roof(roof_builder, side)
    for side, name in enumerate(SIDES):
        used += arcade(part("Arcade" + name, "Stucco"), side)
    for side, name in enumerate(SIDES):
        columns = part("Columns" + name, "Stone")
        for b in range(4):
            x, y = turn([(-ARCADE + b * BAY, -ARCADE, 0.0)], side)[0, :2]
            used += column(columns, x, y)
    used += fountain(part("Fountain", "Stone"), part("Water", "Water"))
    benches = part("Benches", "Wood")
    for side in range(4):
        used += bench(benches, side)
    planters, trunks = part("Planters", "Terracotta"), part("Trunks", "Bark")
    spots = [(x, y) for x, y in ((-3.6, -3.6), (3.6, -3.6), (3.6, 3.6), (-3.6, 3.6))]
    for x, y in spots:
        used += planter(planters, (x, y, 0.0))
        trunk_line = np.array([(x, y, 0.5), (x + 0.02, y, 1.2), (x, y + 0.03, 1.9)])
        used += tube(trunks, trunk_line, np.array([0.06, 0.05, 0.035]), 8)
    rest = triangles - used
    if rest < 0 or rest % 2:
        raise ValueError(f"cannot fill {triangles} triangles with leaves: {rest} left for them")
    n_leaves = rest // 2
    for i, (x, y) in enumerate(spots):
        count = n_leaves // 4 + (1 if i < n_leaves % 4 else 0)
        used += crown(part(f"Crown{i + 1}", "Foliage"), rng, (x, y, 2.3), 0.85, count)
    assert used == triangles, (used, triangles)
    for name, builder, material in parts:
        add_object(name, builder, material, lightmaps)

    add_sun(scene, SUN_STRENGTH, SUN_ELEVATION_DEG, SUN_AZIMUTH_DEG)
    set_world(scene, SKY, 1.0)
    add_camera(scene, (1.2, -7.3, 1.6), (0.0, 2.0, 1.6), lens=16.0)  # from the south gallery
    set_render(scene)
    bpy.context.view_layer.update()  # valid matrix_world for callers that import this
    return scene


def main(argv=None):
    """Build the scene and save it to argv[0] (default: patio.blend here)."""
    return generate(build_patio, DEFAULT_OUTPUT, argv)


if __name__ == "__main__":
    main()
