"""Small analytic scenes built as plain arrays, for core tests without Blender."""
from __future__ import annotations

import numpy as np

from detp_bake.scene import BakeObject, Scene


def grid(size_x: float, size_y: float, n: int, z: float = 0.0, flip: bool = False):
    """A plane of 2·n² triangles at height z facing +Z (−Z with flip), UVs filling [0, 1]²."""
    xs = np.linspace(-size_x / 2, size_x / 2, n + 1)
    ys = np.linspace(-size_y / 2, size_y / 2, n + 1)
    us = np.linspace(0.0, 1.0, n + 1)
    tris, uvs = [], []
    for j in range(n):
        for i in range(n):
            p = [(xs[i], ys[j]), (xs[i + 1], ys[j]), (xs[i + 1], ys[j + 1]), (xs[i], ys[j + 1])]
            t = [(us[i], us[j]), (us[i + 1], us[j]), (us[i + 1], us[j + 1]), (us[i], us[j + 1])]
            for a, b, c in ((0, 1, 2), (0, 2, 3)):
                if flip:
                    b, c = c, b
                tris.append([[*p[a], z], [*p[b], z], [*p[c], z]])
                uvs.append([t[a], t[b], t[c]])
    pos = np.array(tris, float)
    normal = np.array([0.0, 0.0, -1.0 if flip else 1.0])
    return pos, np.broadcast_to(normal, pos.shape).copy(), np.array(uvs, float)


def shuffled_charts(size: float, cells: int, seed: int = 3):
    """grid(size, size, cells) with each cell's two triangles a UV chart of its own: the cells are
    dealt to the tiles of a cells × cells UV grid in random order, each turned by a random quarter
    turn, touching its neighbours (no padding), as a fragmented unwrap leaves them."""
    pos, nrm, uv = grid(size, size, cells)
    rng = np.random.default_rng(seed)
    tile = rng.permutation(cells * cells)
    turns = rng.integers(0, 4, cells * cells)
    out = np.empty_like(uv)
    for cell in range(cells * cells):
        i, j = cell % cells, cell // cells
        local = uv[2 * cell:2 * cell + 2] * cells - np.array([i, j]) - 0.5  # the cell, centred, side 1
        for _ in range(turns[cell]):
            local = np.stack([-local[..., 1], local[..., 0]], axis=-1)
        out[2 * cell:2 * cell + 2] = (local + 0.5 + np.array([tile[cell] % cells, tile[cell] // cells])) / cells
    return pos, nrm, out


def uv_sphere(radius: float, n_theta: int, n_phi: int, inward: bool = False):
    """A closed sphere; lightmap UVs are the (φ, θ) rectangle, shading normals radial."""
    th = np.linspace(0, np.pi, n_theta + 1)
    ph = np.linspace(0, 2 * np.pi, n_phi + 1)
    tris, uvs = [], []

    def pt(t, p):
        return [radius * np.sin(t) * np.cos(p), radius * np.sin(t) * np.sin(p), radius * np.cos(t)]

    for j in range(n_theta):
        for i in range(n_phi):
            q = [pt(th[j], ph[i]), pt(th[j], ph[i + 1]), pt(th[j + 1], ph[i + 1]), pt(th[j + 1], ph[i])]
            u = [(i / n_phi, 1 - j / n_theta), ((i + 1) / n_phi, 1 - j / n_theta),
                 ((i + 1) / n_phi, 1 - (j + 1) / n_theta), (i / n_phi, 1 - (j + 1) / n_theta)]
            for a, b, c in ((0, 2, 1), (0, 3, 2)):
                if inward:
                    b, c = c, b
                tri = [q[a], q[b], q[c]]
                if np.linalg.norm(np.cross(np.subtract(tri[1], tri[0]), np.subtract(tri[2], tri[0]))) < 1e-12:
                    continue
                tris.append(tri)
                uvs.append([u[a], u[b], u[c]])
    pos = np.array(tris, float)
    nrm = pos / np.linalg.norm(pos, axis=2, keepdims=True)
    if inward:
        nrm = -nrm
    # Inset UVs a little so the charts stay inside [0, 1].
    return pos, nrm, 0.02 + 0.96 * np.array(uvs, float)


def make_scene(parts, lights, albedo=0.5, world=(0.0, 0.0, 0.0), resolution=64, bounces=0):
    """parts: list of (name, (pos, nrm, uv), albedo or None, bake)."""
    pos, nrm, uv, alb, objs = [], [], [], [], []
    first = 0
    for name, (p, n, u), a, bake in parts:
        a = albedo if a is None else a
        pos.append(p)
        nrm.append(n)
        uv.append(u)
        alb.append(np.broadcast_to(np.asarray(a, float), (len(p), 3)))
        objs.append(BakeObject(name, first, len(p), resolution, bake))
        first += len(p)
    pos = np.concatenate(pos)
    return Scene(positions=pos, normals=np.concatenate(nrm), uvs=np.concatenate(uv),
                 albedo=np.concatenate(alb), emission=np.zeros((len(pos), 3)), objects=objs,
                 lights=list(lights), world=np.asarray(world, float), default_bounces=bounces)


def box(lo, hi):
    """A closed box from corner `lo` to corner `hi`, faces outward, each face its own UV chart."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    corner = np.array([[hi[0] if i & 1 else lo[0], hi[1] if i & 2 else lo[1], hi[2] if i & 4 else lo[2]]
                       for i in range(8)])
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    tris, nrm, uvs = [], [], []
    for k, q in enumerate(quads):
        p = corner[list(q)]
        n = np.cross(p[1] - p[0], p[2] - p[0])
        n /= np.linalg.norm(n)
        u0, v0 = (k % 3) / 3, (k // 3) / 2
        uv = np.array([[u0 + 0.02, v0 + 0.02], [u0 + 0.31, v0 + 0.02], [u0 + 0.31, v0 + 0.48], [u0 + 0.02, v0 + 0.48]])
        for a, b, c in ((0, 1, 2), (0, 2, 3)):
            tris.append(p[[a, b, c]])
            nrm.append([n] * 3)
            uvs.append(uv[[a, b, c]])
    return np.array(tris), np.array(nrm), np.array(uvs)


def joined(*meshes):
    """One mesh of several (positions, normals, UVs) triples."""
    return tuple(np.concatenate(part) for part in zip(*meshes))


def sealed_room(lights, world=(0.0, 0.0, 0.0), resolution=64, ground=16.0, half=1.0, wall=0.06, height=2.5,
                offset=(0.15, -0.08), bounces=4, ground_mesh=None):
    """A closed room (walls `wall` thick round a 2·`half` square, a roof; one object "Room", not
    baked) standing on a ground quad `ground` metres wide (object "Ground", baked), moved by `offset`
    off the texel grid: nothing from outside can reach the ground inside. The default offset puts a
    row of texel centres under the south wall nearer its outer face, and a column under the west
    wall nearer its inner face. `ground_mesh`: the ground's (positions, normals, UVs) instead of one
    chart (a square `ground` metres wide at height 0)."""
    h, t = half, wall
    walls = joined(box((-h - t, -h - t, 0), (h + t, -h, height)), box((-h - t, h, 0), (h + t, h + t, height)),
                   box((-h - t, -h, 0), (-h, h, height)), box((h, -h, 0), (h + t, h, height)),
                   box((-h - t, -h - t, height), (h + t, h + t, height + t)))
    walls = (walls[0] + np.array([offset[0], offset[1], 0.0]), walls[1], walls[2])
    ground_mesh = grid(ground, ground, 8) if ground_mesh is None else ground_mesh
    return make_scene([("Ground", ground_mesh, 0.5, True), ("Room", walls, 0.6, False)], lights,
                      world=world, resolution=resolution, bounces=bounces)
