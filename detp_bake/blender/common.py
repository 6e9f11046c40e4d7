"""Node-tree helpers every part of the adapter uses."""
from __future__ import annotations

import bpy
import numpy as np

from ..options import UV_LAYER

FRAME_NAME = "detp_bake lightmap"
REVERT_KEY = "detp_bake_revert"
PROBE_PROPERTY = "detp_probe_sh"  # an object's probe SH, one colour per coefficient: detp_probe_sh0 … 8
DEFAULT_UV = UV_LAYER
DEFAULT_ALBEDO = (0.8, 0.8, 0.8)


def uses_nodes(idblock) -> bool:
    """Node-based shading in use (`use_nodes` is deprecated in Blender 5, where it always is)."""
    if idblock.node_tree is None:
        return False
    return bpy.app.version >= (5, 0, 0) or bool(idblock.use_nodes)


def socket_rgb(sock) -> np.ndarray:
    v = sock.default_value
    return np.array([v[0], v[1], v[2]], float) if hasattr(v, "__len__") else np.full(3, float(v))


def socket_value(sock, default=0.0) -> float:
    return float(sock.default_value) if sock is not None else default


def _surface_shader(mat):
    nt = mat.node_tree
    outputs = [n for n in nt.nodes if n.type == "OUTPUT_MATERIAL"]
    outputs.sort(key=lambda n: (not n.is_active_output, n.target not in ("ALL", "CYCLES")))
    for out in outputs:
        surf = out.inputs.get("Surface")
        if surf is not None and surf.is_linked:
            return surf.links[0].from_node
    return None


def probe_lit(obj) -> bool:
    """The object's Probe Light toggle: it moves, so the baked probes light it, and the bake leaves
    it out (no lightmap, no shadow or bounce at wherever it stands now). The add-on's object
    setting, read from the stored settings where the add-on is not registered (the command line)."""
    settings = getattr(obj, "detp_bake", None)
    if settings is not None and hasattr(settings, "probe_light"):
        return bool(settings.probe_light)
    stored = obj.get("detp_bake")
    return bool(stored is not None and hasattr(stored, "get") and stored.get("probe_light"))
