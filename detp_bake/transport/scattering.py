"""What happens where a photon meets a surface: it passes a cut-out, or it lands, and is absorbed or
reflected diffusely with the albedo Cycles would use there.

Two compiled kernels over a stream's ray log (photons.py): `pass_through` lets a ray through a
surface with the probability of its transparency (Cycles treats alpha as stochastic transparency),
continuing it in a new ray from just past the surface; `bounce` records where the others land and
reflects them. The albedo is the triangle's constant, or that constant times its texture at the hit.

Where the photons bring the indirect light alone (shadow rays the direct: PhotonTracer's
indirect_only), every photon is reflected from its first landing, its flux times the albedo; from
the later ones, and from every landing otherwise, by Russian roulette with survival probability
q = max(albedo), its flux times albedo / q. Both keep the expected flux exact. The first landing is
where the roulette costs most there: a photon lost at it took a ray from the light for nothing, and
its landings' flux squared, summed, is q times what the roulette gives, so the same noise takes q
times the photons (`survival` sets the automatic count by it). On the arena-like level
(benchmarks/levels.py) that was 24 % fewer rays (docs/benchmarks.md, "The first bounce without
roulette"). Where the photons bring the direct light too, their first landings are that light and
are counted as they are; reflecting them all would make each photon dearer for the smaller part.
"""
from __future__ import annotations

import numpy as np

from ..sampling import cosine_hemisphere, jit, uniform2
from .textures import hit_uv, lookup, opacity_at

RAY_FAR = 1e37  # a ray's initial tfar: no limit
MAX_PASSES = 64  # cut-out surfaces one flight may pass before the next one stops it


def survival(albedo: np.ndarray, positions: np.ndarray) -> float:
    """The chance a photon goes on from a landing after its first: max(albedo) clipped to [0, 1],
    averaged over the surface by area (textures left out)."""
    a = np.clip(np.asarray(albedo, np.float64).reshape(-1, 3), 0.0, 1.0).max(axis=1) if len(albedo) else np.zeros(0)
    p = np.asarray(positions, np.float64).reshape(-1, 3, 3)
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    total = float(area.sum())
    return float(area @ a / total) if total > 0.0 else float(a.mean()) if len(a) else 0.0


def flights_per_photon(survival: float, bounces: int, first: int = 0, certain: bool = True) -> float:
    """Expected flights of one photon from flight `first` to flight `bounces` (flight 0 leaves the
    light; flight b ends its b-th reflection): with `certain`, the first reflection is certain where
    anything reflects; each other one survives the roulette with probability `survival`."""
    q = min(max(survival, 0.0), 1.0)
    last = min(int(bounces), 100_000)
    if q <= 0.0:
        return 1.0 if first == 0 else 0.0
    if q >= 1.0:
        return float(max(last + 1 - first, 0))
    lost = 1 if certain else 0  # reflections that do not meet the roulette
    return float(sum(q ** max(b - lost, 0) for b in range(first, last + 1)))


def material_table(albedo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-triangle index into a table of the distinct materials, rows (albedo RGB clipped to
    [0, 1], Russian-roulette survival probability q = max(albedo), albedo / q): a small table
    stays in cache where per-triangle rows would not."""
    a = np.clip(np.asarray(albedo, np.float64).reshape(-1, 3), 0.0, 1.0)
    if len(a) == 0:
        return np.zeros(0, np.int32), np.zeros((1, 7))
    table, index = np.unique(a, axis=0, return_inverse=True)
    q = table.max(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        carried = np.where(q[:, None] > 0.0, table / q[:, None], 0.0)
    dtype = np.uint16 if len(table) <= 65536 else np.int32
    return (np.ascontiguousarray(index.reshape(-1), dtype),
            np.ascontiguousarray(np.column_stack([table, q, carried])))


@jit
def pass_through(a, b, prim, bu, bv, through, o, d, f, length, rng, opacity, opacity_tex, tex_uvs, pixels,
                 info, eps):
    """Rays a … b−1 after Embree: each that hit a surface letting light through goes through with
    the probability 1 − opacity (`through[i]`: its segment ends there, and nothing lands), and
    continues as a new ray appended from b on, from just past the surface. Returns the new end."""
    w = b
    for i in range(a, b):
        through[i] = False
        t = prim[i]
        if t < 0:
            continue
        alpha = opacity_at(opacity, opacity_tex, tex_uvs, pixels, info, t, np.float64(bu[i]), np.float64(bv[i]))
        if alpha >= 1.0:
            continue
        state, u0, _ = uniform2(rng[i])
        rng[i] = state
        if u0 < alpha:
            continue
        through[i] = True
        step = np.float64(length[i]) + eps
        for c in range(3):
            o[w, c] = o[i, c] + step * d[i, c]
            d[w, c] = d[i, c]
            f[w, c] = f[i, c]
        length[w] = RAY_FAR
        rng[w] = state
        w += 1
    return w


@jit
def bounce(s, e, prim, ng, bu, bv, through, o, d, f, length, rng, hit_pos, hit_dir, hit_flux, hit_nrm, hit_tri,
           nh, material_of, materials, albedo_tex, tex_uvs, pixels, info, level, max_bounces, centre,
           escape_radius, eps, sums, certain):
    """Rays s … e−1 of one stream's log after Embree (and `pass_through`): segment lengths (Embree
    wrote the hit distances into `length`), hit records from `nh` on, and the diffuse reflection
    (from a first landing, `level` 0, certain when `certain`; else Russian roulette: module
    docstring), whose survivors are appended to the log from e on, with their random
    states. `materials` rows are (albedo RGB, survival probability q, albedo / q); a triangle with
    an albedo texture scales its row's albedo by the texture at the hit. `sums` rows gain the
    absorbed, escaped and truncated flux. Returns (end of the log, hit count, segments of
    positive length)."""
    w = e
    kept = 0
    r2 = escape_radius * escape_radius
    ab0 = ab1 = ab2 = es0 = es1 = es2 = tr0 = tr1 = tr2 = 0.0
    for i in range(s, e):
        ox, oy, oz = np.float64(o[i, 0]), np.float64(o[i, 1]), np.float64(o[i, 2])
        dx, dy, dz = np.float64(d[i, 0]), np.float64(d[i, 1]), np.float64(d[i, 2])
        f0, f1, f2 = np.float64(f[i, 0]), np.float64(f[i, 1]), np.float64(f[i, 2])
        t = prim[i]
        if t < 0:
            # Escapes: the segment runs to the far side of a sphere around the scene.
            cx, cy, cz = ox - centre[0], oy - centre[1], oz - centre[2]
            b = dx * cx + dy * cy + dz * cz
            disc = b * b - (cx * cx + cy * cy + cz * cz - r2)
            te = -b + np.sqrt(disc) if disc > 0.0 else 0.0
            length[i] = te if te > 0.0 else 0.0
            kept += length[i] > 0.0
            es0 += f0
            es1 += f1
            es2 += f2
            continue
        tf = np.float64(length[i])
        kept += tf > 0.0
        if through[i]:
            continue  # went on through a cut-out: its continuation is a later ray
        nx, ny, nz = np.float64(ng[i, 0]), np.float64(ng[i, 1]), np.float64(ng[i, 2])
        ln = np.sqrt(nx * nx + ny * ny + nz * nz)
        if ln > 0.0:
            inv = 1.0 / ln
            nx, ny, nz = nx * inv, ny * inv, nz * inv
        if nx * dx + ny * dy + nz * dz > 0.0:
            nx, ny, nz = -nx, -ny, -nz
        px, py, pz = ox + tf * dx, oy + tf * dy, oz + tf * dz
        hit_pos[nh, 0], hit_pos[nh, 1], hit_pos[nh, 2] = px, py, pz
        hit_dir[nh, 0], hit_dir[nh, 1], hit_dir[nh, 2] = d[i, 0], d[i, 1], d[i, 2]
        hit_flux[nh, 0], hit_flux[nh, 1], hit_flux[nh, 2] = f[i, 0], f[i, 1], f[i, 2]
        hit_nrm[nh, 0], hit_nrm[nh, 1], hit_nrm[nh, 2] = nx, ny, nz
        hit_tri[nh] = t
        nh += 1
        m = material_of[t]
        a0, a1, a2 = materials[m, 0], materials[m, 1], materials[m, 2]
        q, c0, c1, c2 = materials[m, 3], materials[m, 4], materials[m, 5], materials[m, 6]
        k = albedo_tex[t]
        if k >= 0:
            su, sv = hit_uv(tex_uvs, t, np.float64(bu[i]), np.float64(bv[i]))
            a0 = min(max(a0 * lookup(pixels, info, k, su, sv, 0), 0.0), 1.0)
            a1 = min(max(a1 * lookup(pixels, info, k, su, sv, 1), 0.0), 1.0)
            a2 = min(max(a2 * lookup(pixels, info, k, su, sv, 2), 0.0), 1.0)
            q = max(a0, max(a1, a2))
            if q > 0.0:
                c0, c1, c2 = a0 / q, a1 / q, a2 / q
        ab0 += f0 * (1.0 - a0)
        ab1 += f1 * (1.0 - a1)
        ab2 += f2 * (1.0 - a2)
        if level >= max_bounces:
            tr0 += f0 * a0
            tr1 += f1 * a1
            tr2 += f2 * a2
            continue
        state, u0, u1 = uniform2(rng[i])
        if level == 0 and certain:  # every photon reflected from its first landing, its flux times the albedo
            if q <= 0.0:
                continue
            c0, c1, c2 = a0, a1, a2
        elif u0 >= q:  # absorbed by Russian roulette (always when q = 0)
            continue
        state, u2, _ = uniform2(state)
        # Cosine-weighted direction about the face normal on the side the photon arrived.
        rx, ry, rz = cosine_hemisphere(nx, ny, nz, u1, u2)
        o[w, 0], o[w, 1], o[w, 2] = px + eps * nx, py + eps * ny, pz + eps * nz
        d[w, 0], d[w, 1], d[w, 2] = rx, ry, rz
        f[w, 0], f[w, 1], f[w, 2] = f0 * c0, f1 * c1, f2 * c2
        length[w] = RAY_FAR
        rng[w] = state
        w += 1
    sums[0, 0] += ab0
    sums[0, 1] += ab1
    sums[0, 2] += ab2
    sums[1, 0] += es0
    sums[1, 1] += es1
    sums[1, 2] += es2
    sums[2, 0] += tr0
    sums[2, 1] += tr1
    sums[2, 2] += tr2
    return w, nh, kept
