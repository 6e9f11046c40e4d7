"""Photon emission for every light type, in the units Cycles uses (docs/design.md, Units).

Each light becomes an `Emitter` that knows its emitted flux (RGB watts) and can draw photons
(origin, direction, flux). Photons are shared out between emitters in proportion to their flux,
with deterministic counts (largest remainder, `allocate`; batch by batch in schedule.py), so every
photon of one emitter carries about the same flux and the total emitted flux is exact. One compiled
kernel emits every light type (the sun on a footprint, the sky and an HDRI world have their own,
footprint.py and environment.py); photon i draws its numbers from its own random stream
(`sampling.py`), so emission can run in pieces, in any order, on any thread.
"""
from __future__ import annotations

import numpy as np

from ..sampling import (cone_lobe, cosine_hemisphere, cosine_lobe, in_frame, inline, jit, orthonormal_basis,
    search_cdf, photon_rng, uniform2, uniform_disc, uniform_sphere, uniform_triangle)
from .emitter import Emitter
from .environment import environment_emitter
from ..errors import BakeError
from .footprint import Footprint, emit_sky, emit_sun, mean_sky_area
from ..scene import AreaLight, PointLight, Scene, SpotLight, SunLight

@inline
def spot_factor(c, cos_half, smooth):
    """A spot's factor at the cosine `c` to its axis: 0 outside the cone (cosine of its half angle
    `cos_half`), 1 inside, a smoothstep over `smooth` of cosine between (Cycles' spot blend)."""
    if smooth <= 0.0:
        return 1.0 if c > cos_half else 0.0
    t = min(max((c - cos_half) / smooth, 0.0), 1.0)
    return t * t * (3.0 - 2.0 * t)


@jit
def _spot_att_all(c, cos_half, smooth):
    out = np.empty_like(c)
    for i in range(c.shape[0]):
        out[i] = spot_factor(c[i], cos_half, smooth)
    return out


def spot_attenuation(cos_angle: np.ndarray, spot_size: float, blend: float) -> np.ndarray:
    """Cycles' spot falloff: smoothstep from the cone's rim over a `blend` share of (1 - cos)."""
    c = np.asarray(cos_angle, np.float64)
    cos_half = np.cos(0.5 * spot_size)
    return _spot_att_all(c.ravel(), cos_half, (1.0 - cos_half) * blend).reshape(c.shape)


def _spot_solid_angle(spot_size: float, blend: float) -> float:
    """∫ attenuation dω over the cone, by quadrature in cos θ."""
    cos_half = np.cos(0.5 * spot_size)
    if blend <= 0.0:
        return float(2.0 * np.pi * (1.0 - cos_half))
    c = np.linspace(cos_half, 1.0, 4097)
    att = spot_attenuation(c, spot_size, blend)
    return float(2.0 * np.pi * np.trapezoid(att, c)) if hasattr(np, "trapezoid") else \
        float(2.0 * np.pi * np.trapz(att, c))


def _frame(axis: np.ndarray) -> tuple:
    """(tangent, tangent, unit axis), each an (x, y, z) tuple: a constant frame for a kernel."""
    n = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    sign = 1.0 if n[2] >= 0.0 else -1.0  # as in sampling.orthonormal_basis
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    t = (1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0])
    s = (b, sign + n[1] * n[1] * a, -n[1])
    return tuple(map(float, t)), tuple(map(float, s)), tuple(map(float, n))


BLOCK = 256  # photons computed together: columns of a block vectorise, rows of (N, 3) arrays do not


@inline
def _block():
    """Scratch for one block: rows origin xyz, direction xyz, flux RGB; and random states."""
    return np.empty((9, BLOCK)), np.empty(BLOCK, np.uint64)


@inline
def _set(buf, row, k, x, y, z):
    buf[row, k] = x
    buf[row + 1, k] = y
    buf[row + 2, k] = z


@inline
def _flush(buf, state, a, b, o, d, f, rng):
    """Block rows a … b−1 into the (N, 3) outputs (and the states into `rng` unless empty)."""
    for i in range(a, b):
        k = i - a
        for c in range(3):
            o[i, c] = buf[c, k]
            d[i, c] = buf[3 + c, k]
            f[i, c] = buf[6 + c, k]
    if rng.shape[0] > 0:
        rng[a:b] = state[:b - a]


@inline
def _draw4(key, photon_id):
    """A photon's random state after four uniforms, and the uniforms."""
    r = photon_rng(key, photon_id)
    r, u0, u1 = uniform2(r)
    r, u2, u3 = uniform2(r)
    return r, u0, u1, u2, u3


# Light kinds. One compiled kernel (`_emit`) serves them all: a new kind adds a sampler, not a
# compile of its own.
POINT, SPOT, PARALLEL, AREA, MESH = range(5)
# A light's constants in one float64 vector (`_params`): a frame (tangent, tangent, axis), a
# position, the flux per photon (set per call: it depends on the photon count), three scalars
# (_A, _B, _C: see `_sample` for each kind's) and an area light's matrix, its top three rows.
_T, _S, _AXIS, _POS, _FLUX, _A, _B, _C, _M = 0, 3, 6, 9, 12, 15, 16, 17, 18
_SIZE = 30
# The triangle tables of `_emit`'s MESH kind, empty for the others: every call has the same types.
_NO_MESH = (np.empty(0), np.empty((0, 3, 3)), np.empty((0, 3)), np.empty((0, 3)))


def _params(frame=None, pos=None, a=0.0, b=0.0, c=0.0, m=None) -> np.ndarray:
    p = np.zeros(_SIZE)
    if frame is not None:
        p[_T:_T + 3], p[_S:_S + 3], p[_AXIS:_AXIS + 3] = frame
    if pos is not None:
        p[_POS:_POS + 3] = pos
    p[_A], p[_B], p[_C] = a, b, c
    if m is not None:
        p[_M:_M + 12] = np.asarray(m, np.float64)[:3].ravel()
    return p


def _with_flux(par: np.ndarray, flux: np.ndarray) -> np.ndarray:
    p = par.copy()
    p[_FLUX:_FLUX + 3] = flux
    return p


@inline
def _vec(par, at):
    return par[at], par[at + 1], par[at + 2]


@inline
def _point(key, photon_id, pos, radius, flux):
    """Uniform over a sphere of `radius`, cosine-weighted outwards; from `pos` when radius is 0."""
    r, u0, u1, u2, u3 = _draw4(key, photon_id)
    nx, ny, nz = uniform_sphere(u0, u1)
    if radius > 0.0:
        ox, oy, oz = pos[0] + radius * nx, pos[1] + radius * ny, pos[2] + radius * nz
        dx, dy, dz = cosine_hemisphere(nx, ny, nz, u2, u3)
    else:
        ox, oy, oz = pos
        dx, dy, dz = nx, ny, nz
    return r, ox, oy, oz, dx, dy, dz, flux[0], flux[1], flux[2]


@inline
def _spot(key, photon_id, pos, t, s, axis, cos_half, smooth, scale):
    """Uniform in the cone acos(cos_half) about the axis, attenuated by Cycles' blend."""
    r, u0, u1, u2, u3 = _draw4(key, photon_id)
    lx, ly, lz = cone_lobe(cos_half, u0, u1)
    dx, dy, dz = in_frame(lx, ly, lz, t, s, axis)
    att = spot_factor(lz, cos_half, smooth)
    return r, pos[0], pos[1], pos[2], dx, dy, dz, scale[0] * att, scale[1] * att, scale[2] * att


@inline
def _parallel(key, photon_id, t, s, axis, cos_max, centre, radius, flux):
    """A sun over a scene without triangles: directions within acos(cos_max) of the axis, starting
    on a disc of the scene's bounding radius perpendicular to their own direction, 2 radii out,
    which keeps the irradiance uniform. (Sky photons: footprint.emit_sky.)"""
    r, u0, u1, u2, u3 = _draw4(key, photon_id)
    if cos_max < 1.0:
        lx, ly, lz = cone_lobe(cos_max, u2, u3)
        dx, dy, dz = in_frame(lx, ly, lz, t, s, axis)
    else:
        dx, dy, dz = axis
    px, py = uniform_disc(u0, u1)
    t, s = orthonormal_basis(dx, dy, dz)
    return (r, centre[0] + radius * (px * t[0] + py * s[0]) - 2.0 * radius * dx,
            centre[1] + radius * (px * t[1] + py * s[1]) - 2.0 * radius * dy,
            centre[2] + radius * (px * t[2] + py * s[2]) - 2.0 * radius * dz,
            dx, dy, dz, flux[0], flux[1], flux[2])


@inline
def _area(key, photon_id, par):
    """Uniform over the rectangle (or ellipse: _C) _A × _B in the light's local XY plane, placed
    by its matrix (_M), cosine-weighted about the normal (the frame's axis). Read from `par` per
    photon: given as values, the matrix's multiply-adds fused otherwise, 1 ulp off before."""
    r, u0, u1, u2, u3 = _draw4(key, photon_id)
    sx, sy = par[_A], par[_B]
    if par[_C] != 0.0:
        px, py = uniform_disc(u0, u1)
        lx, ly = 0.5 * sx * px, 0.5 * sy * py
    else:
        lx, ly = (u0 - 0.5) * sx, (u1 - 0.5) * sy
    ox = par[_M] * lx + par[_M + 1] * ly + par[_M + 3]
    oy = par[_M + 4] * lx + par[_M + 5] * ly + par[_M + 7]
    oz = par[_M + 8] * lx + par[_M + 9] * ly + par[_M + 11]
    lx, ly, lz = cosine_lobe(u2, u3)
    dx, dy, dz = in_frame(lx, ly, lz, _vec(par, _T), _vec(par, _S), _vec(par, _AXIS))
    return r, ox, oy, oz, dx, dy, dz, par[_FLUX], par[_FLUX + 1], par[_FLUX + 2]


@inline
def _mesh(key, photon_id, cdf, p, normal, tri_flux, offset):
    """A triangle picked by `cdf`, a point uniform on it, a side at random, `offset` off the
    surface, cosine-weighted; tri_flux: each triangle's RGB flux over its probability and the
    photon count."""
    r, u0, u1, u2, u3 = _draw4(key, photon_id)
    r, u4, u5 = uniform2(r)
    lo = search_cdf(cdf, u0)
    b0, b1, b2 = uniform_triangle(u1, u2)
    side = 1.0 if u5 < 0.5 else -1.0
    nx, ny, nz = side * normal[lo, 0], side * normal[lo, 1], side * normal[lo, 2]
    ox = b0 * p[lo, 0, 0] + b1 * p[lo, 1, 0] + b2 * p[lo, 2, 0] + offset * nx
    oy = b0 * p[lo, 0, 1] + b1 * p[lo, 1, 1] + b2 * p[lo, 2, 1] + offset * ny
    oz = b0 * p[lo, 0, 2] + b1 * p[lo, 1, 2] + b2 * p[lo, 2, 2] + offset * nz
    dx, dy, dz = cosine_hemisphere(nx, ny, nz, u3, u4)
    return r, ox, oy, oz, dx, dy, dz, tri_flux[lo, 0], tri_flux[lo, 1], tri_flux[lo, 2]


@inline
def _put(buf, state, k, photon):
    """One sampler's photon (state, origin, direction, flux) into column k of the block."""
    _set(buf, 0, k, photon[1], photon[2], photon[3])
    _set(buf, 3, k, photon[4], photon[5], photon[6])
    _set(buf, 6, k, photon[7], photon[8], photon[9])
    state[k] = photon[0]


@jit
def _sample(kind, key, first, a, b, par, cdf, p, normal, tri_flux, buf, state):
    """Photons first + a … first + b − 1 into the block, by the kind's sampler, its constants
    read from `par` once (the block's stores could alias it: per photon, they would be reloaded).
    Unlike the skeleton (float32 or float64 outputs), this kernel sees the same types in every
    call, so the samplers compile once."""
    t, s, axis, pos, flux = _vec(par, _T), _vec(par, _S), _vec(par, _AXIS), _vec(par, _POS), _vec(par, _FLUX)
    pa, pb, pc = par[_A], par[_B], par[_C]
    if kind == POINT:
        for i in range(a, b):
            _put(buf, state, i - a, _point(key, first + i, pos, pa, flux))
    elif kind == SPOT:
        for i in range(a, b):
            _put(buf, state, i - a, _spot(key, first + i, pos, t, s, axis, pa, pb, flux))
    elif kind == PARALLEL:
        for i in range(a, b):
            _put(buf, state, i - a, _parallel(key, first + i, t, s, axis, pa, pos, pb, flux))
    elif kind == AREA:
        for i in range(a, b):
            _put(buf, state, i - a, _area(key, first + i, par))
    else:
        for i in range(a, b):
            _put(buf, state, i - a, _mesh(key, first + i, cdf, p, normal, tri_flux, pa))


@jit
def _emit(kind, key, first, n, par, cdf, p, normal, tri_flux, o, d, f, rng):
    """The Emit of every kind (`par`: _params; the triangle tables: MESH only), a block at a time;
    the kind is chosen per block, so each loop over a block holds one sampler."""
    buf, state = _block()
    for a in range(0, n, BLOCK):
        b = min(n, a + BLOCK)
        _sample(kind, key, first, a, b, par, cdf, p, normal, tri_flux, buf, state)
        _flush(buf, state, a, b, o, d, f, rng)


def point_emitter(light: PointLight) -> Emitter:
    power = np.asarray(light.power, np.float64)
    par = _params(pos=np.asarray(light.position, np.float64), a=float(light.radius))

    def emit(key, first, n, total, o, d, f, rng):
        _emit(POINT, key, first, n, _with_flux(par, power / total), *_NO_MESH, o, d, f, rng)

    return Emitter(light.name, power, emit)


def spot_emitter(light: SpotLight) -> Emitter:
    power = np.asarray(light.power, np.float64)
    axis = np.asarray(light.direction, np.float64)
    axis = axis / np.linalg.norm(axis)
    spot_size = min(float(light.spot_size), np.pi)
    cos_half = np.cos(0.5 * spot_size)
    cone = 2.0 * np.pi * (1.0 - cos_half)
    flux = power / (4.0 * np.pi) * _spot_solid_angle(spot_size, light.blend)
    par = _params(_frame(axis), np.asarray(light.position, np.float64), cos_half, (1.0 - cos_half) * light.blend)

    def emit(key, first, n, total, o, d, f, rng):
        scale = power / (4.0 * np.pi) * cone / total
        _emit(SPOT, key, first, n, _with_flux(par, scale), *_NO_MESH, o, d, f, rng)

    return Emitter(light.name, flux, emit)


def sun_emitter(light: SunLight, centre: np.ndarray, radius: float, positions: np.ndarray = None,
                margin: float = 0.0) -> Emitter:
    """Photons start outside the scene, facing the sun, on the scene's footprint across the sun's
    direction widened by `margin` metres (footprint.py), or on a disc of the bounding radius when
    there are no triangles."""
    e = np.asarray(light.irradiance, np.float64)
    axis = np.asarray(light.direction, np.float64)
    axis = axis / np.linalg.norm(axis)
    cos_max = float(np.cos(0.5 * light.angle)) if light.angle > 0.0 else 1.0
    centre = np.asarray(centre, np.float64)
    frame = _frame(axis)
    if positions is not None and len(positions):
        fp = Footprint.build(positions, axis, frame, centre, radius, 0.5 * float(light.angle), margin)
        flux = e * fp.area

        def emit(key, first, n, total, o, d, f, rng):
            emit_sun(key, first, n, frame, cos_max, fp.origin, fp.cell, fp.cells, flux / total, o, d, f, rng)

        return Emitter(light.name, flux, emit)
    flux = e * np.pi * radius ** 2
    par = _params(frame, centre, cos_max, float(radius))

    def emit(key, first, n, total, o, d, f, rng):
        _emit(PARALLEL, key, first, n, _with_flux(par, flux / total), *_NO_MESH, o, d, f, rng)

    return Emitter(light.name, flux, emit)


def area_emitter(light: AreaLight) -> Emitter:
    power = np.asarray(light.power, np.float64)
    m = np.ascontiguousarray(light.matrix, np.float64)
    # Normals transform with the inverse transpose, and inv(A)ᵀ·ẑ = (x × y) / det A for the
    # columns x, y of A (no LAPACK call, which would wake OpenBLAS threads that then spin for a
    # tenth of a second); the light faces local -Z.
    xy = np.cross(m[:3, 0], m[:3, 1])
    normal = -xy * np.sign(np.sum(xy * m[:3, 2]))  # det A = (x × y) · z
    normal /= np.linalg.norm(normal)
    shape = light.shape.upper()
    if shape not in ("SQUARE", "RECTANGLE", "DISK", "ELLIPSE"):
        raise BakeError(f"area light '{light.name}' has unknown shape {light.shape}")
    sx = float(light.size_x)
    sy = float(light.size_x if shape in ("SQUARE", "DISK") else light.size_y)
    disc = shape in ("DISK", "ELLIPSE")
    par = _params(_frame(normal), a=sx, b=sy, c=float(disc), m=m)

    def emit(key, first, n, total, o, d, f, rng):
        _emit(AREA, key, first, n, _with_flux(par, power / total), *_NO_MESH, o, d, f, rng)

    return Emitter(light.name, power, emit)


def emissive_triangles(scene: Scene):
    """(triangle indices, corners (n, 3, 3), unit normals, areas) of the emitting triangles with an
    area, or None when nothing emits."""
    tri = np.flatnonzero(np.abs(scene.emission).mean(axis=1) > 0.0)
    p = scene.positions[tri].astype(np.float64)
    cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    keep = area > 0.0
    if not keep.any():
        return None
    tri, p, cross, area = tri[keep], p[keep], cross[keep], area[keep]
    return tri, p, cross / (2.0 * area[:, None]), area


def mesh_emitter(scene: Scene, offset: float) -> Emitter | None:
    """Emissive triangles: Lambertian from BOTH faces, as Cycles emits (measured, docs/design.md, Units
    calibration), so each triangle emits 2·π·L·A. Photons start `offset` off the surface so they
    do not hit their own triangle."""
    found = emissive_triangles(scene)
    if found is None:
        return None
    tri, p, normal, area = found
    tri_flux = 2.0 * np.pi * scene.emission[tri].astype(np.float64) * area[:, None]
    flux = tri_flux.sum(axis=0)
    w = tri_flux.mean(axis=1)
    cdf = np.cumsum(w)
    cdf /= cdf[-1]
    # Picked in proportion to mean flux: a photon carries its triangle's RGB flux over its probability.
    per_pick = tri_flux * (w.sum() / w)[:, None]
    p, normal = np.ascontiguousarray(p), np.ascontiguousarray(normal)
    par = _params(a=float(offset))

    def emit(key, first, n, total, o, d, f, rng):
        _emit(MESH, key, first, n, par, cdf, p, normal, per_pick / total, o, d, f, rng)

    return Emitter("emissive meshes", flux, emit)


def world_emitter(radiance: np.ndarray, centre: np.ndarray, radius: float, lo=None, hi=None) -> Emitter:
    """Uniform sky radiance L. Photons start on the geometry's box [lo, hi] seen along their
    direction (footprint.sky_start): the flux L·4π·⟨area⟩ crosses it, the sky's share that can
    reach the scene. Without a box, the bounding sphere's disc (L·πR²·4π)."""

    radiance = np.asarray(radiance, np.float64)
    centre = np.asarray(centre, np.float64)
    lo = centre - radius if lo is None else np.asarray(lo, np.float64)
    hi = centre + radius if hi is None else np.asarray(hi, np.float64)
    flux = radiance * 4.0 * np.pi * mean_sky_area(lo, hi, centre, float(radius))

    def emit(key, first, n, total, o, d, f, rng):
        emit_sky(key, first, n, lo, hi, centre, float(radius), radiance * 4.0 * np.pi / total, o, d, f, rng)

    return Emitter("world", flux, emit)


def build_emitters(scene: Scene, margin: float = 0.0) -> list[Emitter]:
    """Every emitter of the scene; `margin` widens the sun's footprint (lights.sun_emitter) and the
    sky's box (footprint.sky_start)."""
    centre, radius = scene.bounds()
    out: list[Emitter] = []
    for light in scene.lights:
        if isinstance(light, PointLight):
            out.append(point_emitter(light))
        elif isinstance(light, SpotLight):
            out.append(spot_emitter(light))
        elif isinstance(light, SunLight):
            out.append(sun_emitter(light, centre, radius, scene.positions, margin))
        elif isinstance(light, AreaLight):
            out.append(area_emitter(light))
        else:
            raise BakeError(f"unsupported light {light!r}")
    mesh = mesh_emitter(scene, 1e-5 * radius)
    if mesh is not None:
        out.append(mesh)
    # Sky photons start on the geometry's box, widened as the sun's footprint is: DETP discs reach
    # past a surface's edge.
    lo, hi = (scene.positions.reshape(-1, 3).min(axis=0).astype(np.float64) - margin,
              scene.positions.reshape(-1, 3).max(axis=0).astype(np.float64) + margin) \
        if len(scene.positions) else (None, None)
    if scene.world_map is not None:
        out.append(environment_emitter(scene.world_map, centre, radius, lo, hi))
    elif np.mean(scene.world) > 0.0:
        out.append(world_emitter(scene.world, centre, radius, lo, hi))
    # A negative light (Cycles subtracts it) keeps its sign: its photons carry negative flux, which
    # every estimator and the Russian roulette (by albedo, not flux) treat linearly.
    out = [e for e in out if np.any(np.asarray(e.flux) != 0.0)]
    if not out:
        raise BakeError("the scene has no light: add a light, an emissive material or a world colour")
    return out


def allocate(emitters: list[Emitter], photons: int) -> np.ndarray:
    """Photon count per emitter ∝ |flux| (a negative light needs as many photons as a positive
    one of the same power); every emitter gets at least one photon."""
    w = np.abs(np.array([e.weight for e in emitters], np.float64))
    share = w / w.sum() * photons
    counts = np.floor(share).astype(np.int64)
    rest = photons - counts.sum()
    order = np.argsort(-(share - counts), kind="stable")
    counts[order[:rest]] += 1
    return np.maximum(counts, 1)
