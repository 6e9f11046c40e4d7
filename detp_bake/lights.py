"""Photon emission for every light type, in the units Cycles uses (DESIGN.md §3).

Each light becomes an `Emitter` that knows its emitted flux (RGB watts) and can draw photons
(origin, direction, flux). Photons are shared out between emitters in proportion to their flux,
with deterministic counts (largest remainder), so every photon of one emitter carries about the
same flux and the total emitted flux is exact.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from . import sampling
from .errors import BakeError
from .scene import AreaLight, PointLight, Scene, SpotLight, SunLight

# sample(count, total_count, rng) -> origins (n,3), directions (n,3), flux per photon (n,3)
Sampler = Callable[[int, int, np.random.Generator], tuple[np.ndarray, np.ndarray, np.ndarray]]


@dataclass
class Emitter:
    name: str
    flux: np.ndarray  # RGB watts actually emitted
    sample: Sampler

    @property
    def weight(self) -> float:
        return float(np.mean(self.flux))


def spot_attenuation(cos_angle: np.ndarray, spot_size: float, blend: float) -> np.ndarray:
    """Cycles' spot falloff: smoothstep from the cone's rim over a `blend` share of (1 - cos)."""
    cos_half = np.cos(0.5 * spot_size)
    smooth = (1.0 - cos_half) * blend
    if smooth <= 0.0:
        return (cos_angle > cos_half).astype(np.float64)
    t = np.clip((cos_angle - cos_half) / smooth, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _spot_solid_angle(spot_size: float, blend: float) -> float:
    """∫ attenuation dω over the cone, by quadrature in cos θ."""
    cos_half = np.cos(0.5 * spot_size)
    if blend <= 0.0:
        return float(2.0 * np.pi * (1.0 - cos_half))
    c = np.linspace(cos_half, 1.0, 4097)
    att = spot_attenuation(c, spot_size, blend)
    return float(2.0 * np.pi * np.trapezoid(att, c)) if hasattr(np, "trapezoid") else \
        float(2.0 * np.pi * np.trapz(att, c))


def _uniform(n, rng, k):
    return rng.random((k, n))


def point_emitter(light: PointLight) -> Emitter:
    power = np.asarray(light.power, np.float64)
    pos = np.asarray(light.position, np.float64)

    def sample(n, total, rng):
        u = _uniform(n, rng, 4)
        if light.radius > 0.0:
            normal = sampling.uniform_sphere(u[0], u[1])
            origins = pos + light.radius * normal
            dirs = sampling.cosine_hemisphere(normal, u[2], u[3])
        else:
            origins = np.broadcast_to(pos, (n, 3)).copy()
            dirs = sampling.uniform_sphere(u[0], u[1])
        return origins, dirs, np.broadcast_to(power / total, (n, 3)).copy()

    return Emitter(light.name, power, sample)


def spot_emitter(light: SpotLight) -> Emitter:
    power = np.asarray(light.power, np.float64)
    pos = np.asarray(light.position, np.float64)
    axis = np.asarray(light.direction, np.float64)
    axis = axis / np.linalg.norm(axis)
    spot_size = min(float(light.spot_size), np.pi)
    cos_half = np.cos(0.5 * spot_size)
    cone = 2.0 * np.pi * (1.0 - cos_half)
    flux = power / (4.0 * np.pi) * _spot_solid_angle(spot_size, light.blend)

    def sample(n, total, rng):
        u = _uniform(n, rng, 2)
        dirs = sampling.uniform_cone(axis, cos_half, u[0], u[1])
        att = spot_attenuation(dirs @ axis, spot_size, light.blend)
        per = (power / (4.0 * np.pi) * cone / total)[None, :] * att[:, None]
        return np.broadcast_to(pos, (n, 3)).copy(), dirs, per

    return Emitter(light.name, flux, sample)


def sun_emitter(light: SunLight, centre: np.ndarray, radius: float) -> Emitter:
    """Photons start on a disc of the scene's bounding radius, outside the scene, facing the sun."""
    e = np.asarray(light.irradiance, np.float64)
    axis = np.asarray(light.direction, np.float64)
    axis = axis / np.linalg.norm(axis)
    flux = e * np.pi * radius ** 2
    cos_max = np.cos(0.5 * light.angle)

    def sample(n, total, rng):
        u = _uniform(n, rng, 4)
        if light.angle > 0.0:
            dirs = sampling.uniform_cone(axis, cos_max, u[2], u[3])
        else:
            dirs = np.broadcast_to(axis, (n, 3)).copy()
        # A disc perpendicular to each photon's own direction keeps the irradiance uniform.
        dx, dy = sampling.uniform_disc(u[0], u[1])
        t, s = sampling.orthonormal_basis(dirs)
        origins = centre + radius * (dx[:, None] * t + dy[:, None] * s) - 2.0 * radius * dirs
        return origins, dirs, np.broadcast_to(flux / total, (n, 3)).copy()

    return Emitter(light.name, flux, sample)


def area_emitter(light: AreaLight) -> Emitter:
    power = np.asarray(light.power, np.float64)
    m = np.asarray(light.matrix, np.float64)
    # Normals transform with the inverse transpose; the light faces local -Z.
    normal = np.linalg.inv(m[:3, :3]).T @ np.array([0.0, 0.0, -1.0])
    normal /= np.linalg.norm(normal)
    shape = light.shape.upper()
    if shape not in ("SQUARE", "RECTANGLE", "DISK", "ELLIPSE"):
        raise BakeError(f"area light '{light.name}' has unknown shape {light.shape}")
    sx = light.size_x
    sy = light.size_x if shape in ("SQUARE", "DISK") else light.size_y

    def sample(n, total, rng):
        u = _uniform(n, rng, 4)
        if shape in ("SQUARE", "RECTANGLE"):
            lx, ly = (u[0] - 0.5) * sx, (u[1] - 0.5) * sy
        else:
            dx, dy = sampling.uniform_disc(u[0], u[1])
            lx, ly = 0.5 * sx * dx, 0.5 * sy * dy
        local = np.stack([lx, ly, np.zeros(n), np.ones(n)], axis=1)
        origins = (local @ m.T)[:, :3]
        dirs = sampling.cosine_hemisphere(np.broadcast_to(normal, (n, 3)), u[2], u[3])
        return origins, dirs, np.broadcast_to(power / total, (n, 3)).copy()

    return Emitter(light.name, power, sample)


def mesh_emitter(scene: Scene, offset: float) -> Emitter | None:
    """Emissive triangles: Lambertian from BOTH faces, as Cycles emits (measured, DESIGN.md §3
    calibration), so each triangle emits 2·π·L·A. Photons start `offset` off the surface so they
    do not hit their own triangle."""
    lum = scene.emission.mean(axis=1)
    tri = np.flatnonzero(lum > 0.0)
    if tri.size == 0:
        return None
    p = scene.positions[tri].astype(np.float64)
    cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    keep = area > 0.0
    tri, p, cross, area = tri[keep], p[keep], cross[keep], area[keep]
    normal = cross / (2.0 * area[:, None])
    tri_flux = 2.0 * np.pi * scene.emission[tri].astype(np.float64) * area[:, None]
    flux = tri_flux.sum(axis=0)
    w = tri_flux.mean(axis=1)
    cdf = np.cumsum(w)
    cdf /= cdf[-1]
    total_w = w.sum()

    def sample(n, total, rng):
        u = _uniform(n, rng, 6)
        k = np.minimum(np.searchsorted(cdf, u[0], side="right"), len(cdf) - 1)
        b0, b1, b2 = sampling.uniform_triangle(u[1], u[2])
        side = np.where(u[5] < 0.5, 1.0, -1.0)[:, None]
        nrm = normal[k] * side
        origins = b0[:, None] * p[k, 0] + b1[:, None] * p[k, 1] + b2[:, None] * p[k, 2]
        origins += offset * nrm
        dirs = sampling.cosine_hemisphere(nrm, u[3], u[4])
        # Picked in proportion to mean flux: carry that triangle's RGB flux over its probability.
        per = tri_flux[k] * (total_w / w[k])[:, None] / total
        return origins, dirs, per

    return Emitter("emissive meshes", flux, sample)


def world_emitter(radiance: np.ndarray, centre: np.ndarray, radius: float) -> Emitter:
    """Uniform sky radiance L: a flux of L·πR²·4π crosses the bounding sphere inwards."""
    radiance = np.asarray(radiance, np.float64)
    flux = radiance * 4.0 * np.pi ** 2 * radius ** 2

    def sample(n, total, rng):
        u = _uniform(n, rng, 4)
        dirs = sampling.uniform_sphere(u[0], u[1])
        dx, dy = sampling.uniform_disc(u[2], u[3])
        t, s = sampling.orthonormal_basis(dirs)
        origins = centre + radius * (dx[:, None] * t + dy[:, None] * s) - 2.0 * radius * dirs
        return origins, dirs, np.broadcast_to(flux / total, (n, 3)).copy()

    return Emitter("world", flux, sample)


def build_emitters(scene: Scene) -> list[Emitter]:
    centre, radius = scene.bounds()
    out: list[Emitter] = []
    for light in scene.lights:
        if isinstance(light, PointLight):
            out.append(point_emitter(light))
        elif isinstance(light, SpotLight):
            out.append(spot_emitter(light))
        elif isinstance(light, SunLight):
            out.append(sun_emitter(light, centre, radius))
        elif isinstance(light, AreaLight):
            out.append(area_emitter(light))
        else:
            raise BakeError(f"unsupported light {light!r}")
    mesh = mesh_emitter(scene, 1e-5 * radius)
    if mesh is not None:
        out.append(mesh)
    if np.mean(scene.world) > 0.0:
        out.append(world_emitter(scene.world, centre, radius))
    out = [e for e in out if e.weight > 0.0 and np.all(np.asarray(e.flux) >= 0.0)]
    if not out:
        raise BakeError("the scene has no light: add a light, an emissive material or a world colour")
    return out


def allocate(emitters: list[Emitter], photons: int) -> np.ndarray:
    """Photon count per emitter ∝ flux; every emitter gets at least one photon."""
    w = np.array([e.weight for e in emitters], np.float64)
    share = w / w.sum() * photons
    counts = np.floor(share).astype(np.int64)
    rest = photons - counts.sum()
    order = np.argsort(-(share - counts), kind="stable")
    counts[order[:rest]] += 1
    return np.maximum(counts, 1)


class PhotonSchedule:
    """Photon i of the whole bake belongs to one emitter; batch j draws photons [j·B, (j+1)·B)."""

    def __init__(self, emitters: list[Emitter], photons: int, seed: int):
        self.emitters = emitters
        self.counts = allocate(emitters, photons)
        self.starts = np.concatenate([[0], np.cumsum(self.counts)])
        self.total = int(self.starts[-1])
        self.seed = seed

    @property
    def emitted_flux(self) -> np.ndarray:
        return np.sum([e.flux for e in self.emitters], axis=0)

    def batch(self, index: int, start: int, stop: int):
        rng = np.random.default_rng([self.seed, index])
        parts = []
        for e, a, b, total in zip(self.emitters, self.starts[:-1], self.starts[1:], self.counts):
            lo, hi = max(a, start), min(b, stop)
            if hi > lo:
                parts.append(e.sample(int(hi - lo), int(total), rng))
        origins, dirs, flux = (np.concatenate(x) for x in zip(*parts))
        return origins, dirs, flux
