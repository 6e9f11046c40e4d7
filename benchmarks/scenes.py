"""Scenes the benchmark scripts share: the bundled Cornell box (through the Blender adapter) and a
deterministic ~100k-triangle room built with numpy alone."""
from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from detp_bake.scene import AreaLight, BakeObject, PointLight, Scene  # noqa: E402

SAMPLES = ROOT / "sample_scenes"


def blend_scene(name: str, resolution: int = 64) -> Scene:
    """sample_scenes/<name>.blend exported by the adapter, every visible mesh baked at
    `resolution`; the file stays open in bpy. Imports bpy, with Blender's user folder in a temp
    dir unless one is set already."""
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="detp_bench_blender_"))
    import bpy
    from detp_bake.blender import export_scene

    bpy.ops.wm.open_mainfile(filepath=str(SAMPLES / f"{name}.blend"))
    return export_scene(bpy.context.scene, bpy.context.evaluated_depsgraph_get(), None, None,
                        resolution, log=lambda msg: None)


def cornell_box(resolution: int = 64) -> Scene:
    """The bundled open-front Cornell box: 184 triangles, one 60 W area light."""
    return blend_scene("cornell_box", resolution)


def _quad_grid(corner, u_edge, v_edge, nu: int, nv: int, height=None):
    """nu·nv quads (2 triangles each) over corner + s·u_edge + t·v_edge, s, t in [0, 1], displaced
    along u × v by height(s, t) when given. Returns positions (2·nu·nv, 3, 3) and UVs in [0, 1]²
    with the same layout."""
    corner, u_edge, v_edge = (np.asarray(x, np.float64) for x in (corner, u_edge, v_edge))
    s, t = np.meshgrid(np.linspace(0, 1, nu + 1), np.linspace(0, 1, nv + 1), indexing="ij")
    p = corner + s[..., None] * u_edge + t[..., None] * v_edge
    if height is not None:
        n = np.cross(u_edge, v_edge)
        p = p + height(s, t)[..., None] * n / np.linalg.norm(n)
    uv = np.stack([s, t], axis=-1)
    quads = [(0, 0), (1, 0), (1, 1), (0, 1)]

    def corners(a):
        c = [a[i:nu + i, j:nv + j].reshape(-1, a.shape[-1]) for i, j in quads]
        return np.concatenate([np.stack([c[0], c[1], c[2]], 1), np.stack([c[0], c[2], c[3]], 1)])

    return corners(p), corners(uv)


def _box_faces(lo, hi, n: int, inward: bool = False):
    """The six faces of an axis-aligned box, each an n×n quad grid, normals out (in with inward)."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    d = hi - lo
    ex, ey, ez = np.diag(d)
    faces = [(lo, ey, ex), (lo + ez, ex, ey),  # -Z, +Z
             (lo, ex, ez), (lo + ey, ez, ex),  # -Y, +Y
             (lo, ez, ey), (lo + ex, ey, ez)]  # -X, +X
    if inward:
        faces = [(c, v, u) for c, u, v in faces]
    return [_quad_grid(c, u, v, n, n) for c, u, v in faces]


def _atlas(charts):
    """Concatenate charts (positions, UVs in [0, 1]²), each UV chart shrunk into its own cell of a
    square grid over [0, 1]² with a small gap: a non-overlapping lightmap layout for one object."""
    k = int(np.ceil(np.sqrt(len(charts))))
    cell, gap = 1.0 / k, 0.02 / k
    pos, uvs = [], []
    for i, (p, uv) in enumerate(charts):
        origin = np.array([i % k, i // k], np.float64) * cell + gap
        pos.append(p)
        uvs.append(origin + uv * (cell - 2 * gap))
    return np.concatenate(pos), np.concatenate(uvs)


def dense_room(triangles: int = 100_000) -> Scene:
    """A closed 8 × 6 × 3 m room with a bumpy height-field floor, subdivided walls and ceiling, and
    four subdivided boxes; about `triangles` triangles (half in the floor), albedo 0.5–0.7, lit by
    a 100 W area light under the ceiling and a 40 W point light. Deterministic; no bpy."""
    nf = max(2, int(round(np.sqrt(triangles * 0.5 / 2))))  # floor: 2·nf² triangles
    nw = max(1, int(round(np.sqrt(triangles * 0.2 / (5 * 2)))))  # 5 faces, 2·nw² each
    nb = max(1, int(round(np.sqrt(triangles * 0.3 / (4 * 6 * 2)))))  # 4 boxes of 6 faces
    size = np.array([8.0, 6.0, 3.0])

    def bumps(s, t):
        return 0.05 * np.sin(9 * s) * np.cos(7 * t) + 0.02 * np.sin(31 * s + 17 * t)

    objects = [("Floor", [_quad_grid((0, 0, 0), (size[0], 0, 0), (0, size[1], 0), nf, nf, bumps)], 0.6)]
    room = _box_faces((0, 0, -0.1), size, nw, inward=True)  # walls reach below the bumps
    objects.append(("Walls", room[1:], 0.7))  # the box's -Z face is replaced by the floor
    boxes = [((1.0, 1.0, 0.0), (2.2, 2.0, 1.0)), ((5.0, 1.5, 0.0), (6.5, 2.5, 2.0)),
             ((3.0, 3.8, 0.0), (4.0, 4.8, 0.6)), ((6.0, 4.0, 0.0), (7.2, 5.2, 1.4))]
    for i, (lo, hi) in enumerate(boxes):
        objects.append((f"Box{i}", _box_faces(lo, hi, nb), 0.5 + 0.05 * i))

    pos, uvs, alb, objs, first = [], [], [], [], 0
    for name, charts, albedo in objects:
        p, uv = _atlas(charts)
        pos.append(p)
        uvs.append(uv)
        alb.append(np.broadcast_to([albedo, albedo * 0.95, albedo * 0.9], (len(p), 3)))
        objs.append(BakeObject(name, first, len(p), resolution=256))
        first += len(p)
    pos = np.concatenate(pos)
    n = np.cross(pos[:, 1] - pos[:, 0], pos[:, 2] - pos[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    light = np.eye(4)
    light[:3, 3] = (4.0, 3.0, 2.9)  # faces local -Z: down
    lights = [AreaLight("Panel", light, "RECTANGLE", 1.5, 0.8, np.full(3, 100.0)),
              PointLight("Bulb", np.array([1.5, 4.5, 2.0]), np.full(3, 40.0))]
    return Scene(positions=pos, normals=np.repeat(n[:, None], 3, axis=1), uvs=np.concatenate(uvs),
                 albedo=np.concatenate(alb), emission=np.zeros((len(pos), 3)), objects=objs,
                 lights=lights, default_bounces=4)


def quiet_stdout():
    """Cycles prints a line per object and phase to the process's stdout (fd 1, from C): discard it
    while a bake runs (detp_bake.cli.output does the redirection)."""
    from detp_bake.cli.output import quiet_stdout as redirect
    return redirect(to="null")
