"""The baked probes in the 3D viewport: a small sphere at each probe, each point of it coloured by
the radiance the probe's SH gives from that direction (sh9.radiance), so the light field shows;
invalid probes (inside geometry) in flat red, as Unity draws them.

One draw handler (POST_VIEW) for all 3D views, added when the panel's toggle turns on and removed
when it turns off or the add-on unregisters. The spheres of a probe file are one GPU batch, made
again only when the file changes."""
from __future__ import annotations

import os
from typing import Optional

import bpy
import numpy as np

from ..probes import sh9
from .probe_light import grids_of

INVALID = (1.0, 0.0, 0.0)
_HANDLE = None
_BATCH: dict = {}  # path -> (mtime, radius, batch)


def unit_sphere(rings: int = 6, segments: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """A UV sphere of radius 1: (V, 3) vertices, which are also its normals, and (T, 3) triangles."""
    theta = np.linspace(0.0, np.pi, rings + 1)
    phi = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    v = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1).reshape(-1, 3)
    r, s = np.meshgrid(np.arange(rings), np.arange(segments), indexing="ij")
    a = r * segments + s
    b = r * segments + (s + 1) % segments
    c, d = a + segments, b + segments
    tris = np.concatenate([np.stack([a, c, d], -1).reshape(-1, 3), np.stack([a, d, b], -1).reshape(-1, 3)])
    return v, tris


def spacing(grids: list) -> float:
    """The smallest distance between neighbouring probes of any grid."""
    steps = [np.linalg.norm(g.matrix[:3, :3] @ (2.0 * np.eye(3)[a] / g.resolution[a]))
             for g in grids for a in range(3)]
    return float(min(steps)) if steps else 1.0


def spheres(grids: list, radius: Optional[float] = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every probe's sphere: (V, 3) world positions, (V, 4) linear RGBA colours (sh9.radiance at the
    vertex's normal, red for an invalid probe) and (T, 3) triangles. `radius`: a sixth of the
    spacing when None."""
    radius = spacing(grids) / 6.0 if radius is None else radius
    normals, tris = unit_sphere()
    positions, colours, triangles, base = [], [], [], 0
    for g in grids:
        centres = g.positions + g.offset
        colour = sh9.radiance(g.coefficients[:, None], normals[None])  # (N, V, 3)
        colour[~g.valid] = INVALID
        positions.append((centres[:, None] + radius * normals[None]).reshape(-1, 3))
        colours.append(np.concatenate([colour, np.ones(colour.shape[:2] + (1,))], axis=-1).reshape(-1, 4))
        offsets = base + len(normals) * np.arange(len(g))
        triangles.append((tris[None] + offsets[:, None, None]).reshape(-1, 3))
        base += len(g) * len(normals)
    if not positions:
        return np.zeros((0, 3)), np.zeros((0, 4)), np.zeros((0, 3), dtype=np.int64)
    return (np.concatenate(positions).astype(np.float32), np.clip(np.concatenate(colours), 0.0, None).astype(np.float32),
            np.concatenate(triangles).astype(np.int32))


def _batch(path: str):
    """The GPU batch of the probe file's spheres, made once per file version."""
    import gpu
    from gpu_extras.batch import batch_for_shader
    mtime = os.path.getmtime(path)
    cached = _BATCH.get(path)
    if cached is None or cached[0] != mtime:
        shader = gpu.shader.from_builtin("SMOOTH_COLOR")
        pos, col, tris = spheres(grids_of(path))
        _BATCH.clear()
        _BATCH[path] = cached = (mtime, shader, batch_for_shader(shader, "TRIS", {"pos": pos, "color": col},
                                                                 indices=tris))
    return cached[1], cached[2]


def _draw() -> None:
    """POST_VIEW: the active scene's probes, when its toggle is on and its file is there."""
    scene = bpy.context.scene
    path = probe_file(scene)
    if path is None:
        return
    try:
        shader, batch = _batch(path)
    except Exception:  # noqa: BLE001 (a draw callback must not raise on every redraw)
        return
    import gpu
    gpu.state.depth_test_set("LESS_EQUAL")
    gpu.state.depth_mask_set(True)
    batch.draw(shader)
    gpu.state.depth_mask_set(False)
    gpu.state.depth_test_set("NONE")


def probe_file(scene) -> Optional[str]:
    """The probes.npz the viewport shows for `scene`: the output folder's, when Show Probes is on."""
    settings = getattr(scene, "detp_bake", None)
    if settings is None or not settings.show_probes:
        return None
    path = os.path.join(bpy.path.abspath(settings.output_directory), "probes.npz")
    return path if os.path.isfile(path) else None


def show(on: bool) -> None:
    """Add or remove the draw handler."""
    global _HANDLE
    if on and _HANDLE is None:
        _HANDLE = bpy.types.SpaceView3D.draw_handler_add(_draw, (), "WINDOW", "POST_VIEW")
    elif not on and _HANDLE is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_HANDLE, "WINDOW")
        _HANDLE = None
        _BATCH.clear()
    for window in getattr(bpy.context.window_manager, "windows", []):
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


def shown() -> bool:
    return _HANDLE is not None
