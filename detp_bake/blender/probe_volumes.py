"""The scene's Light Probe Volume objects as plain records (scene.ProbeVolume): each a box (the unit
cube [−1, 1]³ under the object's world matrix) cut by its own x/y/z resolution, as EEVEE reads it
(Blender 4.2 and later: object type 'LIGHT_PROBE', data type 'VOLUME')."""
from __future__ import annotations

import numpy as np

from ..scene import ProbeVolume


def probe_volumes(bl_scene, view_layer=None) -> list[ProbeVolume]:
    """Every Light Probe Volume the render sees (not hidden from it, in the view layer), in name order."""
    visible = None if view_layer is None else {o.name for o in view_layer.objects}
    out = []
    for obj in sorted(bl_scene.objects, key=lambda o: o.name):
        if obj.type != "LIGHT_PROBE" or obj.data is None or obj.data.type != "VOLUME" or obj.hide_render:
            continue
        if visible is not None and obj.name not in visible:
            continue
        res = (int(obj.data.resolution_x), int(obj.data.resolution_y), int(obj.data.resolution_z))
        out.append(ProbeVolume(obj.name, np.array(obj.matrix_world, np.float64), res))
    return out


def panel_cost(bl_scene, view_layer, mode: str, spacing: float) -> tuple[int, int, bool]:
    """(probes, bytes, exact) for the panel before a bake: the volumes' cells exactly, or for an
    automatic grid the cells of the rendered meshes' box (an upper bound: the bake keeps only the
    probes near geometry, and reads the baked objects' box alone)."""
    from ..probes import placement
    if mode == "volumes":
        grids = [placement.grid_of(v) for v in probe_volumes(bl_scene, view_layer)]
        count, size = placement.cost(grids)
        return count, size, True
    corners = [np.array(o.matrix_world) @ np.append(np.array(c), 1.0) for o in view_layer.objects
               if o.type == "MESH" and not o.hide_render for c in o.bound_box]
    if not corners or not spacing > 0.0:
        return 0, 0, True
    pts = np.array(corners)[:, :3]
    count = placement.cells(pts.min(axis=0), pts.max(axis=0), spacing)
    return count, placement.cost_of(min(count, placement.MAX_PROBES)), False
