"""Build the downloaded-content test scenes (sample_scenes/downloaded/) from Khronos' glTF sample
models, as a user would: Blender's own glTF importer, then only what a bake needs added (a floor
or a room to catch the light, a sun and a sky, a camera) and every addition listed in
sample_scenes/downloaded/README.md.

The models are not in this repository (tens of MB of textures); the .blend files made from them
are, with every image shrunk (base colour and emission to at most COLOUR_PX, the rest to OTHER_PX)
and packed, saved compressed. Nothing in the geometry is changed or decimated. Three scenes:

- dish_and_vases: IridescentDishWithOlives (its camera; the glass cover hidden) and
  GlassVaseFlowers (alpha-masked leaves; its two flower objects already share one mesh) plus two
  linked copies of the whole vase and one collection instance of it, on a table.
- lamp: LightsPunctualLamp (five point lights from KHR_lights_punctual, an emissive shade)
  in the corner of a small room with a window.
- living_room: GlamVelvetSofa (its own sun), SheenChair (two UV maps) and a hidden linked copy
  of it, StainedGlassLamp (alpha-masked grill and glass) on a floor with two walls; the chair's
  and the sofa's unused variant materials added as unused material slots.

Usage (with the bpy module, Blender 4.5 or 5.x):
    python sample_scenes/make_downloaded.py MODELS [SCENE ...]
MODELS is the Models/ folder of a KhronosGroup/glTF-Sample-Assets checkout (the .blend files
here were made from commit 02d48689ce60c8799207f180ae324997e974c956 of its mirror).
"""

import math
import os
import sys

import bpy
from mathutils import Vector

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from make_cornell_box import make_material  # noqa: E402
from make_tree import add_camera, add_sun, save, set_render, set_world  # noqa: E402

OUT_DIR = os.path.join(HERE, "downloaded")
COLOUR_PX = 128
OTHER_PX = 64
SKY = (0.35, 0.45, 0.6)
WOOD = (0.45, 0.32, 0.22)
PLASTER = (0.70, 0.68, 0.64)
FLOOR = (0.40, 0.36, 0.30)


# --------------------------------------------------------------------------- importing

def import_model(models, name, location=(0.0, 0.0, 0.0), rot_z_deg=0.0, scale=1.0, on=0.0):
    """Import Models/<name>/glTF/<name>.gltf into a collection of its own; move its top-level
    objects so the model stands on z = `on`, centred on `location` (x, y), turned `rot_z_deg`."""
    coll = bpy.data.collections.new(name)
    bpy.context.scene.collection.children.link(coll)
    bpy.context.view_layer.active_layer_collection = bpy.context.view_layer.layer_collection.children[name]
    before = set(bpy.data.objects)
    bpy.ops.import_scene.gltf(filepath=os.path.join(models, name, "glTF", name + ".gltf"))
    new = [o for o in bpy.data.objects if o not in before]
    tops = [o for o in new if o.parent is None]
    pivot = bpy.data.objects.new(name + "_place", None)
    coll.objects.link(pivot)
    for obj in tops:
        obj.parent = pivot
    pivot.scale = (scale,) * 3
    pivot.rotation_euler = (0.0, 0.0, math.radians(rot_z_deg))
    bpy.context.view_layer.update()
    lo, hi = _bounds([o for o in new if o.type == 'MESH'])
    centre = (lo + hi) / 2
    pivot.location = (location[0] - centre.x, location[1] - centre.y, on - lo.z)
    bpy.context.view_layer.update()
    for obj in tops:  # keep the world transform, drop the helper
        world = obj.matrix_world.copy()
        obj.parent = None
        obj.matrix_world = world
    bpy.data.objects.remove(pivot)
    bpy.context.view_layer.active_layer_collection = bpy.context.view_layer.layer_collection
    return coll, new


def _bounds(objects):
    corners = [o.matrix_world @ Vector(c) for o in objects for c in o.bound_box]
    lo = Vector([min(c[i] for c in corners) for i in range(3)])
    hi = Vector([max(c[i] for c in corners) for i in range(3)])
    return lo, hi


def shrink_images():
    """Every image to at most COLOUR_PX (sRGB: base colour, emission) or OTHER_PX (data: normal,
    occlusion-roughness-metal, transmission), kept in proportion, and packed into the .blend."""
    for img in bpy.data.images:
        w, h = img.size
        if w == 0:
            continue
        limit = COLOUR_PX if img.colorspace_settings.name == 'sRGB' else OTHER_PX
        f = min(1.0, limit / max(w, h))
        img.scale(max(1, round(w * f)), max(1, round(h * f)))
        img.file_format = 'PNG'
        img.filepath_raw = "//" + os.path.splitext(img.name)[0] + ".png"
        img.pack()


def add_unused_slot(obj, material_name):
    """Append `material_name` as a material slot that no face uses (as a variant left behind)."""
    obj.data.materials.append(bpy.data.materials[material_name])


# --------------------------------------------------------------------------- additions

def box_object(name, size, location, color, collection=None):
    """A closed box (size x, y, z; base at location) with a plain material and a "UVMap" layer."""
    mesh = bpy.data.meshes.new(name)
    sx, sy, sz = size
    verts = [((i & 1) * sx - sx / 2, (i >> 1 & 1) * sy - sy / 2, (i >> 2 & 1) * sz) for i in range(8)]
    faces = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    mesh.from_pydata(verts, [], faces)
    uv = mesh.uv_layers.new(name="UVMap")
    for loop in mesh.loops:
        v = verts[loop.vertex_index]
        uv.data[loop.index].uv = (v[0] + v[2], v[1] + v[2])
    mesh.materials.append(make_material(name, color))
    obj = bpy.data.objects.new(name, mesh)
    obj.location = location
    (collection or bpy.context.scene.collection).objects.link(obj)
    return obj


def finish(scene, sun=(3.0, 40.0, 30.0)):
    """Sky, sun (strength, elevation, azimuth), Cycles settings, images shrunk and packed."""
    set_world(scene, SKY, 1.0)
    add_sun(scene, *sun)
    set_render(scene, (640, 480))
    shrink_images()
    bpy.context.view_layer.update()


# --------------------------------------------------------------------------- scenes

def build_dish_and_vases(models):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    box_object("Table", (1.2, 0.7, 0.04), (0.0, 0.0, 0.72), WOOD)
    _, dish = import_model(models, "IridescentDishWithOlives", (0.15, 0.0), on=0.76)
    cover = next(o for o in dish if o.name.startswith("glassCover") and o.type == 'MESH')
    cover.hide_set(True)
    cover.hide_render = True
    vase_coll, vase = import_model(models, "GlassVaseFlowers", (-0.25, 0.1), on=0.76)
    for k, (x, y) in enumerate(((-0.4, -0.15), (0.42, 0.2))):
        for src in vase:
            copy = src.copy()  # linked: the same mesh and materials
            copy.name = f"{src.name}_copy{k + 1}"
            copy.location = src.location + Vector((x + 0.25, y - 0.1, 0.0))
            vase_coll.objects.link(copy)
    inst = bpy.data.objects.new("VaseInstance", None)
    inst.instance_type = 'COLLECTION'
    inst.instance_collection = vase_coll
    inst.location = (0.0, 0.35, 0.0)
    scene.collection.objects.link(inst)
    scene.camera = next(o for o in dish if o.type == 'CAMERA')
    add_camera(scene, (1.1, -1.2, 1.45), (0.0, 0.0, 0.8), lens=30.0).name = "Overview"
    finish(scene, (3.0, 45.0, -60.0))
    return scene


def build_lamp(models):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    room = bpy.data.collections.new("Room")
    scene.collection.children.link(room)
    box_object("Floor", (3.0, 3.0, 0.05), (0.0, 0.0, -0.05), FLOOR, room)
    box_object("WallBack", (3.0, 0.1, 2.4), (0.0, 1.55, -0.05), PLASTER, room)
    box_object("WallLeft", (0.1, 1.0, 2.4), (-1.55, 1.0, -0.05), PLASTER, room)
    box_object("WallLeftFront", (0.1, 1.0, 2.4), (-1.55, -1.0, -0.05), PLASTER, room)
    box_object("Sill", (0.1, 1.0, 0.8), (-1.55, 0.0, -0.05), PLASTER, room)
    import_model(models, "LightsPunctualLamp", (0.6, 1.0), rot_z_deg=200.0)
    add_camera(scene, (1.3, -2.2, 1.3), (-0.2, 0.6, 0.4), lens=24.0)
    finish(scene, (3.0, 30.0, 190.0))
    return scene


def build_living_room(models):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    room = bpy.data.collections.new("Room")
    scene.collection.children.link(room)
    box_object("Floor", (5.0, 4.0, 0.05), (0.0, 0.0, -0.05), FLOOR, room)
    box_object("WallBack", (5.0, 0.12, 2.6), (0.0, 2.06, -0.05), PLASTER, room)
    box_object("WallRight", (0.12, 4.0, 2.6), (2.56, 0.0, -0.05), PLASTER, room)
    _, sofa = import_model(models, "GlamVelvetSofa", (0.0, 1.4))
    _, chair = import_model(models, "SheenChair", (1.6, 0.3), rot_z_deg=120.0)
    for src in chair:  # a hidden linked copy: the same meshes and materials
        spare = src.copy()
        spare.name = src.name + "_spare"
        spare.location = src.location + Vector((-3.4, -1.5, 0.0))
        src.users_collection[0].objects.link(spare)
        spare.hide_set(True)
        spare.hide_render = True
    import_model(models, "StainedGlassLamp", (1.9, 1.5), scale=1.0)
    fabric = next(o for o in chair if o.name.startswith("SheenChair_fabric"))
    add_unused_slot(fabric, "fabric Mystere Peacock Velvet")
    sofa_fabric = next(o for o in sofa if o.name.startswith("GlamVelvetSofa_fabric"))
    for variant in ("GlamVelvetSofa_fabric_gray", "GlamVelvetSofa_fabric_champagne"):
        add_unused_slot(sofa_fabric, variant)
    add_camera(scene, (-1.6, -2.6, 1.7), (0.6, 1.0, 0.5), lens=22.0)
    finish(scene, (3.0, 35.0, -50.0))
    return scene


SCENES = {"dish_and_vases": build_dish_and_vases, "lamp": build_lamp, "living_room": build_living_room}


def main(argv=None):
    """Build the named scenes (default all) from MODELS and save each to downloaded/<scene>.blend."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv:
        sys.exit(__doc__)
    models, names = os.path.abspath(argv[0]), argv[1:] or list(SCENES)
    os.makedirs(OUT_DIR, exist_ok=True)
    for name in names:
        SCENES[name](models)
        save(os.path.join(OUT_DIR, name + ".blend"))


if __name__ == "__main__":
    main()
