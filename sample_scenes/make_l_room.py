"""Build the detp_bake sample scene "l_room": a closed L-shaped room lit by a point and an area light.

The scene of issue 9's quality race (Cycles' bake + OIDN against ours): a room whose two wings
light each other only by bounced light round the inner corner, so most of what a texel receives in
the far ends is indirect.  The floor plan is the L (0,0)-(6,0)-(6,3)-(3,3)-(3,6)-(0,6) in metres
(x east, y north, Z up), 2.7 m high, closed on every side (no light escapes; the world is black).

Nine objects: the floor and the ceiling (each the L as three 3 x 3 m squares of 2 x 2 quads), six
walls, one per edge of the L (SouthWall, EastWall, the two walls of the inner corner InnerNorth
and InnerEast, NorthWall, WestWall; a terracotta west wall for colour bleeding, the others white),
and a cabinet (a box without a bottom, rotated 20 degrees) standing in the corner square where the
wings meet, which casts contact shadows.  Lights: a 60 W point light (radius 5 cm, Soft Falloff
off) in the east wing and a 1.2 x 0.6 m, 90 W rectangular area light under the ceiling of the
north wing, emitting down.  Cycles on the CPU, 4 diffuse bounces.

Every mesh has a texture UV layer "UVMap" (first, active: coordinates in metres) and a "Lightmap"
UV layer made by Lightmap Pack (`make_cornell_box.add_lightmap_uv`, one chart per face).
Deterministic.

Usage (with the bpy module, Blender 4.5 or 5.x):
    python sample_scenes/make_l_room.py [OUTPUT.blend]
"""

import math
import os
import sys

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from make_cornell_box import add_lightmap_uv, add_object as cornell_add_object  # noqa: E402
from make_patio import box, quad_grid  # noqa: E402
from make_tree import (MeshBuilder, generate, add_camera, make_material,  # noqa: E402
                       set_render, set_world)

HEIGHT = 2.7
WING = 3.0  # the L is three WING x WING squares
WHITE = (0.75, 0.74, 0.72)
CEILING = (0.78, 0.78, 0.78)
FLOOR_WOOD = (0.52, 0.40, 0.30)
TERRACOTTA = (0.68, 0.36, 0.26)
CABINET = (0.35, 0.45, 0.60)
POINT_POWER = 60.0
AREA_POWER = 90.0
DEFAULT_OUTPUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "l_room.blend")
# The L as (x, y) corners, anticlockwise seen from above: the room lies on the left of each edge.
PLAN = [(0.0, 0.0), (6.0, 0.0), (6.0, 3.0), (3.0, 3.0), (3.0, 6.0), (0.0, 6.0)]
WALLS = ["SouthWall", "EastWall", "InnerNorth", "InnerEast", "NorthWall", "WestWall"]
SQUARES = [(0.0, 0.0), (3.0, 0.0), (0.0, 3.0)]  # lower-left corners of the floor's squares


def add_object(name, builder, material, location=(0.0, 0.0, 0.0), rot_z_deg=0.0):
    """A new object from `builder`, placed; its Lightmap layer comes later (add_lightmap_uv)."""
    return cornell_add_object(name, builder.mesh(name), material, location, rot_z_deg)


def build_l_room():
    """Reset to an empty factory scene and build the L-shaped room."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    objects = []

    floor, ceiling = MeshBuilder(), MeshBuilder()
    for x, y in SQUARES:
        quad_grid(floor, (x, y, 0.0), (WING, 0, 0), (0, WING, 0), 2, 2)  # faces +Z
        quad_grid(ceiling, (x, y, HEIGHT), (0, WING, 0), (WING, 0, 0), 2, 2)  # faces -Z
    objects.append(add_object("Floor", floor, make_material("Floor", FLOOR_WOOD)))
    objects.append(add_object("Ceiling", ceiling, make_material("Ceiling", CEILING)))

    for k, name in enumerate(WALLS):
        (x0, y0), (x1, y1) = PLAN[k], PLAN[(k + 1) % len(PLAN)]
        length = math.hypot(x1 - x0, y1 - y0)
        # u back along the edge, v up: u x v points to the left of the edge, into the room.
        wall = MeshBuilder()
        quad_grid(wall, (x1, y1, 0.0), (x0 - x1, y0 - y1, 0.0), (0, 0, HEIGHT), round(length / 1.5), 2)
        colour = TERRACOTTA if name == "WestWall" else WHITE
        objects.append(add_object(name, wall, make_material(name, colour)))

    cabinet = MeshBuilder()
    box(cabinet, (0.0, 0.0, 0.6), (0.9, 0.5, 1.2), bottom=False)
    objects.append(add_object("Cabinet", cabinet, make_material("Cabinet", CABINET), (2.1, 2.2, 0.0), 20.0))
    for obj in objects:
        add_lightmap_uv(obj)

    bulb = bpy.data.lights.new("Bulb", type='POINT')
    bulb.energy = POINT_POWER
    bulb.shadow_soft_size = 0.05
    bulb.use_soft_falloff = False  # a true sphere light, as detp_bake exports it (README: units)
    bulb_obj = bpy.data.objects.new("Bulb", bulb)
    bulb_obj.location = (5.0, 1.2, 2.1)
    scene.collection.objects.link(bulb_obj)

    panel = bpy.data.lights.new("Panel", type='AREA')
    panel.shape = 'RECTANGLE'
    panel.size, panel.size_y = 1.2, 0.6
    panel.energy = AREA_POWER
    panel_obj = bpy.data.objects.new("Panel", panel)
    panel_obj.location = (1.5, 4.6, HEIGHT - 0.02)  # emits down (-Z, the default)
    scene.collection.objects.link(panel_obj)
    set_world(scene, (0.0, 0.0, 0.0), 0.0)

    add_camera(scene, (5.6, 0.4, 1.7), (1.0, 5.0, 0.9), lens=16.0)
    set_render(scene)
    bpy.context.view_layer.update()  # valid matrix_world for callers that import this
    return scene


def main(argv=None):
    """Build the scene and save it to argv[0] (default: l_room.blend here)."""
    return generate(build_l_room, DEFAULT_OUTPUT, argv)


if __name__ == "__main__":
    main()
