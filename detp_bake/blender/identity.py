"""Which geometry a bake's lightmaps belong to: a fingerprint of each baked object (its mesh's
vertices and faces, its place in the world), kept in report.json at bake time, so that the glTF
export can refuse lightmaps made for another scene's objects of the same name, or for an object
edited or moved since. The mesh as stored is read, not as its modifiers make it: one array read
per mesh, cheap on a level of thousands of objects."""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

import bpy  # noqa: F401  (this module reads Blender data)
import numpy as np

from ..errors import BakeError


def _mesh_arrays(mesh) -> tuple:
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    corners = np.empty(len(mesh.loops), np.int32)
    mesh.loops.foreach_get("vertex_index", corners)
    sizes = np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("loop_total", sizes)
    return co, corners, sizes


def fingerprint(obj) -> dict:
    """{"vertices", "faces", "hash"} of a mesh object: counts to name in a message, and a SHA-256
    of its vertex positions, faces and world matrix."""
    co, corners, sizes = _mesh_arrays(obj.data)
    h = hashlib.sha256()
    for part in (co, corners, sizes, np.array(obj.matrix_world, np.float32)):
        h.update(np.ascontiguousarray(part).tobytes())
    return {"vertices": len(obj.data.vertices), "faces": len(obj.data.polygons), "hash": h.hexdigest()[:24]}


def fingerprints(objects) -> dict:
    """{object name: fingerprint} of the objects a bake gives lightmaps (report.json's export section)."""
    return {obj.name: fingerprint(obj) for obj in objects}


def _recorded(out_dir) -> tuple[set, dict, str]:
    """The object names, the fingerprints and the .blend file of the bake in `out_dir`."""
    try:
        report = json.loads((Path(out_dir) / "report.json").read_text())
    except (OSError, ValueError):
        return set(), {}, ""  # the export names what is wrong with the report itself
    sections = report.get("estimators") or {"": report}
    names = {e["name"] for s in sections.values() for e in s.get("objects", []) if "name" in e}
    export = next((s["export"] for s in sections.values() if s.get("export", {}).get("geometry")), {})
    return names, export.get("geometry", {}), export.get("file", "")


def check_lightmaps(bl_scene, out_dir) -> None:
    """BakeError naming the objects when the lightmaps in `out_dir` were not baked for this scene's
    objects: missing here, or with other vertices, faces or place than when they were baked. A
    report written before fingerprints were kept is checked by name only."""
    names, recorded, blend = _recorded(out_dir)
    source = f" (baked from '{blend}')" if blend else ""
    missing = sorted(n for n in names if bl_scene.objects.get(n) is None)
    if missing:
        listed = ", ".join(repr(n) for n in missing[:6]) + (" and more" if len(missing) > 6 else "")
        raise BakeError(f"object{'s' if len(missing) > 1 else ''} {listed} of report.json "
                        f"{'are' if len(missing) > 1 else 'is'} not in scene '{bl_scene.name}': the lightmaps in "
                        f"'{out_dir}'{source} are another scene's; give the output folder of this scene's own bake")
    changed = []
    for name in sorted(names & set(recorded)):
        obj = bl_scene.objects[name]
        now = fingerprint(obj) if obj.type == "MESH" else {"vertices": 0, "faces": 0, "hash": ""}
        then = recorded[name]
        if now["hash"] == then.get("hash"):
            continue
        same = (now["faces"], now["vertices"]) == (then.get("faces"), then.get("vertices"))
        changed.append(f"'{name}' (" + ("moved or edited since" if same else
                       f"{then.get('faces')} faces, {then.get('vertices')} vertices when baked; "
                       f"{now['faces']}, {now['vertices']} here") + ")")
    if changed:
        raise BakeError(f"the lightmaps in '{out_dir}'{source} were baked for other geometry than this file's "
                        f"objects {', '.join(changed[:6])}{' and more' if len(changed) > 6 else ''}: bake this "
                        "scene again, or give the output folder of its own bake")
