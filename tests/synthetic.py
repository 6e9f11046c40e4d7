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
