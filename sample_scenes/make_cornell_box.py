"""Build the detp_bake sample scene: an open-front Cornell box.

The scene is a reference case for baking and checking diffuse irradiance
lightmaps: a 2 x 2 x 2 m room (x, y in [-1, 1], z in [0, 2], Z up) whose
front (y = -1) is open so light escapes (used for energy-balance tests),
a red left wall, a green right wall, white floor/ceiling/back wall, the
classic short and tall boxes, and a single 60 W square area light under the
ceiling.  The world is black, so all light comes from that area light.

Every mesh has a texture UV layer "UVMap" (first, active for render) and a
"Lightmap" UV layer made with Blender's Lightmap Pack.  The boxes keep their
placement in the object transform (location + Z rotation, unit scale), the
room meshes are modelled in world space.  The script is deterministic.

Usage (with the bpy module, Blender 4.5 or 5.x):
    python sample_scenes/make_cornell_box.py [OUTPUT.blend]
"""

import math
import os
import sys

import bpy

WHITE = (0.73, 0.73, 0.73)
RED = (0.63, 0.065, 0.05)
GREEN = (0.14, 0.45, 0.09)
GRID = 4  # quads per side on walls, floor and ceiling
# Lightmap Pack "Margin" (UI value, at most 1.0): the operator uses
# int(100 / margin) as divisor, so 1.0 leaves 2/100 of the UV space between
# charts, i.e. 2.56 texels at 128 x 128.
LIGHTMAP_MARGIN = 1.0
DEFAULT_OUTPUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "cornell_box.blend")


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


def grid_mesh(name, corner, u_edge, v_edge, n):
    """n x n quad grid spanning corner + s*u_edge + t*v_edge; normal = u x v."""
    verts = [tuple(corner[k] + u_edge[k] * i / n + v_edge[k] * j / n for k in range(3))
             for j in range(n + 1) for i in range(n + 1)]
    faces = [(j * (n + 1) + i, j * (n + 1) + i + 1,
              (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i)
             for j in range(n) for i in range(n)]
    uvs = [(i / n, j / n) for j in range(n + 1) for i in range(n + 1)]
    return build_mesh(name, verts, faces, lambda v: uvs[v])


def box_mesh(name, sx, sy, sz):
    """Closed box, base centred on the origin (z from 0 to sz), outward normals."""
    verts = [((i & 1) * sx - sx / 2, (i >> 1 & 1) * sy - sy / 2, (i >> 2 & 1) * sz)
             for i in range(8)]
    faces = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4),
             (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    square = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
    return build_mesh(name, verts, faces, None, square)


def build_mesh(name, verts, faces, vert_uv=None, face_uvs=None):
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], faces)
    me.polygons.foreach_set("use_smooth", [False] * len(me.polygons))  # flat shading
    uv = me.uv_layers.new(name="UVMap")
    for poly in me.polygons:
        for k, li in enumerate(poly.loop_indices):
            uv.data[li].uv = vert_uv(me.loops[li].vertex_index) if vert_uv else face_uvs[k]
    me.update()
    me.validate()
    return me


def add_object(name, mesh, material, location=(0, 0, 0), rot_z_deg=0.0):
    mesh.materials.append(material)
    obj = bpy.data.objects.new(name, mesh)
    obj.location = location
    obj.rotation_euler = (0.0, 0.0, math.radians(rot_z_deg))
    bpy.context.scene.collection.objects.link(obj)
    return obj


def add_lightmap_uv(obj):
    """Add a "Lightmap" UV layer filled by Lightmap Pack; keep "UVMap" active."""
    me = obj.data
    me.uv_layers.active = me.uv_layers.new(name="Lightmap")  # operator writes the active layer
    view_layer = bpy.context.view_layer
    for other in view_layer.objects:
        other.select_set(other is obj)
    view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode='EDIT')
    bpy.ops.mesh.select_all(action='SELECT')
    bpy.ops.uv.lightmap_pack(PREF_CONTEXT='ALL_FACES', PREF_PACK_IN_ONE=True,
                             PREF_NEW_UVLAYER=False, PREF_MARGIN_DIV=LIGHTMAP_MARGIN)
    bpy.ops.object.mode_set(mode='OBJECT')
    texture_uv = me.uv_layers["UVMap"]  # look up again: edit mode rebuilt the layers
    me.uv_layers.active = texture_uv
    texture_uv.active_render = True
    obj.select_set(False)


def build_cornell_box():
    """Reset to an empty factory scene and build the Cornell box in it."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene

    white = make_material("White", WHITE)
    red = make_material("Red", RED)
    green = make_material("Green", GREEN)

    # Room: (corner, u edge, v edge) chosen so that u x v points into the room.
    room = [
        ("Floor", white, (-1, -1, 0), (2, 0, 0), (0, 2, 0)),     # +Z
        ("Ceiling", white, (-1, -1, 2), (0, 2, 0), (2, 0, 0)),   # -Z
        ("BackWall", white, (-1, 1, 0), (2, 0, 0), (0, 0, 2)),   # -Y
        ("LeftWall", red, (-1, -1, 0), (0, 2, 0), (0, 0, 2)),    # +X
        ("RightWall", green, (1, -1, 0), (0, 0, 2), (0, 2, 0)),  # -X
    ]
    objects = [add_object(name, grid_mesh(name, c, u, v, GRID), mat)
               for name, mat, c, u, v in room]
    objects.append(add_object("ShortBox", box_mesh("ShortBox", 0.6, 0.6, 0.6), white,
                              (0.33, -0.25, 0.0), -17.0))
    objects.append(add_object("TallBox", box_mesh("TallBox", 0.6, 0.6, 1.2), white,
                              (-0.33, 0.3, 0.0), 17.0))
    for obj in objects:
        add_lightmap_uv(obj)

    # Single square area light under the ceiling, emitting down (-Z, default).
    light = bpy.data.lights.new("CeilingLight", type='AREA')
    light.shape = 'SQUARE'
    light.size = 0.5
    light.energy = 60.0
    light.color = (1.0, 1.0, 1.0)
    light_obj = bpy.data.objects.new("CeilingLight", light)
    light_obj.location = (0.0, 0.0, 1.98)
    scene.collection.objects.link(light_obj)

    # Black world: no environment light.
    world = bpy.data.worlds.new("World")
    world.color = (0.0, 0.0, 0.0)
    if world.node_tree is None:  # Blender < 5.0
        world.use_nodes = True
    background = next(n for n in world.node_tree.nodes if n.type == 'BACKGROUND')
    background.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    background.inputs["Strength"].default_value = 0.0
    scene.world = world

    # Camera in front of the open side, looking +Y into the box.
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.lens = 50.0
    cam.location = (0.0, -3.9, 1.0)
    cam.rotation_euler = (math.radians(90.0), 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam

    scene.render.engine = 'CYCLES'
    scene.cycles.device = 'CPU'
    scene.cycles.samples = 64
    scene.cycles.diffuse_bounces = 4
    scene.render.resolution_x = scene.render.resolution_y = 512
    bpy.context.view_layer.update()  # valid matrix_world for callers that import this
    return scene


def main(argv=None):
    """Build the scene and save it to argv[0] (default: cornell_box.blend here)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    output = os.path.abspath(argv[0] if argv else DEFAULT_OUTPUT)
    build_cornell_box()
    bpy.context.preferences.filepaths.save_version = 0  # no OUTPUT.blend1 backup
    save_props = bpy.ops.wm.save_as_mainfile.get_rna_type().properties
    kwargs = {"compress": True} if "compress" in save_props else {}
    bpy.ops.wm.save_as_mainfile(filepath=output, **kwargs)
    print("Saved", output)
    return output


if __name__ == "__main__":
    main()
