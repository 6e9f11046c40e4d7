"""Build the detp_bake sample scene "window_room": a room lit by the sun and the sky through three
windows, and by six small lamps inside.

The scene of issue 9's quality race with both many lights and a sun: a 7 x 5 x 3 m room (x in
[0, 7], y in [0, 5], z in [0, 3], Z up) whose south wall (y = 0) has three 1.2 x 1.4 m openings
(sill at 0.9 m) with nothing in them.  The sun (strength 4, 35 degrees above the horizon, from the
south-south-west) throws three bright patches on the floor through them, and a blue sky (world
colour (0.35, 0.45, 0.6)) shines in.  There is no ground outside: whatever leaves through a window
is gone, and most of the sun's and the sky's light falls on the outside of the shell (walls and
roof are single faces, so their outside is their back face) and never enters.

Inside, six lamps of three kinds: two 25 W point lights (radius 5 cm) 30 cm off the north wall,
two 80 W spot lights (45 degree cone) pointing down over the table (point and spot lights with
Soft Falloff off), a 30 W disc area light (0.4 m) and a 40 W rectangular area light
(1.0 x 0.3 m) under the ceiling, emitting down.

Eight objects: Floor, Ceiling, WindowWall (a 7 x 3 grid of quads with the three window cells left
out), NorthWall, EastWall, WestWall (warm grey), a Table (top and four legs) and a Shelf against the
west wall, 5 cm off it (boxes without bottoms).  Cycles on the CPU, 4 diffuse bounces.

Every mesh has a texture UV layer "UVMap" (first, active: coordinates in metres) and a "Lightmap"
UV layer made by Lightmap Pack (`make_cornell_box.add_lightmap_uv`, one chart per face).
Deterministic.

Usage (with the bpy module, Blender 4.5 or 5.x):
    python sample_scenes/make_window_room.py [OUTPUT.blend]
"""

import math
import os
import sys

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from make_cornell_box import add_lightmap_uv  # noqa: E402
from make_tree import add_object as make_tree_add_object  # noqa: E402
from make_patio import box, quad_grid  # noqa: E402
from make_tree import (MeshBuilder, generate, add_camera, add_sun, make_material,  # noqa: E402
                       set_render, set_world)

SIZE = (7.0, 5.0, 3.0)
# Columns and rows of the window wall's grid; the cells (column, row) in WINDOWS are openings.
WALL_X = (0.0, 0.8, 2.0, 2.9, 4.1, 5.0, 6.2, 7.0)
WALL_Z = (0.0, 0.9, 2.3, 3.0)
WINDOWS = {(1, 1), (3, 1), (5, 1)}
WHITE = (0.76, 0.75, 0.72)
WARM_GREY = (0.62, 0.58, 0.52)
FLOOR_TILE = (0.55, 0.48, 0.40)
TABLE_WOOD = (0.50, 0.36, 0.25)
SHELF = (0.30, 0.42, 0.50)
SKY = (0.35, 0.45, 0.6)
SUN_STRENGTH = 4.0
SUN_ELEVATION_DEG = 35.0
SUN_AZIMUTH_DEG = -110.0  # light comes from the south-south-west, through the south wall
DEFAULT_OUTPUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "window_room.blend")


def add_object(name, builder, material):
    """A new object from `builder`; its Lightmap layer comes later (add_lightmap_uv)."""
    return make_tree_add_object(name, builder, material, lightmap=False)


def add_light(scene, name, kind, location, energy, rotation=(0.0, 0.0, 0.0), **props):
    light = bpy.data.lights.new(name, type=kind)
    light.energy = energy
    for key, value in props.items():
        setattr(light, key, value)
    obj = bpy.data.objects.new(name, light)
    obj.location = location
    obj.rotation_euler = rotation
    scene.collection.objects.link(obj)
    return obj


def build_window_room():
    """Reset to an empty factory scene and build the room, its windows and its lamps."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    sx, sy, sz = SIZE
    objects = []
    # (name, colour, corner, u edge, v edge, nu, nv) with u x v pointing into the room.
    room = [("Floor", FLOOR_TILE, (0, 0, 0), (sx, 0, 0), (0, sy, 0), 4, 3),
            ("Ceiling", WHITE, (0, 0, sz), (0, sy, 0), (sx, 0, 0), 3, 4),
            ("NorthWall", WHITE, (0, sy, 0), (sx, 0, 0), (0, 0, sz), 4, 2),
            ("EastWall", WHITE, (sx, sy, 0), (0, -sy, 0), (0, 0, sz), 3, 2),
            ("WestWall", WARM_GREY, (0, 0, 0), (0, sy, 0), (0, 0, sz), 3, 2)]
    for name, colour, corner, u, v, nu, nv in room:
        builder = MeshBuilder()
        quad_grid(builder, corner, u, v, nu, nv)
        objects.append(add_object(name, builder, make_material(name, colour)))

    wall = MeshBuilder()
    for i, (x0, x1) in enumerate(zip(WALL_X, WALL_X[1:])):
        for j, (z0, z1) in enumerate(zip(WALL_Z, WALL_Z[1:])):
            if (i, j) not in WINDOWS:  # u = -x, v = +z: the normal points +y, into the room
                quad_grid(wall, (x1, 0.0, z0), (x0 - x1, 0, 0), (0, 0, z1 - z0), 1, 1)
    objects.append(add_object("WindowWall", wall, make_material("WindowWall", WHITE)))

    table = MeshBuilder()
    box(table, (4.2, 3.0, 0.74), (1.6, 0.9, 0.05))  # top
    for x in (3.5, 4.9):
        for y in (2.64, 3.36):
            box(table, (x, y, 0.3575), (0.07, 0.07, 0.715), bottom=False)
    objects.append(add_object("Table", table, make_material("Table", TABLE_WOOD)))
    shelf = MeshBuilder()
    box(shelf, (0.25, 3.2, 0.9), (0.4, 1.6, 1.8), bottom=False)  # 5 cm off the wall
    objects.append(add_object("Shelf", shelf, make_material("Shelf", SHELF)))
    for obj in objects:
        add_lightmap_uv(obj)

    add_sun(scene, SUN_STRENGTH, SUN_ELEVATION_DEG, SUN_AZIMUTH_DEG)
    set_world(scene, SKY, 1.0)
    # Soft Falloff off: Cycles then treats a point or spot light with a radius as the sphere light
    # detp_bake exports (with it on, Cycles is d²/(d²+r²) dimmer within a few radii; README).
    for k, x in enumerate((1.6, 5.4)):
        add_light(scene, f"WallLamp{k}", 'POINT', (x, sy - 0.3, 2.0), 25.0, shadow_soft_size=0.05,
                  use_soft_falloff=False)
    for k, x in enumerate((3.7, 4.7)):
        add_light(scene, f"Spot{k}", 'SPOT', (x, 3.0, sz - 0.3), 80.0, spot_size=math.radians(45.0),
                  spot_blend=0.2, shadow_soft_size=0.05, use_soft_falloff=False)  # spots point down (-Z)
    add_light(scene, "DiscPanel", 'AREA', (1.5, 1.5, sz - 0.02), 30.0, shape='DISK', size=0.4)
    add_light(scene, "StripPanel", 'AREA', (5.8, 4.2, sz - 0.02), 40.0, shape='RECTANGLE', size=1.0, size_y=0.3)

    add_camera(scene, (6.6, 0.5, 1.8), (1.0, 4.5, 0.8), lens=16.0)
    set_render(scene)
    bpy.context.view_layer.update()  # valid matrix_world for callers that import this
    return scene


def main(argv=None):
    """Build the scene and save it to argv[0] (default: window_room.blend here)."""
    return generate(build_window_room, DEFAULT_OUTPUT, argv)


if __name__ == "__main__":
    main()
