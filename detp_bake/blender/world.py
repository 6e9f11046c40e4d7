"""The world as a light: a Background colour, or an Environment Texture (an equirectangular HDRI)
turned by a Mapping node, times the Background's strength."""
from __future__ import annotations

from typing import Callable, Optional

import numpy as np

from ..transport.environment import EnvironmentMap
from .common import uses_nodes, socket_rgb, socket_value
from .materials import image_use, linked_socket, image_pixels


def _euler_matrix(rx: float, ry: float, rz: float) -> np.ndarray:
    """Blender's XYZ Euler rotation: Rz·Ry·Rx."""
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    x = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    y = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    z = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return z @ y @ x


def _rotation(env_node, log) -> np.ndarray:
    """The rotation R with which the texture reads direction ω at R·ω (Mapping node, if any)."""
    src = linked_socket(env_node.inputs.get("Vector"))
    if src is None:
        return np.eye(3)
    node, _ = src
    if node.type == "TEX_COORD":
        return np.eye(3)
    if node.type != "MAPPING":
        log(f"world: the Environment Texture's vector comes from a {node.type.lower()} node: not rotated")
        return np.eye(3)
    rot = node.inputs.get("Rotation")
    r = _euler_matrix(*rot.default_value) if rot is not None and not rot.is_linked else np.eye(3)
    inner = linked_socket(node.inputs.get("Vector"))
    if inner is not None and inner[0].type != "TEX_COORD":
        log(f"world: the Mapping node reads a {inner[0].type.lower()} node: taken as the view direction")
    return r.T if node.vector_type == "TEXTURE" else r


def export_world(world, log: Callable[[str], None] = print) -> tuple[np.ndarray, Optional[EnvironmentMap]]:
    """(constant sky radiance, environment map or None) of the scene's world."""
    if world is None:
        return np.zeros(3), None
    if not uses_nodes(world):
        return np.array(world.color[:3], float), None
    for node in world.node_tree.nodes:
        if node.type != "OUTPUT_WORLD" or not node.is_active_output:
            continue
        src = linked_socket(node.inputs.get("Surface"))
        if src is None or src[0].type != "BACKGROUND":
            if src is not None:
                log(f"world: a {src[0].type.lower()} shader is not understood: no world light")
            return np.zeros(3), None
        bg = src[0]
        strength = socket_value(bg.inputs.get("Strength"), 1.0)
        colour = linked_socket(bg.inputs["Color"])
        if colour is None:
            return socket_rgb(bg.inputs["Color"]) * strength, None
        tex, out = colour
        if tex.type == "TEX_ENVIRONMENT" and out.name == "Color" and tex.image is not None:
            notes = []
            use = image_use(tex, notes, read_uv=False)
            for note in notes:
                log(f"world: {note}")
            if use is not None:
                if tex.projection != "EQUIRECTANGULAR":
                    log("world: a mirror-ball environment is read as equirectangular")
                radiance = image_pixels(use)[..., :3] * strength
                return np.zeros(3), EnvironmentMap(np.ascontiguousarray(radiance, np.float32), _rotation(tex, log))
        log(f"world: its colour comes from a {tex.type.lower()} node: the socket's value is used")
        return socket_rgb(bg.inputs["Color"]) * strength, None
    return np.zeros(3), None
