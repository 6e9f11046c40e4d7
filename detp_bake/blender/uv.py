"""Lightmap UV layers: created with Blender's own unwrapping when missing, removed again when a bake
that created them is cancelled."""
from __future__ import annotations

from typing import Callable, Iterable

import bpy

from ..errors import BakeError


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


def check_can_add(obj, uv_name: str) -> None:
    """A UV layer cannot be added to linked data (it is read-only here): say so before any work,
    naming the object, its library and the fixes, instead of failing inside Blender's operator."""
    library = getattr(obj.data, "library", None) or obj.library
    if library is not None and uv_name not in obj.data.uv_layers:
        path = bpy.path.abspath(library.filepath, library=library.library)
        raise BakeError(f"object '{obj.name}' is linked from '{path}' and has no UV layer '{uv_name}', which cannot be "
                        f"added to linked data: add it in that file, or make the object local "
                        f"(Object > Relations > Make Local)")


def ensure_lightmap_uv(obj, uv_name: str, margin: float = 1.0) -> bool:
    """Create `uv_name` with Blender's Lightmap Pack when it is missing; keep the active UV layer.
    Returns True when the layer was created."""
    if uv_name in obj.data.uv_layers:
        return False
    unwrap_into(obj, uv_name, lambda: bpy.ops.uv.lightmap_pack(
        PREF_CONTEXT="ALL_FACES", PREF_PACK_IN_ONE=True, PREF_NEW_UVLAYER=False, PREF_MARGIN_DIV=margin))
    return True


def remove_uv_layers(bl_scene, created: Iterable) -> None:
    """Undo `ensure_lightmap_uv` for (object name, layer) pairs, e.g. after a cancelled bake."""
    for name, layer in created:
        obj = bl_scene.objects.get(name)
        if obj is not None and layer in obj.data.uv_layers:
            obj.data.uv_layers.remove(obj.data.uv_layers[layer])
