"""Atlases: the UV charts of many objects packed into a few shared lightmaps at one texel density.

Baked one lightmap each, a level of many objects spends its texels badly: each lightmap is rounded
up to a size of its own, small objects get as many texels as big ones or blurry light, and an
engine has one texture per object to bind. Packed together (xatlas), small objects fill the gaps
between big ones, and every texel has the same size in the world: `density` texels per metre,
times an object's own `scale`.

Each object lies in one atlas, so that it has one image to wire into its materials: the objects are
shared out by area (largest first, each into the first atlas with room for it at FILL), each atlas
is packed by xatlas on its own, and an atlas xatlas cannot fit in one image hands its smallest
object on to the next. An object too big for a whole atlas at the density is packed at a lower
density of its own, and the packing says so (`Packing.warnings`).

Charts are xatlas's own (cut by the geometry), or with `keep` the islands of the object's existing
lightmap UVs, only scaled to the density, turned and placed.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from ..errors import BakeError

FILL = 0.7  # of an atlas's texels that charts may take when objects are shared out (padding, gaps)
SHRINK = 0.8  # an object that fills an atlas alone is tried again at this share of its density


@dataclass
class Mesh:
    """One object's triangles in world space (metres) and, to keep its islands, its lightmap UVs."""
    name: str
    positions: np.ndarray  # (T, 3, 3)
    uvs: Optional[np.ndarray] = None  # (T, 3, 2): the islands to keep; None: xatlas's own charts
    scale: float = 1.0  # multiplies the density on this object

    def area(self) -> float:
        p = np.asarray(self.positions, np.float64)
        return float(0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum())


@dataclass
class Placed:
    """Where an object's charts went: its atlas and the UVs of its triangles' corners in it."""
    atlas: int
    uvs: np.ndarray  # (T, 3, 2) float32, in 0..1 of the atlas
    density: float  # texels per metre it got (its UV area in texels over its world area, square-rooted)


@dataclass
class Packing:
    size: int  # the largest atlas side asked for
    objects: dict  # {object name: Placed}
    count: int = 0
    warnings: list = field(default_factory=list)
    sizes: list = field(default_factory=list)  # each atlas's side: `size`, or less where its charts leave room

    def fill(self, covered: int, atlas: int) -> float:
        return covered / float(self.sizes[atlas] ** 2)

    def name(self, atlas: int) -> str:
        return f"atlas_{atlas}"

    def members(self) -> dict:
        """{atlas name: [object names]} in packing order."""
        out: dict = {}
        for obj, placed in self.objects.items():
            out.setdefault(self.name(placed.atlas), []).append(obj)
        return dict(sorted(out.items(), key=lambda kv: int(kv[0].split("_")[1])))


def _weld(mesh: Mesh, keep: bool) -> tuple[np.ndarray, np.ndarray, Optional[np.ndarray]]:
    """Shared vertices for xatlas (it finds charts by what triangles share): corners with the same
    position (and, keeping islands, the same UV) become one vertex."""
    pos = np.asarray(mesh.positions, np.float64).reshape(-1, 3)
    keys = pos if not keep else np.c_[pos, np.asarray(mesh.uvs, np.float64).reshape(-1, 2)]
    _, first, index = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    uv = None if not keep else np.ascontiguousarray(np.asarray(mesh.uvs, np.float32).reshape(-1, 2)[first])
    return (np.ascontiguousarray(pos[first] * mesh.scale, np.float32),
            np.ascontiguousarray(index.reshape(-1, 3), np.uint32), uv)


def _block(mesh: Mesh) -> tuple[Mesh, np.ndarray]:
    """A stand-in for `mesh` packed whole: a rectangle of the world size its UV layout's bounding
    box has at the mesh's own metres per UV unit; and that box (u0, v0, u1, v1)."""
    uv = np.asarray(mesh.uvs, np.float64)
    lo, hi = uv.reshape(-1, 2).min(axis=0), uv.reshape(-1, 2).max(axis=0)
    e = uv[:, 1:] - uv[:, :1]
    uv_area = 0.5 * np.abs(e[:, 0, 0] * e[:, 1, 1] - e[:, 0, 1] * e[:, 1, 0]).sum()
    metres = np.sqrt(mesh.area() / uv_area) if uv_area > 0 else 0.0
    w, h = (hi - lo) * metres
    quad = np.array([[[0, 0, 0], [w, 0, 0], [w, h, 0]], [[0, 0, 0], [w, h, 0], [0, h, 0]]], np.float64)
    box = np.array([[[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]]], [[lo[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]]])
    return Mesh(mesh.name, quad, box, mesh.scale), np.r_[lo, hi]


def _placed_block(mesh: Mesh, box: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """The mesh's UVs carried into its packed stand-in (`corners`, (2, 3, 2)): the affine map of its
    bounding box onto the rectangle xatlas placed (and may have turned)."""
    c0, c1, c3 = corners[0, 0].astype(np.float64), corners[0, 1].astype(np.float64), corners[1, 2].astype(np.float64)
    uv = np.asarray(mesh.uvs, np.float64)
    s = (uv[..., 0:1] - box[0]) / max(box[2] - box[0], 1e-12)
    t = (uv[..., 1:2] - box[1]) / max(box[3] - box[1], 1e-12)
    return (c0 + s * (c1 - c0) + t * (c3 - c0)).astype(np.float32)


def _pack(meshes: list, density: float, size: int, padding: int, keep: bool, whole: bool = False) -> tuple[int, list]:
    """(atlases xatlas needed, [(T, 3, 2) corner UVs per mesh]) of `meshes` packed together."""
    if whole:
        blocks = [_block(m) for m in meshes]
        count, uvs = _pack_charts([b for b, _ in blocks], density, size, padding, True, brute=True)
        return count, [_placed_block(m, box, c) for m, (_, box), c in zip(meshes, blocks, uvs)]
    return _pack_charts(meshes, density, size, padding, keep)


def _pack_charts(meshes: list, density: float, size: int, padding: int, keep: bool,
                 brute: bool = False) -> tuple[int, list]:
    """One xatlas run over `meshes`: (atlases it needed, [(T, 3, 2) corner UVs per mesh]). First
    with the atlas's size left to xatlas (tightest), again at `size` when that is too big."""
    count, side, uvs = _run(meshes, density, 0, padding, keep, brute)
    if count == 1 and side <= size:
        return 1, [u * np.float32(side / size) for u in uvs]
    count, _, uvs = _run(meshes, density, size, padding, keep, brute)
    return count, uvs


def _run(meshes: list, density: float, size: int, padding: int, keep: bool, brute: bool = False) -> tuple[int, int, list]:
    import xatlas

    atlas = xatlas.Atlas()
    for mesh in meshes:
        vertices, index, uv = _weld(mesh, keep and mesh.uvs is not None)
        atlas.add_mesh(vertices, index, None, uv)
    charts = xatlas.ChartOptions()
    charts.use_input_mesh_uvs = keep
    pack = xatlas.PackOptions()
    pack.resolution = int(size)  # 0: as small as the charts allow
    pack.texels_per_unit = float(density)
    pack.padding = int(padding)
    pack.bilinear = True
    pack.bruteForce = bool(brute)  # every position tried: slow per chart, worth it for a few whole layouts
    atlas.generate(charts, pack)
    out = []
    for i, mesh in enumerate(meshes):
        _, index, uv = atlas.get_mesh(i)
        corners = np.asarray(uv, np.float32)[np.asarray(index, np.int64)]
        out.append(corners.reshape(len(mesh.positions), 3, 2))
    side = max(int(atlas.width), int(atlas.height))
    if side != atlas.width or side != atlas.height:  # square: UVs in 0..1 of the larger side
        for corners in out:
            corners[..., 0] *= np.float32(atlas.width / side)
            corners[..., 1] *= np.float32(atlas.height / side)
    return int(atlas.atlas_count), side, out


def _density(mesh: Mesh, uvs: np.ndarray, size: int) -> float:
    uv = uvs.astype(np.float64) * size
    uv_area = 0.5 * np.abs((uv[:, 1, 0] - uv[:, 0, 0]) * (uv[:, 2, 1] - uv[:, 0, 1])
                           - (uv[:, 1, 1] - uv[:, 0, 1]) * (uv[:, 2, 0] - uv[:, 0, 0])).sum()
    area = mesh.area()
    return float(np.sqrt(uv_area / area)) if area > 0 else 0.0


def _trimmed(uvs: list, size: int, padding: int) -> int:
    """The side of the square, from the origin, that holds an atlas's charts and their padding (a
    multiple of 4, at most `size`): an atlas that is not full is cut down to it."""
    extent = max(float(np.max(u)) for u in uvs) * size if uvs else 0.0
    return int(min(size, max(4, 4 * np.ceil((np.ceil(extent) + padding) / 4))))


def _bins(meshes: list, density: float, size: int) -> list:
    """The objects shared out among atlases by the texels they need, largest first (first fit)."""
    room = FILL * size * size
    need = {m.name: m.area() * (density * m.scale) ** 2 for m in meshes}
    bins: list = []
    for mesh in sorted(meshes, key=lambda m: -need[m.name]):
        for b in bins:
            if sum(need[m.name] for m in b) + need[mesh.name] <= room:
                b.append(mesh)
                break
        else:
            bins.append([mesh])
    return bins


def pack(meshes: list, density: float, size: int, padding: int = 2, keep: bool = False,
         whole: bool = False) -> Packing:
    """Pack `meshes` (Mesh) into atlases of size × size texels at `density` texels per metre: their
    own charts (keep: their UV islands, one by one; whole: each one's UV layout as one block)."""
    if not density > 0:
        raise BakeError(f"setting 'texel_density' must be positive, got {density}")
    names = [m.name for m in meshes]
    if len(set(names)) != len(names):
        raise BakeError("atlas: two objects have the same name")
    for m in meshes:
        if m.area() <= 0:
            raise BakeError(f"object '{m.name}': it has no surface to give texels to")
    out = Packing(int(size), {})
    queue = _bins(meshes, density, size)
    while queue:
        group = queue.pop(0)
        count, uvs = _pack(group, density, size, padding, keep, whole and all(m.uvs is not None for m in group))
        if count > 1 and len(group) > 1:  # hand the smallest on to the next atlas
            rest = group.pop()
            if queue:
                queue[0].append(rest)
            else:
                queue.append([rest])
            queue.insert(0, group)
            continue
        if count > 1:  # one object too big for an atlas: a density of its own
            mesh = group[0]
            queue.insert(0, [Mesh(mesh.name, mesh.positions, mesh.uvs, mesh.scale * SHRINK)])
            continue
        side = _trimmed(uvs, size, padding)
        out.sizes.append(side)
        for mesh, corner in zip(group, uvs):
            corner *= np.float32(size / side)
            got = _density(mesh, corner, side)
            out.objects[mesh.name] = Placed(out.count, corner, got)
            asked = density * next(m.scale for m in meshes if m.name == mesh.name)
            if got < 0.9 * asked:
                out.warnings.append(f"object '{mesh.name}': too big for one {size}x{size} atlas at {asked:g} texels "
                                    f"per metre; packed at {got:.3g}: raise the atlas size or lower its density")
        out.count += 1
    out.objects = {n: out.objects[n] for n in names}
    return out
