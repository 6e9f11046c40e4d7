"""Baked probes on the objects that move: each object the user marks shows its probe SH, taken at
its position, as a lightmapped object shows its lightmap (EEVEE, viewport and render).

The object's nine SH colours live in its custom properties (PROBE_PROPERTY0 … 8), which the
material reads through Attribute nodes of type Object; so a frame change rewrites nine numbers
and no shader is rebuilt. The material frame is Apply's own (`lightmaps.wire_light`) with the SH
L2 group of sh_nodes.py in place of the lightmap image, so Revert undoes it exactly as it undoes a
lightmap, and a shared material is copied for the object as Apply copies it.

Which probes a scene shows is the path of a probes.npz on the scene (PROBES_KEY); `update`, run
on every frame change (`frame_change_post`, registered by the add-on), reads it once per file
version and moves the marked objects' SH to where they are now.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Optional

import bpy
import numpy as np

from ..errors import BakeError
from ..probes import grid, lookup, sh9
from . import sh_nodes
from .common import PROBE_PROPERTY, REVERT_KEY, probe_lit as marked
from .lightmaps import apply_lightmap, revert

PROBES_KEY = "detp_bake_probes"  # scene custom property: the probes.npz its probe-lit objects read
_CACHE: dict = {}  # path -> (mtime, grids)


def grids_of(path) -> list:
    """The grids of a probes.npz, read again only when the file changed."""
    path = str(path)
    try:
        mtime = os.path.getmtime(path)
    except OSError:
        raise BakeError(f"no probe file '{path}': bake with probes first") from None
    cached = _CACHE.get(path)
    if cached is None or cached[0] != mtime:
        try:
            _CACHE[path] = cached = (mtime, grid.load(Path(path)))
        except (OSError, ValueError, KeyError) as exc:
            raise BakeError(f"cannot read the probe file '{path}': {exc}") from None
    return cached[1]


def _light(nt, frame, x0, normal):
    """The probe frame's light: nine Attribute nodes (the object's SH) into the SH L2 group."""
    group = nt.nodes.new("ShaderNodeGroup")
    group.node_tree = sh_nodes.probe_group()
    group.label = "Probe light (SH L2)"
    group.parent, group.location = frame, (x0 + 250.0, -400.0)
    for k in range(sh9.COEFFICIENTS):
        attribute = nt.nodes.new("ShaderNodeAttribute")
        attribute.attribute_type = "OBJECT"
        attribute.attribute_name = f"{PROBE_PROPERTY}{k}"
        attribute.parent, attribute.location = frame, (x0, -400.0 - 180.0 * k)
        nt.links.new(attribute.outputs["Color"], group.inputs[f"C{k}"])
    if normal is None:
        geometry = nt.nodes.new("ShaderNodeNewGeometry")
        geometry.parent, geometry.location = frame, (x0, -2100.0)
        normal = geometry.outputs["Normal"]
    nt.links.new(normal, group.inputs["Normal"])
    return group.outputs["Color"]


def set_sh(obj, coefficients: np.ndarray) -> None:
    """Write the object's nine SH colours (9, 3) where its material reads them."""
    for k in range(sh9.COEFFICIENTS):
        obj[f"{PROBE_PROPERTY}{k}"] = [float(v) for v in coefficients[k]]
    obj.update_tag()


def sh_at(grids: list, obj, depsgraph=None) -> np.ndarray:
    """The SH (9, 3) at the object's origin as evaluated now (its animation applied)."""
    evaluated = obj.evaluated_get(depsgraph) if depsgraph is not None else obj
    return lookup.at(grids, np.array(evaluated.matrix_world.translation))[0]


def apply_probes(bl_scene, path, objects: list, shared: bool = False) -> list:
    """Light `objects` with the probes of the probes.npz `path`: each object's materials get the
    probe frame (a material another object uses is copied first) and its SH at its position now.
    Returns the objects."""
    grids = grids_of(path)
    if not grids:
        raise BakeError(f"the probe file '{path}' holds no probes")
    depsgraph = bpy.context.evaluated_depsgraph_get()
    users = {}
    for o in bl_scene.objects:
        for slot in o.material_slots:
            if slot.material is not None:
                users.setdefault(slot.material.name, set()).add(o.name)
    for obj in objects:
        if obj.type != "MESH":
            raise BakeError(f"object '{obj.name}' is not a mesh: only meshes take probe light")
        revert(obj)  # shows a lightmap or older probes: replaced
        mine = shared or any(len(users.get(s.material.name, ())) > 1 for s in obj.material_slots if s.material)
        apply_lightmap(obj, None, "", shared=mine, light=_light)
        set_sh(obj, sh_at(grids, obj, depsgraph))
    bl_scene[PROBES_KEY] = str(path)
    return list(objects)


def apply_marked(bl_scene, folder, log=None) -> list:
    """Light the scene's meshes marked Probe Light with the probes.npz in `folder`, when there is
    one and something is marked; the objects lit."""
    path = Path(folder) / grid.FILE_NAME
    objects = [o for o in bl_scene.objects if o.type == "MESH" and marked(o)]
    if not objects or not path.is_file():
        return []
    lit = apply_probes(bl_scene, path, objects)
    if log is not None:
        log(f"probe light on {len(lit)} object{'s' if len(lit) > 1 else ''}: {', '.join(o.name for o in lit)}")
    return lit


def probe_lit(bl_scene) -> list:
    """The scene's objects that show probe light now."""
    return [o for o in bl_scene.objects if REVERT_KEY in o and f"{PROBE_PROPERTY}0" in o]


def update(bl_scene, depsgraph=None) -> int:
    """Move each probe-lit object's SH to where it is now; how many were updated. Quiet when the
    scene shows no probes or its file is gone (a handler must not raise on every frame)."""
    path: Optional[str] = bl_scene.get(PROBES_KEY)
    objects = probe_lit(bl_scene)
    if not path or not objects:
        return 0
    try:
        grids = grids_of(path)
    except BakeError:
        return 0
    for obj in objects:
        set_sh(obj, sh_at(grids, obj, depsgraph))
    return len(objects)


@bpy.app.handlers.persistent
def on_frame_change(bl_scene, depsgraph=None):
    """frame_change_post: the probe-lit objects follow the frame."""
    update(bl_scene, depsgraph)


def register_handler() -> None:
    if on_frame_change not in bpy.app.handlers.frame_change_post:
        bpy.app.handlers.frame_change_post.append(on_frame_change)


def unregister_handler() -> None:
    for handler in [h for h in bpy.app.handlers.frame_change_post if getattr(h, "__name__", "") == "on_frame_change"
                    and getattr(h, "__module__", "") == __name__]:
        bpy.app.handlers.frame_change_post.remove(handler)
