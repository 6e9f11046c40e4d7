"""The courtyard sample scene (sample_scenes/make_courtyard.py, issue 8): the saved file is what the
generator builds, its features are there as a user would have made them (textured floor, Array and
Subdivision Surface modifiers, a bevelled curve, an instanced tree with alpha-cut leaves, an HDRI
world and a sun), and the exporter takes it with its instances."""
import math
import sys

import numpy as np
import pytest

from blender_helpers import export
from conftest import ROOT

sys.path.insert(0, str(ROOT / "sample_scenes"))
import make_courtyard  # noqa: E402
from detp_bake.lightmap import texels  # noqa: E402
try:  # the exporter's render evaluation (what F12 renders), wherever it lives
    from detp_bake.blender.evaluation import render_evaluation  # noqa: E402
except ImportError:
    from detp_bake.blender_eval import render_evaluation  # noqa: E402

SAVED = ROOT / "sample_scenes" / "courtyard.blend"
BAKEABLE = {"Floor", "NorthWall", "WestWall", "EastWall", "Pillars", "Beam", "Boulder"}
GEOMETRY = ("MESH", "CURVE", "SURFACE", "FONT", "META")
MODIFIER_SETTINGS = {
    "ARRAY": ("count", "fit_type", "use_relative_offset", "use_constant_offset", "constant_offset_displace",
              "use_merge_vertices", "offset_u", "offset_v"),
    "SUBSURF": ("levels", "render_levels", "subdivision_type", "uv_smooth", "boundary_smooth"),
}


def _open(bpy):
    bpy.ops.wm.open_mainfile(filepath=str(SAVED))
    return bpy.context.scene


def _value(v):
    if isinstance(v, (bool, int, str)):
        return v
    if isinstance(v, float):
        return round(v, 6)
    return tuple(round(float(x), 6) for x in v)


def _array(collection, attr, width):
    out = np.empty(len(collection) * width)
    collection.foreach_get(attr, out)
    return out.reshape(-1, width)


def _render(bpy, fn):
    scene = bpy.context.scene
    return render_evaluation(scene, bpy.context.view_layer, fn)


def _render_geometry(depsgraph):
    """What F12 renders: {(instancer or None, object, type): triangles}, and every bake target's
    evaluated "Lightmap" UVs."""
    tris, lightmaps, seen = {}, {}, {}
    for inst in depsgraph.object_instances:
        ob = inst.object
        if ob.type not in GEOMETRY:
            continue
        name = ob.original.name
        if (name, ob.type) not in seen:
            me = ob.to_mesh()
            me.calc_loop_triangles()
            seen[name, ob.type] = len(me.loop_triangles)
            if name in BAKEABLE and not inst.is_instance:
                lightmaps[name] = _array(me.uv_layers["Lightmap"].data, "uv", 2)
            ob.to_mesh_clear()
        parent = inst.parent.original.name if inst.is_instance and inst.parent is not None else None
        key = (parent, name, ob.type)
        tris[key] = tris.get(key, 0) + seen[name, ob.type]
    return tris, lightmaps


def _snapshot(bpy):
    """The things that matter of the open file."""
    data = bpy.data
    snap = {
        "objects": sorted((o.name, o.type, tuple(sorted(c.name for c in o.users_collection)),
                           o.instance_type, o.instance_collection.name if o.instance_collection else None,
                           _value(o.matrix_world.col[3]), _value(o.scale), bool(o.hide_render))
                          for o in data.objects),
        "modifiers": {o.name: [(m.name, m.type, m.show_render, m.show_viewport,
                                tuple(_value(getattr(m, k)) for k in MODIFIER_SETTINGS.get(m.type, ())))
                               for m in o.modifiers] for o in data.objects},
        "materials": {o.name: [s.material.name for s in o.material_slots] for o in data.objects},
        "uv_layers": {m.name: [layer.name for layer in m.uv_layers] for m in data.meshes},
        "vertices": {m.name: _array(m.vertices, "co", 3) for m in data.meshes},
        "lightmaps": {m.name: _array(m.uv_layers["Lightmap"].data, "uv", 2) for m in data.meshes
                      if "Lightmap" in m.uv_layers},
        "images": {i.name: (tuple(i.size), i.colorspace_settings.name, np.array(i.pixels[:], np.float32))
                   for i in data.images},
        "curve": [(c.bevel_mode, _value(c.bevel_depth), c.bevel_resolution, c.resolution_u, c.use_fill_caps,
                   [_value(p.co) for s in c.splines for p in s.bezier_points]) for c in data.curves],
    }
    snap["render"], snap["render_lightmaps"] = _render(bpy, _render_geometry)
    return snap


@pytest.fixture(scope="module")
def snapshots(bpy, tmp_path_factory):
    """(saved, fresh): the file in the repository and a new build, each as _snapshot sees it."""
    _open(bpy)
    saved = _snapshot(bpy)
    make_courtyard.build_courtyard(str(tmp_path_factory.mktemp("courtyard") / make_courtyard.SKY_FILE))
    return saved, _snapshot(bpy)


def test_fresh_build_matches_the_saved_file(bpy, snapshots):
    saved, fresh = snapshots
    for key in ("objects", "modifiers", "materials", "uv_layers", "curve", "render"):
        assert fresh[key] == saved[key], key
    for key in ("vertices", "images"):
        assert sorted(fresh[key]) == sorted(saved[key]), key
    for name, co in saved["vertices"].items():
        assert np.allclose(fresh["vertices"][name], co, atol=1e-6), name
    for name, (size, space, pixels) in saved["images"].items():
        assert fresh["images"][name][:2] == (size, space), name
        assert np.allclose(fresh["images"][name][2], pixels, rtol=1e-3, atol=1e-6), name
    by_type = {}
    for (_, _, kind), n in saved["render"].items():
        by_type[kind] = by_type.get(kind, 0) + n
    assert by_type.get("MESH", 0) > 0 and sum(by_type.values()) < 30_000
    # Lightmap Pack (an operator) could differ between Blender lines; 4.5 and 5.2 give the same.
    for name, uv in saved["lightmaps"].items():
        assert np.allclose(fresh["lightmaps"][name], uv, atol=1e-6), name


def test_render_geometry_and_modifiers(bpy, snapshots):
    """F12's levels, not the viewport's: the Boulder at render level 3, all five pillars; the curve
    renders as triangles; only instances of the tree collection render."""
    saved, _ = snapshots
    render = saved["render"]
    mesh = {name: n for (parent, name, kind), n in render.items() if parent is None and kind == "MESH"}
    assert set(mesh) == BAKEABLE  # the tree collection's own objects do not render
    assert mesh["Boulder"] == 6 * 4 ** 3 * 2 and mesh["Pillars"] == make_courtyard.PILLARS * 10
    assert any(name == "Handrail" and n > 100 for (_, name, _), n in render.items())
    mods = saved["modifiers"]
    (_, kind, show_render, _, settings), = mods["Boulder"]
    assert kind == "SUBSURF" and show_render and settings[:2] == (1, 3)
    (_, kind, show_render, _, settings), = mods["Pillars"]
    assert kind == "ARRAY" and show_render and settings[0] == make_courtyard.PILLARS


def test_lightmap_uvs_in_the_unit_square(bpy, snapshots):
    saved, _ = snapshots
    assert set(saved["lightmaps"]) == BAKEABLE
    for name, uv in list(saved["lightmaps"].items()) + list(saved["render_lightmaps"].items()):
        assert uv.min() >= 0.0 and uv.max() <= 1.0, name
    for name in BAKEABLE:
        assert saved["uv_layers"][name] == ["UVMap", "Lightmap"], name
    assert saved["uv_layers"]["TreeLeaves"] == ["UVMap"]
    # The Array's copies side by side in the lightmap: copy k in [k / n, (k + 1) / n].
    n = make_courtyard.PILLARS
    copies = saved["render_lightmaps"]["Pillars"].reshape(n, -1, 2)
    for k in range(n):
        assert k / n < copies[k, :, 0].min() and copies[k, :, 0].max() < (k + 1) / n, k


def test_scene_settings_and_textures(bpy):
    scene = _open(bpy)
    assert scene.render.engine == "CYCLES" and scene.cycles.diffuse_bounces == 4 and scene.camera is not None
    for obj in scene.objects:
        if obj.type == "MESH" and obj.name in BAKEABLE:
            me = obj.data
            assert me.uv_layers.active.name == "UVMap" and me.uv_layers["UVMap"].active_render, obj.name
    # The floor: an Image Texture on Base Color, a packed sRGB tile image.
    bsdf = next(n for n in scene.objects["Floor"].active_material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    link = bsdf.inputs["Base Color"].links[0]
    assert link.from_node.type == "TEX_IMAGE"
    img = link.from_node.image
    assert img.packed_file is not None and img.colorspace_settings.name == "sRGB" and tuple(img.size) == (256, 256)
    assert len(img.pixels) == 256 * 256 * 4 and np.ptp(np.array(img.pixels[:])) > 0.2
    # The leaves: the same image's Color and Alpha on Base Color and Alpha; alpha cut, not blended.
    leaves = bpy.data.objects["TreeLeaves"].active_material.node_tree
    bsdf = next(n for n in leaves.nodes if n.type == "BSDF_PRINCIPLED")
    color, alpha = bsdf.inputs["Base Color"].links[0], bsdf.inputs["Alpha"].links[0]
    assert color.from_node == alpha.from_node and color.from_node.type == "TEX_IMAGE"
    assert (color.from_socket.name, alpha.from_socket.name) == ("Color", "Alpha")
    atlas = alpha.from_node.image
    assert atlas.packed_file is not None
    a = np.array(atlas.pixels[:]).reshape(-1, 4)[:, 3]
    assert set(np.unique(a)) == {0.0, 1.0} and 0.1 < a.mean() < 0.7


def test_tree_is_a_collection_instanced_three_times(bpy):
    scene = _open(bpy)
    tree = bpy.data.collections["Tree"]
    assert {o.name for o in tree.objects} == {"TreeTrunk", "TreeLeaves"}
    assert bpy.context.view_layer.layer_collection.children["Tree"].exclude
    assert not set(tree.objects.keys()) & set(bpy.context.view_layer.objects.keys())
    empties = [o for o in scene.objects if o.type == "EMPTY" and o.instance_type == "COLLECTION"
               and o.instance_collection == tree]
    assert len(empties) == 3

    def instances(depsgraph):
        return sorted((i.parent.original.name, i.object.original.name) for i in depsgraph.object_instances
                      if i.is_instance and i.parent is not None and i.parent.original.type == "EMPTY")

    found = _render(bpy, instances)
    assert found == sorted((e.name, o) for e in empties for o in ("TreeLeaves", "TreeTrunk"))


def test_hdri_world_and_sun_agree(bpy):
    scene = _open(bpy)
    nt = scene.world.node_tree
    out = next(n for n in nt.nodes if n.type == "OUTPUT_WORLD" and n.is_active_output)
    background = out.inputs["Surface"].links[0].from_node
    assert background.type == "BACKGROUND"
    env = background.inputs["Color"].links[0].from_node
    assert env.type == "TEX_ENVIRONMENT" and env.projection == "EQUIRECTANGULAR"
    mapping = env.inputs["Vector"].links[0].from_node
    assert mapping.type == "MAPPING" and mapping.vector_type == "POINT"
    coords = mapping.inputs["Vector"].links[0]
    assert coords.from_node.type == "TEX_COORD" and coords.from_socket.name == "Generated"
    rot = tuple(mapping.inputs["Rotation"].default_value)
    assert rot[:2] == (0.0, 0.0) and math.isclose(rot[2], math.radians(make_courtyard.SKY_ROTATION_DEG), abs_tol=1e-6)

    img = env.image
    assert img.packed_file is not None or img.filepath.startswith("//")
    w, h = img.size
    pixels = np.array(img.pixels[:], np.float32).reshape(h, w, 4)[..., :3]  # loads from the file
    assert img.has_data and (w, h) == make_courtyard.SKY_SIZE and img.is_float
    assert np.allclose(pixels, make_courtyard.sky_pixels(), rtol=1e-3, atol=1e-4)
    row, col = np.unravel_index(np.argmax(pixels.sum(axis=2)), (h, w))
    assert pixels[row, col].min() > 100.0 > 10.0 > pixels[h // 2 + 1:, :].mean()  # a sun spot, above a sky

    # The world direction w reads the image at Rz(theta) w: the spot is seen at Rz(-theta) s.
    s = make_courtyard.sky_directions(w, h)[row, col]
    t = -rot[2]
    spot = np.array([math.cos(t) * s[0] - math.sin(t) * s[1], math.sin(t) * s[0] + math.cos(t) * s[1], s[2]])
    suns = [o for o in scene.objects if o.type == "LIGHT" and o.data.type == "SUN"]
    assert len(suns) == 1 and suns[0].data.energy > 0.0
    towards_sun = np.array(suns[0].matrix_world.to_3x3().col[2])  # a sun shines along its -Z
    assert math.degrees(math.acos(np.clip(spot @ towards_sun, -1, 1))) < 2.0


def test_export_takes_the_instances(bpy):
    """The exporter's render evaluation: the seven bake targets and the three trees' instances."""
    _open(bpy)
    scene = export(bpy, resolution=64)
    stats = scene.export_stats
    assert stats["instances"] >= 2 and stats["instanced_triangles"] >= 3 * 64  # at least the trees' leaf cards
    assert {o.name for o in scene.objects if o.bake} == BAKEABLE
    minimum = 24 + 3 * 10 + 5 * 10 + 12 + 768 + 3 * 64  # the bake targets and the instanced leaf cards
    assert minimum < stats["triangles"] < 30_000
    tx = texels.rasterise(scene)
    assert {lm.name for lm in tx.lightmaps} == BAKEABLE and all(lm.count > 0 for lm in tx.lightmaps)
    # Everything F12 renders, once: the curve is not doubled by its own geometry listed as an
    # instance of itself; the floor's and the leaves' images, the leaves' alpha and the HDRI arrive.
    assert stats["triangles"] == 24 + 3 * 10 + 50 + 12 + 768 + 588 + 3 * 210
    assert stats["instances"] == 6 and stats["textures"] == 2
    assert (scene.opacity_texture >= 0).sum() == 3 * 64 and (scene.albedo_texture >= 0).sum() >= 24
    assert scene.world_map is not None and scene.world_map.radiance.max() > 100
