"""A bake's light probes in the .glb (docs/gltf.md, DETP_light_probes): on the scene, each grid's
box in glTF's axes and its SH as seven RGBA float16 3D textures a loader uploads as they are
(probes/lookup.py `textures`); on each node the user marked Probe Light, DETP_light_probes
{"sample": "origin"}: light it with the probes' SH at its origin, as Blender does.

Blender's axes (z up) become glTF's (y up): a point (x, y, z) is (x, z, −y) there, so the grid's
matrix is turned and so is every probe's SH (`lookup.rotated`)."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np

from ..probes import grid, lookup
from .common import PROBE_PROPERTY
from .probe_light import marked

EXTENSION = "DETP_light_probes"
FORMAT = "RGBA16F"
ENCODING = "SH L2 radiance, three.js SphericalHarmonics3 order, lightmap unit (E/pi)"
TO_GLTF = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0], [0, -1.0, 0, 0], [0, 0, 0, 1.0]])


def read(out_dir) -> list:
    """The bake's grids in glTF's axes, or [] when it baked no probes."""
    path = Path(out_dir) / grid.FILE_NAME
    if not path.is_file():
        return []
    grids = grid.load(path)
    for g in grids:
        g.matrix = TO_GLTF @ g.matrix
        g.offset = (g.offset @ TO_GLTF[:3, :3].T).astype(np.float32)
        g.coefficients = lookup.rotated(g.coefficients, TO_GLTF[:3, :3]).astype(np.float32)
    return grids


def probe_lit(obj) -> bool:
    """An object the export marks: it shows probe light, or its Probe Light toggle is on."""
    return f"{PROBE_PROPERTY}0" in obj or marked(obj)


def scene_extension(grids: list):
    """The scene's DETP_light_probes: per grid its box, resolution and seven texture buffer views."""
    from io_scene_gltf2.io.com.gltf2_io_extensions import Extension
    from io_scene_gltf2.io.exp.binary_data import BinaryData
    entries = []
    for g in grids:
        textures = lookup.textures(g, np.float16)
        entries.append({
            "name": g.name,
            "matrix": [float(v) for v in g.matrix.T.ravel()],  # column-major, as glTF's
            "resolution": [int(r) for r in g.resolution],
            "format": FORMAT,
            "textures": [BinaryData(np.ascontiguousarray(t).tobytes()) for t in textures],
            "probes": len(g),
            "invalid": int((~g.valid).sum()),
        })
    return Extension(name=EXTENSION, required=False, extension={"encoding": ENCODING, "grids": entries})


def node_extension():
    from io_scene_gltf2.io.com.gltf2_io_extensions import Extension
    return Extension(name=EXTENSION, required=False, extension={"sample": "origin"})


def user_material_of(obj, index: int, frame_name: str, user_material) -> Optional[object]:
    """Slot `index`'s material as the user made it, when the slot shows probe light (None: leave it)."""
    slot = obj.material_slots[index]
    if slot.material is None or slot.material.node_tree is None or \
            slot.material.node_tree.nodes.get(frame_name) is None:
        return None
    return user_material(obj, index)
