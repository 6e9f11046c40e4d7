"""The first bounce of the shadowmask lights' light, for the final gather in the shadowmask's
subtract mode: the lightmaps then lack those lights' direct light, which a probe must still see
reflected off the surfaces around it (only the light reaching the probe straight from them goes
to `occlusion`). At each front-face hit of a gather ray on a baked surface, one shadow ray to each
masked light adds albedo · E/π of it there, in the ray's direction, as the lightmap would have held.
"""
from __future__ import annotations

import math

import numpy as np

from ..sampling import jit, photon_rng, uniform2
from ..transport.direct_lights import light_ray
from ..transport.textures import hit_uv, lookup
from .sh9 import add_sh


@jit
def bounce_points(o, d, prim, bu, bv, tfar, normals, albedo, alb_tex, tex_uvs, tex_pixels, tex_info, lm_of, eps,
                  hp, hn, ha, hk):
    """Front-face hits on baked surfaces: point (off the surface by eps), unit normal, albedo and
    the gather ray; returns how many."""
    m = 0
    for k in range(prim.shape[0]):
        t = prim[k]
        if t < 0 or lm_of[t] < 0:
            continue
        u, v = np.float64(bu[k]), np.float64(bv[k])
        w = 1.0 - u - v
        nx = w * normals[t, 0, 0] + u * normals[t, 1, 0] + v * normals[t, 2, 0]
        ny = w * normals[t, 0, 1] + u * normals[t, 1, 1] + v * normals[t, 2, 1]
        nz = w * normals[t, 0, 2] + u * normals[t, 1, 2] + v * normals[t, 2, 2]
        length = math.sqrt(nx * nx + ny * ny + nz * nz)
        if length <= 0.0 or nx * d[k, 0] + ny * d[k, 1] + nz * d[k, 2] > 0.0:
            continue
        nx, ny, nz = nx / length, ny / length, nz / length
        for c in range(3):
            hp[m, c] = o[k, c] + tfar[k] * d[k, c]
        hp[m, 0] += eps * nx
        hp[m, 1] += eps * ny
        hp[m, 2] += eps * nz
        hn[m, 0], hn[m, 1], hn[m, 2] = nx, ny, nz
        for c in range(3):
            ha[m, c] = albedo[t, c]
        if alb_tex[t] >= 0:
            ts, tq = hit_uv(tex_uvs, t, u, v)
            for c in range(3):
                ha[m, c] *= lookup(tex_pixels, tex_info, alb_tex[t], ts, tq, c)
        hk[m] = k
        m += 1
    return m


@jit
def bounce_rays(kind, prm, hp, hn, n, key, salt, o, d, t, w, owner):
    """One shadow ray from each hit point to a POINT, SUN or AREA light: the irradiance it adds."""
    m = 0
    for q in range(n):
        _, u0, u1 = uniform2(photon_rng(key, q * 104729 + salt))
        ok, dx, dy, dz, far, w0, w1, w2 = light_ray(kind, prm, hp[q, 0], hp[q, 1], hp[q, 2], hn[q, 0], hn[q, 1],
                                                    hn[q, 2], u0, u1, 1.0)
        if not ok or far <= 0.0:
            continue
        o[m, 0], o[m, 1], o[m, 2] = hp[q, 0], hp[q, 1], hp[q, 2]
        d[m, 0], d[m, 1], d[m, 2] = dx, dy, dz
        t[m] = far
        w[m, 0], w[m, 1], w[m, 2] = w0, w1, w2
        owner[m] = q
        m += 1
    return m


@jit
def add_bounce(m, occluded, w, owner, ha, hk, d, rays, scale, coeff):
    """Each arrived ray's albedo · E/π into its gather ray's probe, from that ray's direction."""
    for r in range(m):
        if occluded[r] >= 0:
            continue
        q = owner[r]
        k = hk[q]
        f = scale / math.pi
        add_sh(coeff, k // rays, np.float64(d[k, 0]), np.float64(d[k, 1]), np.float64(d[k, 2]),
               ha[q, 0] * w[r, 0] * f, ha[q, 1] * w[r, 1] * f, ha[q, 2] * w[r, 2] * f)


def add(lit, o, d, hit, rays, coeff, salt: int = 0) -> None:
    """The masked lights' first bounce, for one chunk's gather rays (gather._gather_chunk)."""
    masked = [lt for lt in lit.lights if lt.name in lit.masked]
    if not masked:
        return
    scene, sf, n = lit.scene, lit.surfaces, len(o)
    hp, hn, ha, hk = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3)), np.empty(n, np.int64)
    eps = scene.ray_offset()
    count = bounce_points(o, d, hit["primID"], hit["u"], hit["v"], hit["tfar"], scene.normals, scene.albedo,
                          sf.albedo_tex, sf.tex_uvs, sf.pixels, sf.info, lit.lm_of, eps, hp, hn, ha, hk)
    if not count:
        return
    for number, light in enumerate(masked):
        ro, rd = np.empty((count, 3), np.float32), np.empty((count, 3), np.float32)
        rt, rw, owner = np.empty(count, np.float32), np.empty((count, 3)), np.empty(count, np.int64)
        m = bounce_rays(light.kind, light.params, hp, hn, count, lit.key, salt + 7 * number, ro, rd, rt, rw, owner)
        if m:
            occluded = lit.caster.occluded(ro[:m], rd[:m], rt[:m])
            add_bounce(m, occluded, rw, owner, ha, hk, d, rays, 4.0 * math.pi / rays, coeff)
