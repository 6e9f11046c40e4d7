"""Lightmap UV layers made for many objects at once (blender/uv.py, `ensure_lightmap_uvs`): Smart
UV Project in one edit-mode session for all of them, then xatlas per object."""
import numpy as np


def _uvs(obj):
    flat = np.empty(len(obj.data.loops) * 2, np.float32)
    obj.data.uv_layers["Lightmap"].uv.foreach_get("vector", flat)
    return flat.reshape(-1, 2)


def _uv_area(obj):
    me = obj.data
    me.calc_loop_triangles()
    loops = np.empty(len(me.loop_triangles) * 3, np.int64)
    me.loop_triangles.foreach_get("loops", loops)
    u = _uvs(obj)[loops.reshape(-1, 3)].astype(np.float64)
    e1, e2 = u[:, 1] - u[:, 0], u[:, 2] - u[:, 0]
    return 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()


def test_many_objects_get_the_charts_one_at_a_time_would_give(bpy):
    """Cubes of three sizes and a sphere: each gets a layer filling its square as much as one
    object's own session gives it (the charts are the same; their order may differ), a mesh shared
    by two objects gets one, every mesh keeps its active UV layer, and the names made are said."""
    from detp_bake.blender.uv import ensure_lightmap_uv, ensure_lightmap_uvs
    bpy.ops.wm.read_factory_settings(use_empty=True)
    objs = []
    for i in range(3):
        bpy.ops.mesh.primitive_cube_add(size=1.0 + 0.4 * i, location=(3 * i, 0, 0))  # its own active 'UVMap'
        objs.append(bpy.context.active_object)
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=2, location=(0, 5, 0))
    objs.append(bpy.context.active_object)
    twin = objs[0].copy()  # shares the first cube's mesh
    bpy.context.scene.collection.objects.link(twin)
    alone = []
    for obj in objs:
        copy = obj.copy()
        copy.data = obj.data.copy()
        bpy.context.scene.collection.objects.link(copy)
        alone.append(copy)
    everyone = objs + [twin]
    made = ensure_lightmap_uvs(everyone, {o.name: "Lightmap" for o in everyone}, {o.name: 32 for o in everyone}, {})
    assert made == [o.name for o in objs]
    for obj, copy in zip(objs, alone):
        assert ensure_lightmap_uv(copy, "Lightmap", 32)
        uv = _uvs(obj)
        assert uv.min() >= 0.0 and uv.max() <= 1.0
        assert abs(_uv_area(obj) / _uv_area(copy) - 1) < 1e-4 and _uv_area(obj) > 0.3
        assert obj.data.uv_layers.active.name == "UVMap"
