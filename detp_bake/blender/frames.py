"""The Blender side of a frame range (detp_bake/run/frames.py): the scene at a frame, exported as F12
renders it, and the user's current frame given back afterwards."""
from __future__ import annotations

from contextlib import contextmanager
from typing import Callable, Optional

from .export import export_scene


def frame_exporter(bl_scene, objects=None, uv_layer=None, resolution=0, log: Callable[[str], None] = print,
                   created: Optional[list] = None, max_bytes: Optional[int] = None, atlas=None):
    """`scene_at(frame)`: set the frame (animation, drivers, modifiers, simulations as Blender
    evaluates them) and export it (export.export_scene, same arguments). Each message of the
    exporter is said once for the whole range, not once per frame."""
    said = set()

    def once(message: str) -> None:
        if message not in said:
            said.add(message)
            log(message)

    def scene_at(frame: int):
        bl_scene.frame_set(int(frame))
        return export_scene(bl_scene, None, objects, uv_layer, resolution, once, created, max_bytes, atlas)

    return scene_at


@contextmanager
def frame_kept(bl_scene):
    """Put the scene back on the frame (and subframe) it showed before, whatever happens inside."""
    frame, subframe = bl_scene.frame_current, bl_scene.frame_subframe
    try:
        yield bl_scene
    finally:
        bl_scene.frame_set(frame, subframe=subframe)
