"""Build the detp_bake sample scene "tree": a procedural tree on a ground plane.

The paper this project implements (García et al., CEIG 2005) times its estimators on a tree
("Árbol", 72,500 triangles) and a patio (122,318 triangles); this scene stands in for the tree,
with exactly TRIANGLES = 72,500 triangles.  A trunk (Z up, base at the origin) splits into
branches in three levels (tapered tubes, smooth shaded); the last level carries flat diamond
leaves (one quad, two triangles each) in clouds around the twigs.  The number of leaves is what is
left of the triangle budget once the ground and the wood are built, so the total is exact.  A
ground plane (20 x 20 m) lies under it.  Light: a sun of strength 3 at 40 degrees elevation and a
constant sky-blue world (0.35, 0.45, 0.6), strength 1.

Objects: Ground, Trunk (trunk + first-level branches), Branches (second and third levels) and
LEAF_GROUPS leaf objects Leaves01.. (one per half of each first-level branch), so that each gets
its own lightmap.  Every mesh has a texture UV layer "UVMap" (first, active: coordinates in metres)
and a "Lightmap" UV layer in [0, 1].  The lightmap charts are made here, not by Lightmap Pack
(which cuts every face into its own chart: on a tube of hundreds of faces that leaves about a texel
per chart at 128 x 128): each tube is cut open along one line and unrolled, each planar piece is
one chart, each leaf is one chart; all charts of an object share one scale (uniform texel density)
and are shelf-packed LIGHTMAP_MARGIN apart (2 texels at 128 x 128; less on the leaf objects, whose
thousands of charts would not fit otherwise, see lightmap_margin).  make_patio.py uses the same
helpers.  All randomness comes from random.Random(SEED) and the packing is plain arithmetic, so
the scene is the same on every run and Blender line.

Usage (with the bpy module, Blender 4.5 or 5.x):
    python sample_scenes/make_tree.py [OUTPUT.blend]
"""

import math
import os
import random
import sys

import bpy
import numpy as np
from mathutils import Vector

TRIANGLES = 72_500
SEED = 2005
GROUND_SIZE = 20.0
GROUND_GRID = 24  # quads per side of the ground
LEAF_GROUPS = 12  # leaf objects (each first-level branch gives two)
BARK = (0.30, 0.23, 0.20)
LEAF = (0.22, 0.45, 0.20)
GRASS = (0.30, 0.40, 0.22)
SKY = (0.35, 0.45, 0.6)
SUN_STRENGTH = 3.0
SUN_ELEVATION_DEG = 40.0
SUN_AZIMUTH_DEG = 30.0
# Branch levels: branches per parent, faces around, rings along.
LEVEL1 = dict(count=6, sides=10, rings=6)
LEVEL2 = dict(count=6, sides=6, rings=4)
LEVEL3 = dict(count=6, sides=4, rings=3)
LEAF_LENGTH = 0.12
LEAF_WIDTH = 0.06
# Margin between lightmap charts as a fraction of the UV square: 2 texels at 128 x 128 (less on
# objects with thousands of charts, see lightmap_margin).
LIGHTMAP_MARGIN = 2.0 / 128
DEFAULT_OUTPUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "tree.blend")


# --------------------------------------------------------------------------- Blender helpers

def make_material(name, color):
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:  # Blender < 5.0 creates materials without nodes
        mat.use_nodes = True
    mat.diffuse_color = (*color, 1.0)  # viewport colour
    bsdf = next(n for n in mat.node_tree.nodes if n.type == 'BSDF_PRINCIPLED')
    values = {"Base Color": (*color, 1.0), "Roughness": 1.0, "Metallic": 0.0,
              "Specular IOR Level": 0.0}
    for socket, value in values.items():
        if socket in bsdf.inputs:
            bsdf.inputs[socket].default_value = value
    return mat


class MeshBuilder:
    """Polygons (3 or 4 corners) of one mesh, grouped in lightmap charts.

    Each `add` call is one chart: `chart_uvs` gives every corner a position in metres in the
    chart's own plane (the surface unrolled or projected without stretching), which becomes the
    texture layer "UVMap" as it is (texture coordinates in metres) and, packed with the other
    charts by pack_charts, the "Lightmap" layer."""

    def __init__(self):
        self.verts, self.faces, self.chart_uvs, self.smooth, self.charts = [], [], [], [], []
        self.n_verts = 0

    def add(self, verts, faces, chart_uvs, smooth, chart_faces=None):
        """verts (n, 3); faces: tuples of local vertex indices; chart_uvs: per face, one (u, v) in
        metres per corner.  The faces make one chart, or consecutive runs of `chart_faces` faces
        make one chart each.  Returns the number of triangles added."""
        verts = np.asarray(verts, np.float64).reshape(-1, 3)
        corner = len(self.chart_uvs)
        self.verts.append(verts)
        self.faces.extend(tuple(self.n_verts + i for i in f) for f in faces)
        self.chart_uvs.extend(tuple(map(float, uv)) for f_uv in chart_uvs for uv in f_uv)
        self.smooth.extend([bool(smooth)] * len(faces))
        self.n_verts += len(verts)
        first_face = 0
        for count in chart_faces or [len(faces)]:
            n_corners = sum(len(f) for f in faces[first_face:first_face + count])
            self.charts.append((corner, corner + n_corners))
            corner += n_corners
            first_face += count
        assert first_face == len(faces) and corner == len(self.chart_uvs)
        return sum(len(f) - 2 for f in faces)

    @property
    def triangles(self):
        return sum(len(f) - 2 for f in self.faces)

    def lightmap_uvs(self, margin):
        """Per-corner lightmap UVs: every chart at one common scale (uniform texel density),
        shelf-packed into [0, 1]^2 with `margin` (a fraction of the square) between charts."""
        uv = np.array(self.chart_uvs, np.float64)
        starts = np.array([a for a, _ in self.charts])
        chart = np.repeat(np.arange(len(self.charts)), [b - a for a, b in self.charts])
        lo = np.minimum.reduceat(uv, starts)
        size = np.maximum.reduceat(uv, starts) - lo
        x, y, rotated, scale = pack_charts(size, margin)
        local = uv - lo[chart]
        turn = rotated[chart]  # a quarter turn keeps the chart's orientation
        local[turn] = np.stack([size[chart[turn], 1] - local[turn, 1], local[turn, 0]], axis=1)
        return np.stack([x, y], axis=1)[chart] + local * scale

    def mesh(self, name, lightmap_margin=None):
        """A new mesh with layers "UVMap" (chart coordinates in metres, active) and, when
        `lightmap_margin` is given, "Lightmap"."""
        me = bpy.data.meshes.new(name)
        me.from_pydata(np.concatenate(self.verts).tolist(), [], self.faces)
        me.polygons.foreach_set("use_smooth", self.smooth)
        uv = me.uv_layers.new(name="UVMap")
        uv.data.foreach_set("uv", np.asarray(self.chart_uvs, np.float64).ravel())
        if lightmap_margin is not None:
            lightmap = me.uv_layers.new(name="Lightmap")
            lightmap.data.foreach_set("uv", self.lightmap_uvs(lightmap_margin).ravel())
        me.uv_layers.active = me.uv_layers["UVMap"]
        me.uv_layers["UVMap"].active_render = True
        me.update()
        me.validate()
        return me


def pack_charts(sizes, margin):
    """Shelf packing of rectangles `sizes` (n, 2) (metres) at one common scale into the unit
    square, `margin` apart and margin/2 from its edges: the largest scale that fits, by bisection.
    Returns x (n,), y (n,), rotated (n,) and the scale; rotated rectangles lie on their side."""
    sizes = np.asarray(sizes, np.float64)
    rotated = sizes[:, 1] > sizes[:, 0]
    dims = np.where(rotated[:, None], sizes[:, ::-1], sizes)
    order = np.lexsort((np.arange(len(dims)), -dims[:, 0], -dims[:, 1]))  # tallest first
    w, h = dims[order, 0], dims[order, 1]

    def place(scale):
        """Lower-left corners in packing order, or None when the charts do not fit."""
        advance = np.concatenate([[0.0], np.cumsum(w * scale + margin)])
        x, y = np.empty(len(w)), np.empty(len(w))
        start, top = 0, margin / 2
        while start < len(w):
            end = int(np.searchsorted(advance, advance[start] + 1.0, side="right")) - 1
            if end <= start:
                return None  # one chart wider than the square
            x[start:end] = margin / 2 + advance[start:end] - advance[start]
            y[start:end] = top
            top += h[start] * scale + margin
            start = end
        return (x, y) if top - margin / 2 <= 1.0 else None

    area = float(np.sum(w * h))
    lo, hi = 0.0, min((1.0 - margin) / dims.max(), 1.0 / math.sqrt(area))
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if place(mid) is not None else (lo, mid)
    x, y = np.empty(len(w)), np.empty(len(w))
    x[order], y[order] = place(lo)
    return x, y, rotated, lo


def lightmap_margin(n_charts):
    """Margin between charts: LIGHTMAP_MARGIN (2 texels at 128 x 128), less on objects with so
    many charts that it would eat most of the square (leaves: a fraction of a texel at 128)."""
    return min(LIGHTMAP_MARGIN, 0.15 / math.sqrt(n_charts))


def add_object(name, builder, material, lightmap=True):
    """Link a new object made from `builder`, with a packed "Lightmap" layer unless told not to."""
    margin = lightmap_margin(len(builder.charts)) if lightmap else None
    mesh = builder.mesh(name, margin)
    mesh.materials.append(material)
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def set_world(scene, color, strength):
    world = bpy.data.worlds.new("World")
    world.color = color
    if world.node_tree is None:  # Blender < 5.0
        world.use_nodes = True
    background = next(n for n in world.node_tree.nodes if n.type == 'BACKGROUND')
    background.inputs["Color"].default_value = (*color, 1.0)
    background.inputs["Strength"].default_value = strength
    scene.world = world


def add_sun(scene, strength, elevation_deg, azimuth_deg):
    """A sun whose light travels down at `elevation_deg` above the horizon, coming from azimuth
    `azimuth_deg` (counter-clockwise from +X)."""
    sun = bpy.data.lights.new("Sun", type='SUN')
    sun.energy = strength
    sun.angle = math.radians(0.5)
    obj = bpy.data.objects.new("Sun", sun)
    obj.rotation_euler = (math.radians(90.0 - elevation_deg), 0.0, math.radians(azimuth_deg + 90.0))
    obj.location = (0.0, 0.0, 10.0)
    scene.collection.objects.link(obj)
    return obj


def add_camera(scene, location, target, lens=35.0):
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.lens = lens
    cam.location = location
    cam.rotation_euler = (Vector(target) - Vector(location)).to_track_quat('-Z', 'Y').to_euler()
    scene.collection.objects.link(cam)
    scene.camera = cam
    return cam


def set_render(scene, resolution=(1024, 768)):
    scene.render.engine = 'CYCLES'
    scene.cycles.device = 'CPU'
    scene.cycles.samples = 64
    scene.cycles.diffuse_bounces = 4
    scene.render.resolution_x, scene.render.resolution_y = resolution


def save(output):
    bpy.context.preferences.filepaths.save_version = 0  # no OUTPUT.blend1 backup
    save_props = bpy.ops.wm.save_as_mainfile.get_rna_type().properties
    kwargs = {"compress": True} if "compress" in save_props else {}
    bpy.ops.wm.save_as_mainfile(filepath=output, **kwargs)
    print("Saved", output)


def mesh_triangles(scene):
    """Triangles of every mesh object's evaluated mesh, by object name."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    counts = {}
    for obj in scene.objects:
        if obj.type == 'MESH':
            ev = obj.evaluated_get(depsgraph)
            me = ev.to_mesh()
            me.calc_loop_triangles()
            counts[obj.name] = len(me.loop_triangles)
            ev.to_mesh_clear()
    return counts


# --------------------------------------------------------------------------- geometry

def grid(builder, size, n):
    """n x n quads over [-size/2, size/2]^2 at z = 0, normal +Z: one chart."""
    s = np.linspace(-size / 2, size / 2, n + 1)
    x, y = np.meshgrid(s, s)  # row j: y = s[j]
    verts = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    faces = [(j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i)
             for j in range(n) for i in range(n)]
    return builder.add(verts, faces, [[verts[v, :2] for v in f] for f in faces], smooth=False)


def tube(builder, centres, radii, sides):
    """A tube along the polyline `centres` (k, 3) with ring radii `radii` (k,), `sides` faces
    around, open at the start and closed at the end by a cone to a tip vertex; one chart, the
    tube cut open and unrolled (each ring keeps its circumference).
    Triangles: 2*sides*(k-1) + sides."""
    centres = np.asarray(centres, np.float64)
    radii = np.asarray(radii, np.float64)
    k = len(centres)
    tangents = np.gradient(centres, axis=0)
    tangents /= np.linalg.norm(tangents, axis=1, keepdims=True)
    normal = perpendicular(tangents[0])
    angles = 2.0 * np.pi * np.arange(sides) / sides
    rings = []
    for c, t, r in zip(centres, tangents, radii):  # parallel transport of the ring frame
        normal = normal - np.dot(normal, t) * t
        normal /= np.linalg.norm(normal)
        binormal = np.cross(t, normal)
        rings.append(c + r * (np.cos(angles)[:, None] * normal + np.sin(angles)[:, None] * binormal))
    tip = centres[-1] + tangents[-1] * radii[-1]
    verts = np.concatenate(rings + [tip[None]])
    # Unrolled: v = length along the axis, u = arc length around ring i, centred on u = 0.
    v = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(centres, axis=0), axis=1))])
    chord = 2.0 * np.sin(np.pi / sides)  # polygon side of a unit ring

    def corner(i, j):
        return ((j - sides / 2) * chord * radii[i], v[i])

    faces, uvs = [], []
    for i in range(k - 1):
        for j in range(sides):
            j1 = (j + 1) % sides
            faces.append((i * sides + j, i * sides + j1, (i + 1) * sides + j1, (i + 1) * sides + j))
            uvs.append([corner(i, j), corner(i, j + 1), corner(i + 1, j + 1), corner(i + 1, j)])
    last = (k - 1) * sides
    tip_uv = (0.0, v[-1] + radii[-1] * math.sqrt(2.0))
    for j in range(sides):
        faces.append((last + j, last + (j + 1) % sides, k * sides))
        uvs.append([corner(k - 1, j), corner(k - 1, j + 1), tip_uv])
    return builder.add(verts, faces, uvs, smooth=True)


def unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)


def normalised(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def perpendicular(d):
    helper = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    p = np.cross(d, helper)
    return p / np.linalg.norm(p)


def branch_curve(rng, start, direction, length, rings, droop):
    """Polyline of `rings` points from `start`, bending down by `droop` (and a little at random)."""
    d = unit(direction)
    wobble = np.array([rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1)]) * 0.15
    pts = [np.asarray(start, np.float64)]
    step = length / (rings - 1)
    for _ in range(rings - 1):
        d = unit(d + (np.array([0.0, 0.0, -droop]) + wobble) / (rings - 1))
        pts.append(pts[-1] + step * d)
    return np.array(pts)


def point_on(curve, t):
    """Point and direction at parameter t in [0, 1] along a polyline."""
    x = t * (len(curve) - 1)
    i = min(int(x), len(curve) - 2)
    f = x - i
    return curve[i] * (1 - f) + curve[i + 1] * f, unit(curve[i + 1] - curve[i])


def child_direction(rng, parent_dir, angle_deg, azimuth):
    side = perpendicular(parent_dir)
    other = np.cross(parent_dir, side)
    radial = math.cos(azimuth) * side + math.sin(azimuth) * other
    a = math.radians(angle_deg)
    return unit(math.cos(a) * parent_dir + math.sin(a) * radial + np.array([0, 0, 0.25]))


def leaves(builder, rng, twig, count):
    """`count` leaves (see add_leaves) in a cloud around the twig polyline."""
    draws = np.array([[rng.uniform(0.15, 1.0), rng.gauss(0, 1), rng.gauss(0, 1), rng.gauss(0, 1),
                       rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1),
                       rng.uniform(0.0, math.pi), rng.uniform(0.8, 1.2), rng.uniform(0.8, 1.2)]
                      for _ in range(count)]).reshape(count, 10)
    x = draws[:, 0] * (len(twig) - 1)  # point and direction along the twig
    i = np.minimum(x.astype(int), len(twig) - 2)
    f = (x - i)[:, None]
    p = twig[i] * (1 - f) + twig[i + 1] * f
    d = normalised(twig[i + 1] - twig[i])
    offset = draws[:, 1:4] * 0.09
    base = p + offset
    axis = normalised(normalised(offset) + 0.6 * d + np.array([0.0, 0.0, 0.3]) + 0.5 * draws[:, 4:7])
    helper = np.where(np.abs(axis[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    side = normalised(np.cross(axis, helper))
    roll = draws[:, 7:8]
    side = np.cos(roll) * side + np.sin(roll) * np.cross(axis, side)
    return add_leaves(builder, base, axis, side, LEAF_LENGTH * draws[:, 8], LEAF_WIDTH * draws[:, 9])


def add_leaves(builder, base, axis, side, length, width):
    """Flat rhombus leaves (one quad each) from `base` along unit `axis`, `side` across (all (n, 3)),
    each its own chart: the rhombus sheared onto a square of the same area.  Returns triangles."""
    length, width = np.asarray(length)[:, None], np.asarray(width)[:, None]
    mid = base + 0.5 * length * axis
    verts = np.stack([base, mid - 0.5 * width * side, base + length * axis, mid + 0.5 * width * side],
                     axis=1)
    a = np.sqrt(0.5 * length[:, 0] * width[:, 0])
    for n in range(len(verts)):
        builder.add(verts[n], [(0, 1, 2, 3)], [[(0.0, 0.0), (a[n], 0.0), (a[n], a[n]), (0.0, a[n])]],
                    smooth=False)
    return 2 * len(verts)


def build_tree_geometry(rng, triangles):
    """Builders for Ground, Trunk, Branches and the leaf groups, with exactly `triangles`."""
    ground, trunk, branches = MeshBuilder(), MeshBuilder(), MeshBuilder()
    used = grid(ground, GROUND_SIZE, GROUND_GRID)

    # Trunk: 3.6 m, leaning a little, base below the ground so that no cap is needed.
    trunk_curve = branch_curve(rng, (0.0, 0.0, -0.1), (0.05, 0.02, 1.0), 3.7, 10, -0.05)
    trunk_radii = np.linspace(0.20, 0.08, 10)
    used += tube(trunk, trunk_curve, trunk_radii, 16)

    # Level 1 along the upper trunk, level 2 along each of those, level 3 (twigs) on level 2.
    twigs = []  # (leaf group, polyline)
    golden = math.radians(137.5)
    for b1 in range(LEVEL1["count"]):
        t = 0.5 + 0.45 * b1 / (LEVEL1["count"] - 1)
        start, d = point_on(trunk_curve, t)
        direction = child_direction(rng, d, rng.uniform(45, 60), b1 * golden + rng.uniform(-0.3, 0.3))
        length = rng.uniform(2.3, 2.8) * (1.0 - 0.3 * b1 / LEVEL1["count"])
        curve1 = branch_curve(rng, start, direction, length, LEVEL1["rings"], 0.25)
        r0 = 0.075 * (1.0 - 0.3 * b1 / LEVEL1["count"])
        used += tube(trunk, curve1, np.linspace(r0, 0.02, LEVEL1["rings"]), LEVEL1["sides"])
        for b2 in range(LEVEL2["count"]):
            t2 = 0.25 + 0.7 * b2 / (LEVEL2["count"] - 1)
            start2, d2 = point_on(curve1, t2)
            dir2 = child_direction(rng, d2, rng.uniform(35, 55), b2 * golden + rng.uniform(-0.5, 0.5))
            len2 = rng.uniform(0.8, 1.2) * (1.0 - 0.4 * t2)
            curve2 = branch_curve(rng, start2, dir2, len2, LEVEL2["rings"], 0.2)
            used += tube(branches, curve2, np.linspace(0.022, 0.008, LEVEL2["rings"]), LEVEL2["sides"])
            group = 2 * b1 + (b2 * 2) // LEVEL2["count"]
            for b3 in range(LEVEL3["count"]):
                t3 = 0.2 + 0.75 * b3 / (LEVEL3["count"] - 1)
                start3, d3 = point_on(curve2, t3)
                dir3 = child_direction(rng, d3, rng.uniform(30, 60), b3 * golden + rng.uniform(-0.5, 0.5))
                curve3 = branch_curve(rng, start3, dir3, rng.uniform(0.3, 0.45), LEVEL3["rings"], 0.1)
                used += tube(branches, curve3, np.linspace(0.008, 0.003, LEVEL3["rings"]), LEVEL3["sides"])
                twigs.append((group, curve3))

    # Leaves take the rest of the budget: two triangles each, spread evenly over the twigs.
    rest = triangles - used
    if rest < 0 or rest % 2:
        raise ValueError(f"cannot fill {triangles} triangles with leaves: {rest} left for them")
    n_leaves = rest // 2
    groups = [MeshBuilder() for _ in range(LEAF_GROUPS)]
    for i, (group, twig) in enumerate(twigs):
        count = n_leaves // len(twigs) + (1 if i < n_leaves % len(twigs) else 0)
        used += leaves(groups[group], rng, twig, count)
    assert used == triangles
    return ground, trunk, branches, groups


def build_tree(triangles=TRIANGLES, seed=SEED, lightmaps=True):
    """Reset to an empty factory scene and build the tree scene in it, with exactly `triangles`
    triangles (a smaller number gives fewer leaves: quicker, for tests).  `lightmaps=False` skips
    the "Lightmap" UV layers."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    rng = random.Random(seed)

    bark = make_material("Bark", BARK)
    leaf = make_material("Leaf", LEAF)
    grass = make_material("Grass", GRASS)
    ground, trunk, branches, groups = build_tree_geometry(rng, triangles)
    add_object("Ground", ground, grass, lightmaps)
    add_object("Trunk", trunk, bark, lightmaps)
    add_object("Branches", branches, bark, lightmaps)
    for i, group in enumerate(groups):
        add_object(f"Leaves{i + 1:02d}", group, leaf, lightmaps)

    add_sun(scene, SUN_STRENGTH, SUN_ELEVATION_DEG, SUN_AZIMUTH_DEG)
    set_world(scene, SKY, 1.0)
    add_camera(scene, (6.5, -7.5, 1.7), (0.0, 0.0, 3.0), lens=28.0)
    set_render(scene)
    bpy.context.view_layer.update()  # valid matrix_world for callers that import this
    return scene


def generate(build, default_output: str, argv=None) -> str:
    """Build a scene with `build()` and save it to argv[0] (default: `default_output`): every
    generator's command line."""
    argv = sys.argv[1:] if argv is None else list(argv)
    output = os.path.abspath(argv[0] if argv else default_output)
    scene = build()
    print("Triangles:", sum(mesh_triangles(scene).values()))
    save(output)
    return output


def main(argv=None):
    """Build the scene and save it to argv[0] (default: tree.blend here)."""
    return generate(build_tree, DEFAULT_OUTPUT, argv)


if __name__ == "__main__":
    main()
