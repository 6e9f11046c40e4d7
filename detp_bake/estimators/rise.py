"""How far a texel's own surface rises in front of its tangent plane within its disc.

A DETP disc also counts segments that end a little short of its plane (discs.py, rule b), because
on a concave surface a photon that lands ρ from x ends ρ²/(2R) before the tangent plane. How much
short is enough depends only on the texel's own surface, so the bake measures it: for each texel,
the height above its tangent plane that the same connected piece of mesh (triangles welded by
shared vertex positions) reaches at the disc's rim, read from the piece's texels nearby. A flat leaf card gets
(almost) no slab, so the photons that landed on the leaf lying just in front of it are not counted
as if they had come through; a curved wall still gets what its curvature needs.

The search is a hashed uniform grid, one cell per disc diameter, in compiled code.
"""
from __future__ import annotations

import numba
import numpy as np

from ..components import connected_components
from ..lightmap.texels import TexelSet, lightmap_triangles

SMALL_PIECE = 64  # vertices: a piece this small is measured from its vertices when texels are too few


def _welded(positions: np.ndarray):
    """(piece per triangle, the welded vertices (V, 3) float64, piece per vertex)."""
    t = len(positions)
    if t == 0:
        return np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0, np.int64)
    corners = np.ascontiguousarray(positions.reshape(-1, 3))
    _, first, vertex = np.unique(corners.view(np.dtype((np.void, corners.dtype.itemsize * 3))).ravel(),
                                 return_index=True, return_inverse=True)
    vertex = vertex.reshape(t, 3)
    n = int(vertex.max()) + 1
    a = np.concatenate([vertex[:, 0], vertex[:, 1]])
    b = np.concatenate([vertex[:, 1], vertex[:, 2]])
    _, label = connected_components(n, a, b)
    return label[vertex[:, 0]].astype(np.int64), corners[first].astype(np.float64), label.astype(np.int64)


@numba.njit(cache=True, parallel=True)
def _rise_over_vertices(todo, position, normal, piece, start, vertices, out):
    """For the texels `todo`: the greatest height of their piece's vertices above their tangent
    plane. A planar triangle is highest at a vertex, so this bounds the piece's rise anywhere."""
    for k in numba.prange(todo.shape[0]):
        i = todo[k]
        p = piece[i]
        best = 0.0
        for v in range(start[p], start[p + 1]):
            h = ((vertices[v, 0] - position[i, 0]) * normal[i, 0] + (vertices[v, 1] - position[i, 1]) * normal[i, 1]
                 + (vertices[v, 2] - position[i, 2]) * normal[i, 2])
            if h > best:
                best = h
        out[i] = best


@numba.njit(cache=True)
def _cell_key(ix, iy, iz):
    # Any hash will do: texels of colliding cells are filtered by their true distance.
    return ix * np.int64(73856093) + iy * np.int64(19349663) + iz * np.int64(83492791)


@numba.njit(cache=True, parallel=True)
def _rise(position, normal, radius, piece, cell):
    n = len(radius)
    key = np.empty(n, np.int64)
    for i in range(n):
        key[i] = _cell_key(np.int64(np.floor(position[i, 0] / cell)), np.int64(np.floor(position[i, 1] / cell)),
                           np.int64(np.floor(position[i, 2] / cell)))
    order = np.argsort(key)
    sorted_key = key[order]
    out = np.empty(n)
    for i in numba.prange(n):
        x, y, z = position[i, 0], position[i, 1], position[i, 2]
        nx, ny, nz = normal[i, 0], normal[i, 1], normal[i, 2]
        r2 = radius[i] * radius[i]
        cx, cy, cz = np.int64(np.floor(x / cell)), np.int64(np.floor(y / cell)), np.int64(np.floor(z / cell))
        best = 0.0
        seen = False
        for dx in range(-1, 2):
            for dy in range(-1, 2):
                for dz in range(-1, 2):
                    k = _cell_key(cx + dx, cy + dy, cz + dz)
                    a = np.searchsorted(sorted_key, k)
                    while a < n and sorted_key[a] == k:
                        j = order[a]
                        a += 1
                        if piece[j] != piece[i]:
                            continue
                        ex, ey, ez = position[j, 0] - x, position[j, 1] - y, position[j, 2] - z
                        h = ex * nx + ey * ny + ez * nz
                        lateral2 = ex * ex + ey * ey + ez * ez - h * h
                        if lateral2 < 0.25 * r2 or lateral2 > 4.0 * r2:
                            continue
                        seen = True
                        # The height this surface reaches at the disc's rim, if it rises like a
                        # sphere or a cylinder (h ∝ ρ²); a crease (h ∝ ρ) only gets more slab.
                        rim = h * r2 / lateral2
                        if rim > best:
                            best = rim
        out[i] = best if seen else np.inf
    return out


def welded_pieces(texels: TexelSet, scene) -> list:
    """Per lightmap, its object's mesh welded into pieces (`_welded`): computed once, read by both
    piece_extent and own_surface_rise."""
    return [_welded(scene.positions[lightmap_triangles(scene, lm)]) for lm in texels.lightmaps]


def piece_extent(texels: TexelSet, scene, welds=None) -> np.ndarray:
    """Per texel: the radius of a disc with the area of its own welded piece of mesh, sqrt(A/π).

    A disc wider than the surface it lies on reads the light in the air around that surface. On a
    leaf card in a crown, where light falls steeply from the crown's shell inwards, that read the
    crowns' indirect light 2–3 % high with 3-texel discs (benchmarks/objects.py); discs no wider
    than their leaf take it under 1 %. Large pieces (walls, floors) are far wider than any disc.
    `welds`: welded_pieces, when the caller has them."""
    out = np.full(len(texels), np.inf)
    welds = welded_pieces(texels, scene) if welds is None else welds
    for lm, (tri_piece, _, _) in zip(texels.lightmaps, welds):
        sl = lm.texels
        own = lightmap_triangles(scene, lm)
        tris = scene.positions[own]
        if len(tris) == 0:
            continue
        area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
        piece_area = np.bincount(tri_piece, weights=area.astype(np.float64))
        out[sl] = np.sqrt(piece_area[tri_piece[np.searchsorted(own, texels.triangle[sl])]] / np.pi)
    return out


def own_surface_rise(texels: TexelSet, scene, radius: np.ndarray, welds=None) -> np.ndarray:
    """Per texel: how high its own surface rises in front of its tangent plane at `radius`: from
    the texels of its own lightmap on the same piece of its object's mesh, between r/2 and 2r
    away, each one's height carried to the rim as h·r²/ρ² (exact on spheres and cylinders, more
    than enough at creases). 0 on a flat piece. Where no such texel exists (a leaf of a texel or
    two, or texels sparser than the disc), a piece of at most SMALL_PIECE vertices gives the
    height of its highest vertex; a larger one inf: the bake then keeps the full slab. `welds`:
    welded_pieces, when the caller has them."""
    out = np.full(len(texels), np.inf)
    welds = welded_pieces(texels, scene) if welds is None else welds
    for lm, (tri_piece, vertices, vertex_piece) in zip(texels.lightmaps, welds):
        sl = lm.texels
        r = np.ascontiguousarray(radius[sl], np.float64)
        if r.size == 0 or not np.isfinite(r).all() or r.max() <= 0.0:
            continue
        piece = np.ascontiguousarray(tri_piece[np.searchsorted(lightmap_triangles(scene, lm), texels.triangle[sl])])
        position = np.ascontiguousarray(texels.position[sl], np.float64)
        normal = np.ascontiguousarray(texels.normal[sl], np.float64)
        part = _rise(position, normal, r, piece, 2.0 * float(r.max()))
        by_piece = np.argsort(vertex_piece, kind="stable")
        count = np.bincount(vertex_piece, minlength=int(tri_piece.max()) + 1)
        start = np.concatenate([[0], np.cumsum(count)]).astype(np.int64)
        todo = np.flatnonzero(np.isinf(part) & (count[piece] <= SMALL_PIECE)).astype(np.int64)
        if todo.size:
            _rise_over_vertices(todo, position, normal, piece, start, np.ascontiguousarray(vertices[by_piece]), part)
        out[sl] = part
    return out
