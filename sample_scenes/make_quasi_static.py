"""Build the detp_bake sample scene "quasi_static": a closed room in which one small box moves.

The scene for the hybrid estimator of García et al. (CEIG 2005): a quasi-static scene is a large
static set plus a few small moving objects over a frame range, so the static objects' discs can be
indexed once and every frame's photons splatted through that index, while only the moving
objects' texels are estimated afresh.  Here: a closed 4 x 4 x 2.6 m room (x, y in [-2, 2], z in
[0, 2.6], Z up) with a wooden floor, white ceiling, front and right walls, a terracotta left wall
and a blue back wall, a table in the middle, and a 0.3 m box "Mover" that slides once round the
table on the floor over frames 1..24 (a location keyframe on every frame, on a circle of radius
1.3 m: frame 25 would be frame 1 again).  Lit by one 80 W square area light under the ceiling;
the world is black.  Nothing but the Mover is animated.

Every mesh has a texture UV layer "UVMap" (first, active: coordinates in metres) and a "Lightmap"
UV layer made by Lightmap Pack, as in make_cornell_box.py (the meshes are small enough for one chart
per face).  Deterministic.

Usage (with the bpy module, Blender 4.5 or 5.x):
    python sample_scenes/make_quasi_static.py [OUTPUT.blend]
"""

import math
import os
import sys

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from make_cornell_box import add_lightmap_uv  # noqa: E402
from make_patio import box, quad_grid  # noqa: E402
from make_tree import (MeshBuilder, generate, add_camera, make_material,  # noqa: E402
                       set_render, set_world)

HALF, HEIGHT = 2.0, 2.6
GRID = 6  # quads per side on walls, floor and ceiling
FRAME_START, FRAME_END = 1, 24
PATH_RADIUS = 1.3
MOVER_SIZE = 0.3
LIGHT_POWER = 80.0
WHITE = (0.72, 0.72, 0.70)
FLOOR_WOOD = (0.50, 0.38, 0.28)
TERRACOTTA = (0.70, 0.34, 0.25)
BLUE = (0.25, 0.40, 0.62)
TABLE_WOOD = (0.55, 0.43, 0.32)
YELLOW = (0.78, 0.62, 0.22)
# Lightmap Pack "Margin" as in make_cornell_box.py: 2/100 of the UV space between charts.
DEFAULT_OUTPUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "quasi_static.blend")


def add_object(name, builder, material, location=(0.0, 0.0, 0.0)):
    mesh = builder.mesh(name)
    mesh.materials.append(material)
    obj = bpy.data.objects.new(name, mesh)
    obj.location = location
    bpy.context.scene.collection.objects.link(obj)
    return obj


def mover_location(frame):
    """Where the Mover stands at `frame`: once round the table, anticlockwise, over 24 frames."""
    angle = 2.0 * math.pi * (frame - FRAME_START) / (FRAME_END - FRAME_START + 1)
    return (PATH_RADIUS * math.cos(angle), PATH_RADIUS * math.sin(angle), 0.0)


def build_quasi_static():
    """Reset to an empty factory scene and build the room, the table and the moving box."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    h, z = HALF, HEIGHT
    # (name, colour, corner, u edge, v edge) with u x v pointing into the room.
    room = [("Floor", FLOOR_WOOD, (-h, -h, 0), (2 * h, 0, 0), (0, 2 * h, 0)),
            ("Ceiling", WHITE, (-h, -h, z), (0, 2 * h, 0), (2 * h, 0, 0)),
            ("BackWall", BLUE, (-h, h, 0), (2 * h, 0, 0), (0, 0, z)),
            ("FrontWall", WHITE, (h, -h, 0), (-2 * h, 0, 0), (0, 0, z)),
            ("LeftWall", TERRACOTTA, (-h, -h, 0), (0, 2 * h, 0), (0, 0, z)),
            ("RightWall", WHITE, (h, h, 0), (0, -2 * h, 0), (0, 0, z))]
    objects = []
    for name, colour, corner, u, v in room:
        builder = MeshBuilder()
        quad_grid(builder, corner, u, v, GRID, GRID)
        objects.append(add_object(name, builder, make_material(name, colour)))

    table = MeshBuilder()
    box(table, (0.0, 0.0, 0.72), (1.0, 0.7, 0.06))  # top
    for x in (-0.44, 0.44):
        for y in (-0.29, 0.29):
            box(table, (x, y, 0.345), (0.06, 0.06, 0.69), bottom=False)
    objects.append(add_object("Table", table, make_material("Table", TABLE_WOOD)))

    mover_mesh = MeshBuilder()
    box(mover_mesh, (0.0, 0.0, MOVER_SIZE / 2), (MOVER_SIZE,) * 3)
    mover = add_object("Mover", mover_mesh, make_material("Mover", YELLOW), mover_location(FRAME_START))
    objects.append(mover)
    for obj in objects:
        add_lightmap_uv(obj)
    for frame in range(FRAME_START, FRAME_END + 1):
        mover.location = mover_location(frame)
        mover.keyframe_insert("location", frame=frame)

    light = bpy.data.lights.new("CeilingLight", type='AREA')
    light.shape = 'SQUARE'
    light.size = 1.0
    light.energy = LIGHT_POWER
    light_obj = bpy.data.objects.new("CeilingLight", light)
    light_obj.location = (0.0, 0.0, HEIGHT - 0.02)  # emits down (-Z, the default)
    scene.collection.objects.link(light_obj)
    set_world(scene, (0.0, 0.0, 0.0), 0.0)

    add_camera(scene, (1.85, -1.85, 1.7), (-0.5, 0.5, 0.5), lens=18.0)
    set_render(scene)
    scene.frame_start, scene.frame_end = FRAME_START, FRAME_END
    scene.render.fps = 24
    scene.frame_set(FRAME_START)
    bpy.context.view_layer.update()  # valid matrix_world for callers that import this
    return scene


def main(argv=None):
    """Build the scene and save it to argv[0] (default: quasi_static.blend here)."""
    return generate(build_quasi_static, DEFAULT_OUTPUT, argv)


if __name__ == "__main__":
    main()
