"""Atlases in Blender: each baked object's islands packed by the core (lightmap/atlas.py) into a UV
layer of its own, ATLAS_UV, which the bake then reads.

The object's lightmap UV layer stays as it is (it holds the islands; the user may have made it), so
Revert and a per-object bake still find it; the atlas layer is created by the bake and is the one
the atlases' images are wired through. Linked duplicates share one mesh and so one UV layer: each
gets a mesh of its own first (said through the log), or two objects would share texels.

Packing is skipped when nothing it reads has changed since the last packing of the scene (a hash
kept on the scene), so a rebake, or a frame of a range whose objects only move, keeps the same
UVs and the same atlas of each object.
"""
from __future__ import annotations

import hashlib
import json
import os

import numpy as np

from ..errors import BakeError
from ..lightmap import atlas as atlas_mod
from .uv import mesh_arrays, smart_project, unwrap_into

ATLAS_UV = "LightmapAtlas"
SMART_UV = "detp_bake smart islands"
STATE = "detp_bake_atlas"  # scene custom property: the last packing's hash and atlases


def _single_users(objects, log) -> None:
    """Give linked duplicates among `objects` meshes of their own (their UVs must differ)."""
    seen = set()
    split = []
    for obj in objects:
        if obj.data.name in seen:
            obj.data = obj.data.copy()
            split.append(obj.name)
        seen.add(obj.data.name)
    if split:
        log(f"atlas: {', '.join(split[:5])}{' …' if len(split) > 5 else ''} shared a mesh with another baked "
            "object: each now has a mesh of its own (its texels in the atlas are its own)")


# Modifiers whose copies of the faces keep the mesh's UVs: the copies share the object's texels.
COPYING = {"ARRAY": "Array", "MIRROR": "Mirror", "SOLIDIFY": "Solidify", "SCREW": "Screw"}


def _copied(objects, log) -> None:
    """Say, before the bake, which objects' modifiers copy faces onto the same atlas texels: a UV
    layer lives on the mesh, so no packing can give the copies texels of their own."""
    found = []
    for obj in objects:
        kinds = list(dict.fromkeys(COPYING[m.type] for m in obj.modifiers if m.type in COPYING and m.show_render))
        if kinds:
            found.append(f"'{obj.name}' ({', '.join(kinds)})")
    if found:
        log(f"atlas: the modifiers of {', '.join(found[:6])}{' …' if len(found) > 6 else ''} copy faces with their "
            "lightmap UVs, so the copies share texels (one light for all): apply the modifiers (Object › Apply) to "
            "give each copy texels of its own")


def _triangles(obj, layer: str):
    """(loop indices (T, 3), world positions (T, 3, 3), the layer's UVs (T, 3, 2)) of obj's mesh."""
    loops, vertex, co, uv = mesh_arrays(obj, layer, np.float64)
    m = np.array(obj.matrix_world, np.float64)
    world = co @ m[:3, :3].T + m[:3, 3]
    loops = loops.reshape(-1, 3)
    return loops, world[vertex[loops]], uv[loops]


def _islands(obj, layer: str, charts: str):
    """The triangles and the UVs whose islands are packed: the layer's, or Smart UV Project's."""
    if charts != "smart":
        return _triangles(obj, layer)
    unwrap_into(obj, SMART_UV, smart_project)
    try:
        return _triangles(obj, SMART_UV)
    finally:
        obj.data.uv_layers.remove(obj.data.uv_layers[SMART_UV])


def _hash(objects, layers, settings) -> str:
    h = hashlib.blake2b(digest_size=16)
    h.update(json.dumps([settings.texel_density, settings.atlas_size, settings.atlas_padding,
                         settings.atlas_charts]).encode())
    for obj in objects:
        loops, world, uv = _triangles(obj, layers[obj.name])
        h.update(obj.name.encode())
        h.update(np.ascontiguousarray(world - world.reshape(-1, 3).min(axis=0), np.float32).tobytes())
        h.update(np.ascontiguousarray(uv, np.float32).tobytes())
        h.update(np.float64(obj.detp_bake.density_scale if hasattr(obj, "detp_bake") else 1.0).tobytes())
    return h.hexdigest()


def _write(obj, loops, corner_uvs, created) -> None:
    me = obj.data
    if ATLAS_UV not in me.uv_layers:
        if len(me.uv_layers) >= 8:
            raise BakeError(f"object '{obj.name}' has 8 UV layers, Blender's most: remove one for the atlas "
                            f"layer '{ATLAS_UV}'")
        me.uv_layers.new(name=ATLAS_UV, do_init=False)
        if created is not None:
            created.append((obj.name, ATLAS_UV))
    out = np.zeros((len(me.loops), 2), np.float32)
    out[loops.reshape(-1)] = corner_uvs.reshape(-1, 2)
    me.uv_layers[ATLAS_UV].uv.foreach_set("vector", out.reshape(-1))


def pack(bl_scene, objects, layers: dict, settings, log, created=None) -> dict:
    """Pack `objects` (their islands in `layers` {name: UV layer}) into atlases, each one's UVs
    written into ATLAS_UV; returns {object name: (atlas name, its side in texels)}."""
    _single_users(objects, log)
    _copied(objects, log)
    digest = _hash(objects, layers, settings)
    state = json.loads(bl_scene.get(STATE, "{}"))
    fresh = state.get("hash") == digest and all(ATLAS_UV in o.data.uv_layers for o in objects) \
        and set(state.get("atlas", {})) == {o.name for o in objects}
    if fresh:
        return {name: tuple(v) for name, v in state["atlas"].items()}
    meshes, loops = [], {}
    for obj in objects:
        loop, world, uv = _islands(obj, layers[obj.name], settings.atlas_charts)
        loops[obj.name] = loop
        scale = float(obj.detp_bake.density_scale) if hasattr(obj, "detp_bake") else 1.0
        meshes.append(atlas_mod.Mesh(obj.name, world, uv, scale))
    packing = atlas_mod.pack(meshes, settings.texel_density, settings.atlas_size, settings.atlas_padding, keep=True,
                             whole=settings.atlas_charts == "layout")
    for warning in packing.warnings:
        log(warning)
    for obj in objects:
        _write(obj, loops[obj.name], packing.objects[obj.name].uvs, created)
    out = {name: (packing.name(placed.atlas), packing.sizes[placed.atlas]) for name, placed in packing.objects.items()}
    bl_scene[STATE] = json.dumps({"hash": digest, "atlas": out}, allow_nan=False)
    sides = ", ".join(f"{s}²" for s in packing.sizes)
    log(f"atlas: {len(objects)} objects packed into {packing.count} atlas{'es' if packing.count > 1 else ''} "
        f"({sides}) at {settings.texel_density:g} texels per metre")
    return out


def members(bl_scene) -> dict:
    """{atlas name: [object names]} of the scene's last packing (empty when it has none)."""
    out: dict = {}
    for name, (image, _) in json.loads(bl_scene.get(STATE, "{}")).get("atlas", {}).items():
        out.setdefault(image, []).append(name)
    return out


def lightmap_of(bl_scene, files: dict) -> dict:
    """{object name: (lightmap name, its paths)} of a bake's `files` ({lightmap name: paths}, or
    {object name: paths} as report.json lists them): an atlas's paths go to each of its objects."""
    atlases = members(bl_scene)
    placed = {obj: image for image, objs in atlases.items() for obj in objs}
    out = {}
    for name, paths in files.items():
        if name in atlases:
            out.update({obj: (name, paths) for obj in atlases[name]})
        elif name in placed and any(os.path.basename(p).startswith(placed[name] + ".") for p in paths):
            out[name] = (placed[name], paths)
        else:
            out[name] = (name, paths)
    return out
