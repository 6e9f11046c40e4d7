"""Lightmap UV layers: created when missing (xatlas charts, `xatlas_unwrap`), removed again when a
bake that created them is cancelled.

A created layer is xatlas's: Smart UV Project's charts (whole polygons) packed at the lightmap's
size or texel density with a 2-texel padding. Lightmap Pack, which the bake used before, gives one
chart per face: on a level of 36,167 faces 36,015 charts under a texel wide, 82 % of the texels on
a chart's border. The panel's Unwrap button runs the same function.
"""
from __future__ import annotations

from typing import Callable, Iterable

import bpy
import numpy as np

from ..errors import BakeError

PADDING = 2  # texels between xatlas charts: no texel shared under bilinear filtering


def unwrap_into(objects, uv_name: str, unwrap: Callable[[], None]) -> None:
    """Run a UV operator (`unwrap`, called once in edit mode with all faces of `objects` selected: one
    object or a list) into `uv_name`, creating the layer where needed; each mesh's active UV layer,
    the selection and the mode are restored."""
    objects = list(objects) if isinstance(objects, (list, tuple)) else [objects]
    view_layer = bpy.context.view_layer
    selected = [o for o in view_layer.objects if o.select_get()]
    active = view_layer.objects.active
    previous = {}
    for obj in objects:
        me = obj.data
        previous[obj.name] = me.uv_layers.active.name if me.uv_layers.active else None
        if uv_name not in me.uv_layers:
            me.uv_layers.new(name=uv_name)
        me.uv_layers.active = me.uv_layers[uv_name]
    try:
        for other in selected:
            other.select_set(False)
        for obj in objects:
            obj.select_set(True)
        view_layer.objects.active = objects[0]
        bpy.ops.object.mode_set(mode="EDIT")
        bpy.ops.mesh.select_all(action="SELECT")
        unwrap()
        bpy.ops.object.mode_set(mode="OBJECT")
    finally:
        for obj in objects:
            obj.select_set(False)
        for other in selected:
            other.select_set(True)
        view_layer.objects.active = active
    for obj in objects:
        me, name = obj.data, previous[obj.name]
        if name is not None and name in me.uv_layers:
            me.uv_layers.active = me.uv_layers[name]


def smart_project() -> None:
    """Smart UV Project as every unwrap here runs it (in edit mode): charts of whole polygons."""
    bpy.ops.uv.smart_project(angle_limit=1.15, island_margin=0.0)


def check_can_add(obj, uv_name: str) -> None:
    """A UV layer cannot be added to linked data (it is read-only here): say so before any work,
    naming the object, its library and the fixes, instead of failing inside Blender's operator."""
    library = getattr(obj.data, "library", None) or obj.library
    if library is not None and uv_name not in obj.data.uv_layers:
        path = bpy.path.abspath(library.filepath, library=library.library)
        raise BakeError(f"object '{obj.name}' is linked from '{path}' and has no UV layer '{uv_name}', which cannot be "
                        f"added to linked data: add it in that file, or make the object local "
                        f"(Object > Relations > Make Local)")


def lightmap_pack(obj, uv_name: str, margin: float = 1.0) -> None:
    """Blender's Lightmap Pack into `uv_name` (one chart per face), replacing the layer."""
    if uv_name in obj.data.uv_layers:
        obj.data.uv_layers.remove(obj.data.uv_layers[uv_name])
    unwrap_into(obj, uv_name, lambda: bpy.ops.uv.lightmap_pack(
        PREF_CONTEXT="ALL_FACES", PREF_PACK_IN_ONE=True, PREF_NEW_UVLAYER=False, PREF_MARGIN_DIV=margin))


def ensure_lightmap_uv(obj, uv_name: str, resolution: int = 0, density: float = 0.0) -> bool:
    """Create `uv_name` with xatlas charts (`xatlas_unwrap`) when it is missing; keep the active UV
    layer. Returns True when the layer was created."""
    if uv_name in obj.data.uv_layers:
        return False
    xatlas_unwrap(obj, uv_name, resolution, density)
    return True


def mesh_arrays(obj, layer: str, dtype=np.float32):
    """(the triangles' corner loops (T·3,), each loop's vertex, the vertices (V, 3), each loop's UV in
    `layer` (L, 2)) of obj's mesh, read in bulk."""
    me = obj.data
    me.calc_loop_triangles()
    tri_l = np.empty(len(me.loop_triangles) * 3, np.int64)
    me.loop_triangles.foreach_get("loops", tri_l)
    loop_v = np.empty(len(me.loops), np.int64)
    me.loops.foreach_get("vertex_index", loop_v)
    co = np.empty(len(me.vertices) * 3, dtype)
    me.vertices.foreach_get("co", co)
    uv = np.empty(len(me.loops) * 2, dtype)
    me.uv_layers[layer].uv.foreach_get("vector", uv)
    return tri_l, loop_v, co.reshape(-1, 3), uv.reshape(-1, 2)


def _welded(obj, layer: str):
    """(corner loops of the triangles (T, 3), xatlas vertices, their indices (T, 3), their UVs):
    one vertex per (mesh vertex, UV) pair, so islands stay joined and seams stay seams; positions
    in the object's scaled space (texels per metre hold on a scaled object)."""
    tri_l, loop_v, co, uv = mesh_arrays(obj, layer)
    co = co * np.abs(np.array(obj.matrix_world.to_scale(), np.float32))
    keys, vertex_of_loop = np.unique(np.c_[loop_v, np.round(uv * 1e6)], axis=0, return_inverse=True)
    vertex_of_loop = vertex_of_loop.reshape(-1)
    first = np.zeros(len(keys), np.int64)
    first[vertex_of_loop] = np.arange(len(vertex_of_loop))
    index = vertex_of_loop[tri_l].reshape(-1, 3).astype(np.uint32)
    return tri_l.reshape(-1, 3), np.ascontiguousarray(co[loop_v[first]]), index, np.ascontiguousarray(uv[first])


def _pack(vertices, index, uv, density: float, resolution: int = 0):
    """xatlas's packing of the charts at `density` texels per unit, or scaled by xatlas for a
    `resolution`² lightmap, into one atlas: where xatlas would spread them over several (whose UVs
    would overlap in one layer) they are packed again at its scale into one that grows to fit.
    Returns (the atlas's side, indices, corner UVs in 0..1 of the side, utilisation), or None when
    xatlas finds no chart (every face without area: the bake leaves such a mesh out and says so)."""
    import xatlas

    for attempt in range(2):
        atlas = xatlas.Atlas()
        atlas.add_mesh(vertices, index, None, uv)
        charts = xatlas.ChartOptions()
        charts.use_input_mesh_uvs = True
        pack = xatlas.PackOptions()
        pack.texels_per_unit = float(density)
        pack.resolution = int(resolution)
        pack.padding = PADDING
        pack.bilinear = True
        atlas.generate(charts, pack)
        if atlas.atlas_count == 1:
            break
        density, resolution = float(atlas.texels_per_unit), 0
    if atlas.atlas_count == 0:  # no chart at all: every face without area
        return None
    _, indices, packed = atlas[0]
    side = max(int(atlas.width), int(atlas.height), 1)
    packed = np.asarray(packed, np.float32) * np.array([atlas.width / side, atlas.height / side], np.float32)
    return side, np.asarray(indices, np.int64).reshape(-1, 3), packed, float(np.ravel(atlas.utilization)[0])


def xatlas_unwrap(obj, layer: str, resolution: int = 0, density: float = 0.0) -> float:
    """Charts from Smart UV Project (whole polygons, so every face keeps consistent UVs), packed by
    xatlas with a PADDING-texel bilinear padding into `layer` (created or replaced; no other layer
    changes): at `density` texels per metre (an atlas's objects), else for a `resolution`²
    lightmap. UVs in 0..1 of the layout's longer side. Returns xatlas's utilisation."""
    unwrap_into(obj, layer, smart_project)
    return _xatlas_charts(obj, layer, resolution, density)


def _xatlas_charts(obj, layer: str, resolution: int, density: float) -> float:
    """`xatlas_unwrap` once Smart UV Project's charts are in `layer`."""
    if not len(obj.data.polygons):
        return 0.0
    tri_l, vertices, index, uv = _welded(obj, layer)
    packing = _pack(vertices, index, uv, density) if density > 0 else \
        _pack(vertices, index, uv, 0.0, int(resolution or 128))
    if packing is None:
        return 0.0  # Smart UV Project's layer stays
    _, indices, packed, used = packing
    out = np.zeros((len(obj.data.loops), 2), np.float32)
    out[tri_l] = packed[indices]
    obj.data.uv_layers[layer].uv.foreach_set("vector", out.reshape(-1))
    return used


def ensure_lightmap_uvs(objects, layers: dict, sizes: dict, densities: dict) -> list:
    """`ensure_lightmap_uv` for many objects ({object name: layer, lightmap size, texel density}):
    Smart UV Project once for all of them, in one edit-mode session, then xatlas per object. One
    session per object cost 0.1-0.15 s each, most of it the view-layer update Blender runs around
    every operator call, which grows with the objects in the scene (1,500 crates: 94 s). The names
    of the objects whose layer was created, in order."""
    todo, meshes = [], set()
    for obj in objects:
        if layers[obj.name] not in obj.data.uv_layers and obj.data.as_pointer() not in meshes:
            meshes.add(obj.data.as_pointer())
            todo.append(obj)
    one_by_one = len(todo) < 2 or len({layers[o.name] for o in todo}) > 1 or \
        any(o.mode != "OBJECT" or not o.visible_get() for o in todo)
    if one_by_one:
        return [o.name for o in objects
                if ensure_lightmap_uv(o, layers[o.name], sizes.get(o.name, 0), densities.get(o.name, 0.0))]
    layer = layers[todo[0].name]
    unwrap_into(todo, layer, smart_project)  # one edit-mode session for all
    for obj in todo:
        _xatlas_charts(obj, layer, sizes.get(obj.name, 0), densities.get(obj.name, 0.0))
    return [o.name for o in todo]


def remove_uv_layers(bl_scene, created: Iterable) -> None:
    """Undo `ensure_lightmap_uv` for (object name, layer) pairs, e.g. after a cancelled bake."""
    for name, layer in created:
        obj = bl_scene.objects.get(name)
        if obj is not None and layer in obj.data.uv_layers:
            obj.data.uv_layers.remove(obj.data.uv_layers[layer])
