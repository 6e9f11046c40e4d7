"""Opening and saving .blend files for the command line: the scene to bake comes from a file, and a
baked scene is saved with its lightmap images stored relative to it."""
from __future__ import annotations

import os
from pathlib import Path

import bpy

from ..errors import BakeError


def open_blend(path: Path):
    """Open a .blend file; its active scene."""
    if not path.is_file() or not os.access(path, os.R_OK):
        raise BakeError(f"cannot read scene file '{path}'")
    try:
        bpy.ops.wm.open_mainfile(filepath=str(path.resolve()))
    except RuntimeError as exc:
        raise BakeError(f"cannot open scene file '{path}': {exc}") from None
    saved, running = tuple(bpy.data.version[:2]), tuple(bpy.app.version[:2])
    if saved > running:  # Blender reads it, says "expect loss of data" and goes on: we do not
        raise BakeError(f"scene file '{path}' was saved by Blender {saved[0]}.{saved[1]}, newer than this Blender "
                        f"{bpy.app.version_string}: what it reads of it may be wrong or missing; bake with Blender "
                        f"{saved[0]}.{saved[1]} or later (the bpy wheel of that line)")
    return bpy.context.scene


def save_blend(target: Path, files: dict) -> None:
    """Save the open file as `target`, the lightmap images (`files`: object -> paths) pointing at
    their files relative to it (//…), so it opens with its lightmaps from any folder; absolute where
    no relative path exists (another drive)."""
    ours = {os.path.normcase(os.path.abspath(p)) for paths in files.values() for p in paths}
    for img in bpy.data.images:
        path = os.path.normcase(os.path.abspath(bpy.path.abspath(img.filepath))) if img.filepath else None
        if path in ours:
            try:
                img.filepath = "//" + Path(os.path.relpath(path, target.parent)).as_posix()
            except ValueError:
                img.filepath = path
    bpy.ops.wm.save_as_mainfile(filepath=str(target), copy=False, relative_remap=False)
