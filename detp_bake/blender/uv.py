"""Lightmap UV layers: created with Blender's own unwrapping when missing, removed again when a bake
that created them is cancelled."""
from __future__ import annotations

import contextlib
import io
from typing import Callable, Iterable

import bpy


def unwrap_into(obj, uv_name: str, unwrap: Callable[[], None]) -> None:
    """Run a UV operator (`unwrap`, called in edit mode with all faces selected) into `uv_name`,
    creating the layer if needed; the active UV layer, selection and mode are restored."""
    me = obj.data
    previous = me.uv_layers.active.name if me.uv_layers.active else None
    view_layer = bpy.context.view_layer
    selected = [o for o in view_layer.objects if o.select_get()]
    active = view_layer.objects.active
    if uv_name not in me.uv_layers:
        me.uv_layers.new(name=uv_name)
    me.uv_layers.active = me.uv_layers[uv_name]
    try:
        for other in selected:
            other.select_set(False)
        obj.select_set(True)
        view_layer.objects.active = obj
        bpy.ops.object.mode_set(mode="EDIT")
        bpy.ops.mesh.select_all(action="SELECT")
        unwrap()
        bpy.ops.object.mode_set(mode="OBJECT")
    finally:
        obj.select_set(False)
        for other in selected:
            other.select_set(True)
        view_layer.objects.active = active
    if previous is not None and previous in me.uv_layers:
        me.uv_layers.active = me.uv_layers[previous]


def ensure_lightmap_uv(obj, uv_name: str, margin: float = 1.0) -> bool:
    """Create `uv_name` with Blender's Lightmap Pack when it is missing; keep the active UV layer.
    Returns True when the layer was created."""
    if uv_name in obj.data.uv_layers:
        return False
    unwrap_into(obj, uv_name, lambda: bpy.ops.uv.lightmap_pack(
        PREF_CONTEXT="ALL_FACES", PREF_PACK_IN_ONE=True, PREF_NEW_UVLAYER=False, PREF_MARGIN_DIV=margin))
    return True


def ensure_lightmap_uvs(objects: Iterable, layers: dict, margin: float = 1.0) -> list:
    """`ensure_lightmap_uv` for many objects (`layers`: {object name: layer}) with one Lightmap
    Pack call for all their meshes, each mesh packed into its own square, no mode switch: one call
    per object cost 0.15 s, mostly the view layer update Blender runs around every operator call
    (1,500 crates: 4 minutes). The objects whose layer was created, in order. Objects in edit mode
    take the one-by-one path."""
    objects = list(objects)
    if any(o.mode == "EDIT" for o in objects):
        return [o for o in objects if ensure_lightmap_uv(o, layers[o.name], margin)]
    created, rounds = [], []  # rounds: [{mesh pointer: (object, layer)}], one layer per mesh a round
    for obj in objects:
        me, layer = obj.data, layers[obj.name]
        if layer in me.uv_layers or any(r.get(me.as_pointer(), (None, None))[1] == layer for r in rounds):
            continue
        created.append(obj)
        free = next((r for r in rounds if me.as_pointer() not in r), None)
        if free is None:
            rounds.append(free := {})
        free[me.as_pointer()] = (obj, layer)
    for pending in rounds:
        _pack(list(pending.values()), margin)
    return created


def _pack(pairs: list, margin: float) -> None:
    """Lightmap Pack into layer L of each (object, L) in `pairs` (each its own mesh), created here;
    each mesh's active UV layer kept."""
    previous = {}
    for obj, layer in pairs:
        me = obj.data
        previous[obj.name] = me.uv_layers.active.name if me.uv_layers.active else None
        me.uv_layers.active = me.uv_layers.new(name=layer)
    chosen = [obj for obj, _ in pairs]
    try:
        with bpy.context.temp_override(selected_objects=chosen, active_object=chosen[0], object=chosen[0]), \
                contextlib.redirect_stdout(io.StringIO()):  # the operator prints per mesh
            bpy.ops.uv.lightmap_pack(PREF_CONTEXT="ALL_FACES", PREF_PACK_IN_ONE=False, PREF_NEW_UVLAYER=False,
                                     PREF_MARGIN_DIV=margin)
    finally:
        for obj, _ in pairs:
            me, name = obj.data, previous[obj.name]
            if name is not None and name in me.uv_layers:
                me.uv_layers.active = me.uv_layers[name]


def remove_uv_layers(bl_scene, created: Iterable) -> None:
    """Undo `ensure_lightmap_uv` for (object name, layer) pairs, e.g. after a cancelled bake."""
    for name, layer in created:
        obj = bl_scene.objects.get(name)
        if obj is not None and layer in obj.data.uv_layers:
            obj.data.uv_layers.remove(obj.data.uv_layers[layer])
