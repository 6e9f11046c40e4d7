"""Build the detp_bake sample scene "courtyard": a small walled courtyard as a user would make it.

Issue 8's ordinary scene: the features real level content uses, together, in 2,102 rendered
triangles.  Z up, metres, x east, y north; the court is 8 x 6 m (x in [-4, 4], y in [-3, 3]),
walled on the north, west and east (2.6 m high, 0.25 m thick, boxes without bottoms) and open to
the south.

- Floor: a 4 x 3 grid of quads whose material has an Image Texture on Base Color: FLOOR_TILES, a
  256 x 256 sRGB tile pattern (4 x 4 sandstone tiles with grout) made here with numpy and packed
  into the .blend, read through the render-active UV layer "UVMap" (the image covers 2 x 2 m,
  Repeat).
- NorthWall and WestWall in pale plaster, EastWall in terracotta.
- Pillars: one pillar with an Array modifier (PILLARS copies, 1.5 m apart, on in renders and the
  viewport) standing in a row 0.8 m in front of the north wall, under a Beam that spans the court
  from the west wall to the east wall.  The Array offsets each copy's UVs (offset_u), and the
  pillar's "Lightmap" layer is squeezed into the first copy's strip, so the copies get lightmap
  charts side by side instead of on top of each other.
- Boulder: a slightly irregular cube with a Subdivision Surface modifier, viewport level 1, render
  level 3 (F12 renders 768 triangles, the viewport shows 48).
- Handrail: a Bezier curve along the west wall, 0.9 m up and 12 cm off it, with a round bevel
  (2.5 cm radius) and capped ends, which renders as geometry; its ends bend into the wall.
- Three trees "TreeInstance1..3": Empties instancing the collection "Tree" (a trunk with three
  branches, TreeTrunk, and LEAF_CARDS leaf cards, TreeLeaves), which is linked to the scene but
  excluded from the view layer, so only the instances render.  The cards' material feeds the
  Color and Alpha of LEAF_ATLAS (256 x 256 RGBA, packed: a sprig of leaves, alpha 0 around them)
  into Base Color and Alpha of a Principled BSDF.
- Light: an HDRI world, an Environment Texture on SKY_FILE (a 256 x 128 half-float EXR written
  next to the .blend and referenced by a relative path: a sky gradient over a dark ground and a
  bright sun spot) read through Texture Coordinate (Generated) -> Mapping (Z rotation
  SKY_ROTATION_DEG) -> Vector; and a Sun light (strength SUN_STRENGTH) aligned with the sun spot
  as the Mapping rotation places it in the world.

Every bakeable mesh (Floor, the three walls, Pillars, Beam, Boulder) has a texture UV layer
"UVMap" (first, active: coordinates in metres, the floor's in image repeats) and a "Lightmap" layer
made by Lightmap Pack (`make_cornell_box.add_lightmap_uv`).  The meshes of the Tree collection have
"UVMap" only: they are only instances, which light and shadow the others but get no lightmap.
Cycles on the CPU, 4 diffuse bounces, a camera south of the court.  Randomness comes from
random.Random(SEED) and numpy's PCG64(SEED) uniforms, images are quantised to 8 bits (half floats
for the sky) before they are stored, so the scene is the same on every run and Blender line.

Usage (with the bpy module, Blender 4.5 or 5.x, and the project's requirements for OpenImageIO):
    python sample_scenes/make_courtyard.py [OUTPUT.blend]   # also writes courtyard_sky.exr beside it
"""

import math
import os
import random
import sys

import bpy
import numpy as np
from mathutils import Vector

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.dirname(HERE))  # the repository root, for detp_bake.lightmap.images
from make_cornell_box import add_lightmap_uv, box_mesh  # noqa: E402
from make_patio import box, quad_grid  # noqa: E402
from make_tree import (MeshBuilder, add_camera, add_sun, make_material, save, set_render,  # noqa: E402
                       tube)

from detp_bake.lightmap.images import write_exr  # noqa: E402

SEED = 8
HALF_X, HALF_Y = 4.0, 3.0  # the floor; the walls stand outside it
WALL_HEIGHT = 2.6
WALL_THICKNESS = 0.25
PILLARS = 5  # copies made by the Array modifier
PILLAR_SPACING = 1.5
PILLAR_Y = 2.2
PILLAR_SIZE = (0.3, 0.3, 2.4)
PILLAR_GUTTER = 0.08  # of each copy's lightmap strip, on either side (1 texel at 64 x 64)
BEAM_HEIGHT = 0.2
LEAF_CARDS = 32
LEAF_CARD_SIZE = 0.7
TREES = [  # (location, Z rotation in degrees, uniform scale)
    ((-2.4, -0.7, 0.0), 0.0, 1.0),
    ((2.2, 0.8, 0.0), 75.0, 0.85),
    ((0.4, -2.0, 0.0), 200.0, 0.95),
]
PLASTER = (0.72, 0.69, 0.63)
TERRACOTTA = (0.60, 0.33, 0.22)
STONE = (0.50, 0.48, 0.44)
BEAM_WOOD = (0.40, 0.29, 0.20)
RAIL = (0.30, 0.30, 0.32)
BARK = (0.30, 0.23, 0.20)
TEXTURE_SIZE = 256
FLOOR_METRES_PER_IMAGE = 2.0
FLOOR_TILES_PER_IMAGE = 4
FLOOR_TILES = "FloorTiles"
LEAF_ATLAS = "LeafAtlas"
SKY_SIZE = (256, 128)
SKY_FILE = "courtyard_sky.exr"
SKY_ROTATION_DEG = 40.0  # the Mapping node's Z rotation
SUN_ELEVATION_DEG = 45.0
SUN_AZIMUTH_DEG = -60.0  # in the world, counter-clockwise from +X: from the south-south-east
SUN_SPOT_PEAK = 200.0  # the sky image's sun, a Gaussian spot (about 1.5 W/m² of irradiance)
SUN_SPOT_SIGMA_DEG = 2.0
SUN_STRENGTH = 3.0
ZENITH = np.array([0.10, 0.22, 0.55])
HORIZON = np.array([0.55, 0.62, 0.72])
GROUND = np.array([0.16, 0.14, 0.11])
DEFAULT_OUTPUT = os.path.join(HERE, "courtyard.blend")


# --------------------------------------------------------------------------- images

def _rng():
    return np.random.Generator(np.random.PCG64(SEED))


def tile_pixels(size=TEXTURE_SIZE, tiles=FLOOR_TILES_PER_IMAGE):
    """(size, size, 4) float32 sRGB values, multiples of 1/255: `tiles` x `tiles` sandstone tiles
    with 4-pixel grout lines on the tile borders (2 pixels on each side, so the image repeats
    seamlessly), each tile its own shade, a little grain.  Row 0 is the bottom."""
    rng = _rng()
    shade = 0.88 + 0.2 * rng.random((tiles, tiles))  # per tile
    grain = 0.96 + 0.08 * rng.random((size, size))
    base = np.array([196.0, 164.0, 124.0])  # sandstone, sRGB 0..255
    grout = np.array([150.0, 146.0, 138.0])
    cell = size // tiles
    idx = np.arange(size)
    tile = idx // cell
    edge = np.minimum(idx % cell, cell - 1 - idx % cell) < 2
    colour = base * (shade[tile[:, None], tile[None, :]] * grain)[..., None]
    colour[edge[:, None] | edge[None, :]] = grout * grain[edge[:, None] | edge[None, :]][:, None]
    rgba = np.concatenate([np.clip(np.round(colour), 0, 255), np.full((size, size, 1), 255.0)], axis=2)
    return (rgba / 255.0).astype(np.float32)


def leaf_pixels(size=TEXTURE_SIZE):
    """(size, size, 4) float32 sRGB values with straight alpha, multiples of 1/255: a sprig (a thin
    twig up the middle of the image and nine pointed leaves along it), alpha 1 on the sprig and 0
    around it; the colour under alpha 0 is the mean leaf green, so filtering makes no dark rim."""
    rng = random.Random(SEED)
    y, x = (np.mgrid[0:size, 0:size] + 0.5) / size  # row 0 at the bottom: y = 0
    green = np.array([70.0, 120.0, 45.0])
    rgb = np.broadcast_to(green, (size, size, 3)).copy()
    alpha = np.zeros((size, size))
    leaves = [(0.5, 0.68, 90.0, 0.30)]  # (where on the twig x, y, direction in degrees, length)
    for k in range(8):
        side = 1 if k % 2 == 0 else -1
        leaves.append((0.5, 0.08 + 0.075 * k, 90.0 - side * (50.0 + rng.uniform(-10.0, 10.0)),
                       0.30 + rng.uniform(-0.04, 0.04)))
    for bx, by, angle, length in leaves:
        d = np.array([math.cos(math.radians(angle)), math.sin(math.radians(angle))])
        s = ((x - bx) * d[0] + (y - by) * d[1]) / length
        t = ((x - bx) * -d[1] + (y - by) * d[0]) / (0.28 * length)
        inside = (s > 0.0) & (s < 1.0) & (np.abs(t) < np.sin(np.pi * np.clip(s, 0.0, 1.0)) ** 0.7)
        tint = np.array([rng.uniform(0.85, 1.15), rng.uniform(0.9, 1.12), rng.uniform(0.85, 1.1)])
        rib = inside & (np.abs(t) < 0.08)
        rgb[inside] = green * tint
        rgb[rib] = green * tint * 1.35
        alpha[inside] = 1.0
    twig = (np.abs(x - 0.5) < 0.008) & (y < 0.7)
    rgb[twig] = (92.0, 70.0, 50.0)
    alpha[twig] = 1.0
    rgba = np.concatenate([np.clip(np.round(rgb), 0, 255), 255.0 * alpha[..., None]], axis=2)
    return (rgba / 255.0).astype(np.float32)


def sky_directions(width, height):
    """World-independent image directions at the pixel centres: (height, width, 3), row 0 the
    nadir, as Cycles maps an equirectangular image: u = 1/2 - atan2(y, x)/2pi, v = 1/2 + asin(z)/pi."""
    v = (np.arange(height) + 0.5) / height
    u = (np.arange(width) + 0.5) / width
    elev = (v - 0.5) * np.pi
    azim = (0.5 - u) * 2.0 * np.pi
    ce = np.cos(elev)[:, None]
    return np.stack([ce * np.cos(azim)[None, :], ce * np.sin(azim)[None, :],
                     np.broadcast_to(np.sin(elev)[:, None], (height, width))], axis=2)


def sun_image_direction():
    """The sun spot's direction in the image: the world sun direction turned by the Mapping
    rotation (the world direction w reads the image at Rz(SKY_ROTATION_DEG) w)."""
    e = math.radians(SUN_ELEVATION_DEG)
    a = math.radians(SUN_AZIMUTH_DEG + SKY_ROTATION_DEG)
    return np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])


def sky_pixels(width=SKY_SIZE[0], height=SKY_SIZE[1]):
    """(height, width, 3) float32 linear radiance, row 0 the nadir, stored as half floats: a sky
    from HORIZON to ZENITH with a soft glow round the sun, a dark GROUND below a 3 degree blend at
    the horizon, and the sun spot, SUN_SPOT_PEAK at its centre."""
    d = sky_directions(width, height)
    z = d[..., 2]
    t = (1.0 - np.clip(z, 0.0, 1.0)) ** 3
    sky = ZENITH * (1.0 - t)[..., None] + HORIZON * t[..., None]
    angle = np.arccos(np.clip(d @ sun_image_direction(), -1.0, 1.0))
    sky = sky * (1.0 + 1.5 * np.exp(-(angle / 0.35) ** 2))[..., None]
    ground = GROUND * (0.8 + 0.2 * np.clip(1.0 + z, 0.0, 1.0))[..., None]
    blend = np.clip(z / math.sin(math.radians(3.0)) * 0.5 + 0.5, 0.0, 1.0)[..., None]
    radiance = sky * blend + ground * (1.0 - blend)
    sigma = math.radians(SUN_SPOT_SIGMA_DEG)
    radiance = radiance + SUN_SPOT_PEAK * np.exp(-0.5 * (angle / sigma) ** 2)[..., None]
    return radiance.astype(np.float16).astype(np.float32)


def packed_image(name, pixels, alpha):
    """A packed 8-bit sRGB image datablock from (h, w, 4) pixels (row 0 at the bottom)."""
    h, w = pixels.shape[:2]
    img = bpy.data.images.new(name, w, h, alpha=alpha)
    img.colorspace_settings.name = 'sRGB'
    img.alpha_mode = 'STRAIGHT'
    img.pixels.foreach_set(np.ascontiguousarray(pixels, np.float32).ravel())
    img.file_format = 'PNG'
    img.pack()
    return img


# --------------------------------------------------------------------------- materials and world

def textured_material(name, image, alpha=False):
    """make_material's Principled BSDF with `image` (through the render-active UV layer) on Base
    Color, and on Alpha too when `alpha`."""
    mat = make_material(name, (0.5, 0.5, 0.5))
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    bsdf = next(n for n in nodes if n.type == 'BSDF_PRINCIPLED')
    tex = nodes.new("ShaderNodeTexImage")
    tex.name = tex.label = name + " texture"
    tex.image = image
    tex.interpolation = 'Linear'
    tex.extension = 'REPEAT'
    tex.location = (bsdf.location.x - 350.0, bsdf.location.y)
    links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    if alpha:
        links.new(tex.outputs["Alpha"], bsdf.inputs["Alpha"])
    return mat


def set_hdri_world(scene, sky_path):
    """World: Texture Coordinate (Generated) -> Mapping (Z rotation) -> Environment Texture on the
    EXR at `sky_path` -> Background (strength 1)."""
    world = bpy.data.worlds.new("World")
    world.color = tuple(HORIZON)
    if world.node_tree is None:  # Blender < 5.0
        world.use_nodes = True
    nodes, links = world.node_tree.nodes, world.node_tree.links
    background = next(n for n in nodes if n.type == 'BACKGROUND')
    background.inputs["Strength"].default_value = 1.0
    coords = nodes.new("ShaderNodeTexCoord")
    mapping = nodes.new("ShaderNodeMapping")
    mapping.vector_type = 'POINT'
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(SKY_ROTATION_DEG))
    env = nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(sky_path)
    env.image.name = "Sky"
    env.interpolation = 'Linear'
    env.projection = 'EQUIRECTANGULAR'
    for k, node in enumerate((coords, mapping, env)):
        node.location = (background.location.x - 300.0 * (3 - k), background.location.y)
    links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
    links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    links.new(env.outputs["Color"], background.inputs["Color"])
    scene.world = world
    return world


# --------------------------------------------------------------------------- objects

def link(name, data, collection=None, location=(0.0, 0.0, 0.0), rot_z_deg=0.0):
    obj = bpy.data.objects.new(name, data)
    obj.location = location
    obj.rotation_euler = (0.0, 0.0, math.radians(rot_z_deg))
    (collection or bpy.context.scene.collection).objects.link(obj)
    return obj


def mesh_object(name, builder, material, collection=None, location=(0.0, 0.0, 0.0)):
    mesh = builder.mesh(name)  # "UVMap" only; the "Lightmap" layer comes from Lightmap Pack
    mesh.materials.append(material)
    return link(name, mesh, collection, location)


def build_walls():
    h, t = WALL_HEIGHT, WALL_THICKNESS
    walls = {
        "NorthWall": ((0.0, HALF_Y + t / 2, h / 2), (2 * (HALF_X + t), t, h), PLASTER),
        "WestWall": ((-HALF_X - t / 2, 0.0, h / 2), (t, 2 * HALF_Y, h), PLASTER),
        "EastWall": ((HALF_X + t / 2, 0.0, h / 2), (t, 2 * HALF_Y, h), TERRACOTTA),
    }
    objects = []
    for name, (centre, size, colour) in walls.items():
        builder = MeshBuilder()
        box(builder, centre, size, bottom=False)
        objects.append(mesh_object(name, builder, make_material(name, colour)))
    return objects


def build_floor():
    builder = MeshBuilder()
    quad_grid(builder, (-HALF_X, -HALF_Y, 0.0), (2 * HALF_X, 0, 0), (0, 2 * HALF_Y, 0), 4, 3)
    image = packed_image(FLOOR_TILES, tile_pixels(), alpha=False)
    obj = mesh_object("Floor", builder, textured_material("Floor", image))
    uv = obj.data.uv_layers["UVMap"]  # metres -> image repeats
    co = np.empty(len(uv.data) * 2)
    uv.data.foreach_get("uv", co)
    uv.data.foreach_set("uv", co / FLOOR_METRES_PER_IMAGE)
    return obj


def build_pillars():
    """One pillar (bottomless box) at the west end of the row and an Array modifier for the rest."""
    builder = MeshBuilder()
    box(builder, (0.0, 0.0, PILLAR_SIZE[2] / 2), PILLAR_SIZE, bottom=False)
    x0 = -PILLAR_SPACING * (PILLARS - 1) / 2
    obj = mesh_object("Pillars", builder, make_material("Pillars", STONE), location=(x0, PILLAR_Y, 0.0))
    array = obj.modifiers.new("Array", 'ARRAY')
    array.count = PILLARS
    array.use_relative_offset = False
    array.use_constant_offset = True
    array.constant_offset_displace = (PILLAR_SPACING, 0.0, 0.0)
    array.offset_u = 1.0 / PILLARS  # copy k's UVs move by k / PILLARS (every UV layer)
    array.show_viewport = array.show_render = True
    return obj


def squeeze_pillar_lightmap(obj):
    """Lightmap Pack filled [0, 1]^2 for one pillar; the Array repeats it PILLARS times, each copy
    offset_u further: squeeze it into [0, 1/PILLARS] with a gutter so the copies sit side by side."""
    layer = obj.data.uv_layers["Lightmap"]
    uv = np.empty(len(layer.data) * 2)
    layer.data.foreach_get("uv", uv)
    uv = uv.reshape(-1, 2)
    uv[:, 0] = (PILLAR_GUTTER + uv[:, 0] * (1.0 - 2.0 * PILLAR_GUTTER)) / PILLARS
    layer.data.foreach_set("uv", uv.ravel())
    obj.data.update()


def build_beam():
    builder = MeshBuilder()
    span = 2 * HALF_X + WALL_THICKNESS  # its ends go halfway into the side walls
    box(builder, (0.0, PILLAR_Y, PILLAR_SIZE[2] + BEAM_HEIGHT / 2), (span, 0.35, BEAM_HEIGHT))
    return mesh_object("Beam", builder, make_material("Beam", BEAM_WOOD))


def build_boulder():
    """A cube (connected, 8 vertices) pushed about a little, smooth shaded, with a Subdivision
    Surface modifier: viewport level 1, render level 3."""
    mesh = box_mesh("Boulder", 0.9, 0.7, 0.6)
    rng = random.Random(SEED)
    for v in mesh.vertices:
        v.co = v.co + Vector((rng.uniform(-0.08, 0.08), rng.uniform(-0.08, 0.08), rng.uniform(-0.05, 0.05)))
    mesh.polygons.foreach_set("use_smooth", [True] * len(mesh.polygons))
    mesh.update()
    mesh.materials.append(make_material("Boulder", STONE))
    obj = link("Boulder", mesh, location=(2.7, -1.8, -0.08), rot_z_deg=25.0)
    subsurf = obj.modifiers.new("Subdivision", 'SUBSURF')
    subsurf.levels = 1
    subsurf.render_levels = 3
    subsurf.uv_smooth = 'PRESERVE_BOUNDARIES'
    return obj


def build_handrail():
    """A Bezier curve 0.9 m up along the west wall, bevelled round and capped, ends in the wall."""
    curve = bpy.data.curves.new("Handrail", 'CURVE')
    curve.dimensions = '3D'
    curve.resolution_u = 12
    curve.bevel_mode = 'ROUND'
    curve.bevel_depth = 0.025
    curve.bevel_resolution = 2
    curve.use_fill_caps = True
    spline = curve.splines.new('BEZIER')
    x_wall, x_rail, z = -HALF_X - 0.05, -HALF_X + 0.12, 0.9
    # (point, left handle, right handle): a straight run 12 cm off the wall, bent into it at both ends.
    points = [((x_wall, -2.3), (x_wall - 0.1, -2.3), (x_wall + 0.1, -2.3)),
              ((x_rail, -2.05), (x_rail, -2.15), (x_rail, -1.9)),
              ((x_rail, 1.55), (x_rail, 1.4), (x_rail, 1.65)),
              ((x_wall, 1.8), (x_wall + 0.1, 1.8), (x_wall - 0.1, 1.8))]
    spline.bezier_points.add(len(points) - 1)
    for bp, (co, left, right) in zip(spline.bezier_points, points):
        bp.handle_left_type = bp.handle_right_type = 'FREE'
        bp.co, bp.handle_left, bp.handle_right = (*co, z), (*left, z), (*right, z)
    curve.materials.append(make_material("Handrail", RAIL))
    return link("Handrail", curve)


def leaf_cards(builder, rng, centre, radius):
    """LEAF_CARDS square cards, each with the whole atlas on it (twig at v = 0), fanned out of the
    crown round `centre`: the twig end `radius` / 3 from it, the card pointing outwards."""
    s = LEAF_CARD_SIZE
    for _ in range(LEAF_CARDS):
        z = rng.uniform(-0.35, 0.9)
        phi = rng.uniform(0.0, 2.0 * math.pi)
        out = np.array([math.sqrt(1.0 - z * z) * math.cos(phi), math.sqrt(1.0 - z * z) * math.sin(phi), z])
        spin = rng.uniform(0.0, 2.0 * math.pi)
        helper = np.array([math.cos(spin), math.sin(spin), 0.3])
        across = np.cross(out, helper)
        across /= np.linalg.norm(across)
        base = np.asarray(centre) + out * radius / 3.0
        verts = [base - across * s / 2, base + across * s / 2,
                 base + across * s / 2 + out * s, base - across * s / 2 + out * s]
        builder.add(verts, [(0, 1, 2, 3)], [[(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]], smooth=False)


def build_tree_collection(scene):
    """The "Tree" collection (trunk with three branches, leaf cards), linked to the scene but
    excluded from the view layer: only its instances render."""
    coll = bpy.data.collections.new("Tree")
    scene.collection.children.link(coll)
    rng = random.Random(SEED)
    wood = MeshBuilder()
    trunk = np.array([(0.0, 0.0, 0.0), (0.02, 0.01, 0.6), (0.03, -0.01, 1.2), (0.0, 0.0, 1.7)])
    tube(wood, trunk, [0.11, 0.09, 0.07, 0.05], 8)
    crown = np.array([0.0, 0.0, 2.1])
    for k in range(3):
        a = 2.0 * math.pi * k / 3 + 0.4
        tip = crown + 0.5 * np.array([math.cos(a), math.sin(a), 0.6])
        start = trunk[2] + np.array([0.0, 0.0, 0.15 * k])
        tube(wood, [start, 0.5 * (start + tip) + [0.0, 0.0, 0.1], tip], [0.045, 0.035, 0.02], 6)
    mesh_object("TreeTrunk", wood, make_material("Bark", BARK), collection=coll)
    cards = MeshBuilder()
    leaf_cards(cards, rng, crown, 0.9)
    atlas = packed_image(LEAF_ATLAS, leaf_pixels(), alpha=True)
    mesh_object("TreeLeaves", cards, textured_material("Leaves", atlas, alpha=True), collection=coll)
    bpy.context.view_layer.layer_collection.children[coll.name].exclude = True
    return coll


def add_tree_instances(scene, coll):
    empties = []
    for k, (location, rot_z, scale) in enumerate(TREES, start=1):
        empty = link(f"TreeInstance{k}", None, location=location, rot_z_deg=rot_z)
        empty.scale = (scale, scale, scale)
        empty.instance_type = 'COLLECTION'
        empty.instance_collection = coll
        empty.empty_display_size = 0.5
        empties.append(empty)
    return empties


def build_courtyard(sky_path=None):
    """Reset to an empty factory scene and build the courtyard in it; the sky image is written to
    `sky_path` (default: SKY_FILE here) and loaded from there."""
    sky_path = os.path.abspath(sky_path or os.path.join(HERE, SKY_FILE))
    os.makedirs(os.path.dirname(sky_path), exist_ok=True)
    write_exr(sky_path, sky_pixels(), half=True)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene

    bakeable = [build_floor(), *build_walls(), build_pillars(), build_beam(), build_boulder()]
    for obj in bakeable:
        add_lightmap_uv(obj)
    squeeze_pillar_lightmap(scene.objects["Pillars"])
    build_handrail()
    add_tree_instances(scene, build_tree_collection(scene))

    set_hdri_world(scene, sky_path)
    add_sun(scene, SUN_STRENGTH, SUN_ELEVATION_DEG, SUN_AZIMUTH_DEG)
    add_camera(scene, (0.4, -5.8, 2.3), (0.0, 0.9, 0.7), lens=18.0)
    set_render(scene)
    bpy.context.view_layer.update()  # valid matrix_world for callers that import this
    return scene


def main(argv=None):
    """Build the scene and save it to argv[0] (default: courtyard.blend here), the sky beside it."""
    argv = sys.argv[1:] if argv is None else list(argv)
    output = os.path.abspath(argv[0] if argv else DEFAULT_OUTPUT)
    build_courtyard(os.path.join(os.path.dirname(output), SKY_FILE))
    save(output)
    bpy.data.images["Sky"].filepath = "//" + SKY_FILE  # relative to the saved file
    save(output)
    return output


if __name__ == "__main__":
    main()
