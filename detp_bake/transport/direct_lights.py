"""The lights as the shadow-ray kernel reads them: a kind and a float64 parameter row each, with
how many rays it takes per texel (direct.py samples them). Units as in direct.py."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numba
import numpy as np

from ..errors import BakeError
from .lights import emissive_triangles, spot_factor
from ..sampling import cone_lobe, in_frame, inline, orthonormal_basis, uniform_disc
from ..scene import AreaLight, PointLight, Scene, SpotLight, SunLight

POINT, SUN, AREA, MESH, WORLD, WORLD_MAP = 0, 1, 2, 3, 4, 5
# Point, spot and sun lights: exact away from penumbrae (every ray agrees), even with a radius or an
# angle; area lights, emissive meshes and the world are noisy wherever they are partly hidden.
SHARP_KINDS = (POINT, SUN)
FIRST_SAMPLES = 4  # a point light's or sharp sun's first rays per texel, from its square's corners
FAR = 1e37


@inline
def towards(sx, sy, sz, nx, ny, nz):
    """The unit direction to a point at offset (sx, sy, sz), its squared distance and distance, and
    its cosine with the normal n; all 0 when the offset is 0."""
    d2 = sx * sx + sy * sy + sz * sz
    if d2 <= 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    dist = math.sqrt(d2)
    dx, dy, dz = sx / dist, sy / dist, sz / dist
    return dx, dy, dz, d2, dist, dx * nx + dy * ny + dz * nz


@inline
def light_ray(kind, prm, ox, oy, oz, nx, ny, nz, u0, u1, inv_s):
    """One shadow ray from (ox, oy, oz), shading normal n, to a POINT, SUN or AREA light (its row
    `prm`; `u0`, `u1` pick the point of a light with extent): (ok, unit direction, far limit, RGB
    irradiance it adds unoccluded times `inv_s`); ok is False where it can add nothing (the light
    behind the surface, outside a spot's cone)."""
    dx = dy = dz = 0.0
    far = FAR
    if kind == POINT:
        cx, cy, cz = prm[0] - ox, prm[1] - oy, prm[2] - oz
        d2 = cx * cx + cy * cy + cz * cz
        dist = math.sqrt(d2)
        if dist <= 0.0:
            return False, dx, dy, dz, far, 0.0, 0.0, 0.0
        ax, ay, az = cx / dist, cy / dist, cz / dist  # towards the light's centre
        att = 1.0
        if prm[12] > 0.0:  # spot: the angle between its axis and the way to the texel
            att = spot_factor(-(ax * prm[7] + ay * prm[8] + az * prm[9]), prm[10], prm[11])
            if att <= 0.0:
                return False, dx, dy, dz, far, 0.0, 0.0, 0.0
        radius = prm[6]
        if radius > 0.0 and dist > radius:
            # A sphere: directions uniform in its cone, radiance P/(4π²r²) each.
            sin2 = radius * radius / d2
            cos_max = math.sqrt(max(0.0, 1.0 - sin2))
            lx, ly, lz = cone_lobe(cos_max, u0, u1)
            ts, ss = orthonormal_basis(ax, ay, az)
            dx, dy, dz = in_frame(lx, ly, lz, ts, ss, (ax, ay, az))
            cos_x = dx * nx + dy * ny + dz * nz
            if cos_x <= 0.0:
                return False, dx, dy, dz, far, 0.0, 0.0, 0.0
            # E = L·Ω·E[cos]; L·Ω = I/r² · (1 − cos_max)·2π/π = 2·I·(1 − cos_max)/r².
            scale = 2.0 * (1.0 - cos_max) / (radius * radius) * cos_x * att * inv_s
            # distance to the sphere along d (the near root)
            b_ = dx * cx + dy * cy + dz * cz
            disc = b_ * b_ - (d2 - radius * radius)
            far = b_ - math.sqrt(max(disc, 0.0))
        else:
            dx, dy, dz = ax, ay, az
            cos_x = dx * nx + dy * ny + dz * nz
            if cos_x <= 0.0:
                return False, dx, dy, dz, far, 0.0, 0.0, 0.0
            scale = cos_x / d2 * att * inv_s
            far = dist
        return True, dx, dy, dz, far, prm[3] * scale, prm[4] * scale, prm[5] * scale
    if kind == SUN:
        if prm[6] < 1.0:
            ts, ss = orthonormal_basis(prm[0], prm[1], prm[2])
            lx, ly, lz = cone_lobe(prm[6], u0, u1)
            dx, dy, dz = in_frame(lx, ly, lz, ts, ss, (prm[0], prm[1], prm[2]))
        else:
            dx, dy, dz = prm[0], prm[1], prm[2]
        cos_x = dx * nx + dy * ny + dz * nz
        if cos_x <= 0.0:
            return False, dx, dy, dz, far, 0.0, 0.0, 0.0
        scale = cos_x * inv_s
        return True, dx, dy, dz, far, prm[3] * scale, prm[4] * scale, prm[5] * scale
    # AREA
    if prm[17] > 0.0:
        qx, qy = uniform_disc(u0, u1)
        lx, ly = 0.5 * prm[15] * qx, 0.5 * prm[16] * qy
    else:
        lx, ly = (u0 - 0.5) * prm[15], (u1 - 0.5) * prm[16]
    dx, dy, dz, d2, dist, cos_x = towards(prm[0] * lx + prm[1] * ly + prm[3] - ox,
                                          prm[4] * lx + prm[5] * ly + prm[7] - oy,
                                          prm[8] * lx + prm[9] * ly + prm[11] - oz, nx, ny, nz)
    if d2 <= 0.0:
        return False, dx, dy, dz, far, 0.0, 0.0, 0.0
    cos_l = -(dx * prm[12] + dy * prm[13] + dz * prm[14])
    if cos_x <= 0.0 or cos_l <= 0.0:
        return False, dx, dy, dz, far, 0.0, 0.0, 0.0
    scale = cos_x * cos_l / d2 * inv_s
    return True, dx, dy, dz, dist, prm[18] * scale, prm[19] * scale, prm[20] * scale


@numba.njit(cache=True, nogil=True, inline="always")
def radical_inverse2(j):
    """Van der Corput in base 2: the second coordinate of a Hammersley set."""
    x = np.uint32(j)
    x = ((x << np.uint32(16)) | (x >> np.uint32(16)))
    x = ((x & np.uint32(0x55555555)) << np.uint32(1)) | ((x & np.uint32(0xAAAAAAAA)) >> np.uint32(1))
    x = ((x & np.uint32(0x33333333)) << np.uint32(2)) | ((x & np.uint32(0xCCCCCCCC)) >> np.uint32(2))
    x = ((x & np.uint32(0x0F0F0F0F)) << np.uint32(4)) | ((x & np.uint32(0xF0F0F0F0)) >> np.uint32(4))
    x = ((x & np.uint32(0x00FF00FF)) << np.uint32(8)) | ((x & np.uint32(0xFF00FF00)) >> np.uint32(8))
    return np.float64(x) * (1.0 / 4294967296.0)


@inline
def light_weight(kind, prm, px, py, pz, nx, ny, nz):
    """What a POINT, SUN or AREA light would give a point p with normal n unshadowed, roughly (a
    sphere or an area light as a point no closer than its size, a sun's axis; cosines floored at
    0.05 so that a light seen from part of a texel keeps a share): the weight rays are dealt by."""
    if kind == SUN:
        c = prm[0] * nx + prm[1] * ny + prm[2] * nz
        return (prm[3] + prm[4] + prm[5]) * max(c, 0.05)
    if kind == POINT:
        cx, cy, cz = prm[0] - px, prm[1] - py, prm[2] - pz
        size2 = prm[6] * prm[6]
        power = prm[3] + prm[4] + prm[5]
    else:  # AREA: its centre, its emitting side
        cx, cy, cz = prm[3] - px, prm[7] - py, prm[11] - pz
        size2 = 0.25 * prm[15] * prm[16]
        power = prm[18] + prm[19] + prm[20]
    d2 = cx * cx + cy * cy + cz * cz
    dist = math.sqrt(max(d2, 1e-300))
    c = (cx * nx + cy * ny + cz * nz) / dist
    if kind == AREA:
        c *= max(-(cx * prm[12] + cy * prm[13] + cz * prm[14]) / dist, 0.05)
    if kind == POINT and prm[12] > 0.0:
        c *= max(spot_factor(-(cx * prm[7] + cy * prm[8] + cz * prm[9]) / dist, prm[10], prm[11]), 0.05)
    return power * max(c, 0.05) / max(d2, size2)


@dataclass
class DirectLight:
    """One light as the shadow-ray kernel reads it: `kind`, a float64 parameter row, `samples`
    rays per texel, and for emissive meshes the triangle table."""
    name: str
    kind: int
    params: np.ndarray
    samples: int
    extra: int = 0  # a light without extent, spread: rays added where the first `samples` disagree
    tri_cdf: np.ndarray = None
    tri_pos: np.ndarray = None
    tri_normal: np.ndarray = None
    tri_radiance: np.ndarray = None  # per triangle, radiance × area / probability (RGB)
    env: tuple = None  # WORLD_MAP: the environment's sampling tables (environment.py)


def _row(*parts) -> np.ndarray:
    out = []
    for p in parts:
        out.extend(np.asarray(p, np.float64).ravel().tolist())
    row = np.zeros(32)
    row[:len(out)] = out
    return row


def direct_lights(scene: Scene, samples: int, spread: bool = True) -> list[DirectLight]:
    """The scene's emitters in the kernel's form. Param rows (float64[32]):
    POINT: position(3) intensity RGB(3) radius axis(3) cos_half smooth is_spot;
    SUN: towards-sun direction(3) irradiance(3) cos_max;
    AREA: matrix rows 0-2 (12) emitting normal(3) size_x size_y is_disc P/π RGB(3);
    WORLD: radiance(3). A point light or a sharp sun takes one ray per texel, or, spread over the
    texel's middle (`spread`), FIRST_SAMPLES rays and `samples` more where they disagree (a shadow
    edge or a spot's rim crosses the texel): four alone left those texels a quarter off Cycles'."""
    delta = min(samples, FIRST_SAMPLES) if spread else 1
    extra = samples if spread and samples > FIRST_SAMPLES else 0
    out = []
    for light in scene.lights:
        if isinstance(light, (PointLight, SpotLight)):
            intensity = np.asarray(light.power, np.float64) / (4.0 * np.pi)
            radius = float(light.radius)
            if isinstance(light, SpotLight):
                axis = np.asarray(light.direction, np.float64)
                axis = axis / np.linalg.norm(axis)
                half = 0.5 * min(float(light.spot_size), np.pi)
                cos_half = np.cos(half)
                spot = (axis, cos_half, (1.0 - cos_half) * float(light.blend), 1.0)
            else:
                spot = (np.zeros(3), -2.0, 0.0, 0.0)
            out.append(DirectLight(light.name, POINT, _row(light.position, intensity, radius, *spot),
                                   samples if radius > 0.0 else delta, 0 if radius > 0.0 else extra))
        elif isinstance(light, SunLight):
            d = np.asarray(light.direction, np.float64)
            d = -d / np.linalg.norm(d)
            cos_max = float(np.cos(0.5 * light.angle)) if light.angle > 0.0 else 1.0
            out.append(DirectLight(light.name, SUN, _row(d, light.irradiance, cos_max),
                                   samples if cos_max < 1.0 else delta, 0 if cos_max < 1.0 else extra))
        elif isinstance(light, AreaLight):
            m = np.asarray(light.matrix, np.float64)
            xy = np.cross(m[:3, 0], m[:3, 1])
            normal = -xy * np.sign(np.sum(xy * m[:3, 2]))  # faces local -Z, as lights.area_emitter
            normal /= np.linalg.norm(normal)
            shape = light.shape.upper()
            sx = float(light.size_x)
            sy = float(light.size_x if shape in ("SQUARE", "DISK") else light.size_y)
            disc = 1.0 if shape in ("DISK", "ELLIPSE") else 0.0
            out.append(DirectLight(light.name, AREA, _row(m[:3, :4], normal, sx, sy, disc,
                                                          np.asarray(light.power, np.float64) / np.pi),
                                   samples))
        else:
            raise BakeError(f"unsupported light {light!r}")
    mesh = _mesh_light(scene, samples)
    if mesh is not None:
        out.append(mesh)
    world = np.asarray(scene.world, np.float64)
    if scene.world_map is not None:
        pixels, marginal, cond, prob = scene.world_map.tables()
        light = DirectLight("world", WORLD_MAP, np.zeros(32), samples)
        light.env = (marginal, cond, prob, np.ascontiguousarray(scene.world_map.rotation, np.float64), pixels)
        out.append(light)
    elif np.any(world != 0.0):
        out.append(DirectLight("world", WORLD, _row(world), samples))
    return out


def _mesh_light(scene: Scene, samples: int) -> Optional[DirectLight]:
    found = emissive_triangles(scene)
    if found is None:
        return None
    tri, p, normal, area = found
    radiance = scene.emission[tri].astype(np.float64)
    w = np.abs(radiance).mean(axis=1) * area
    cdf = np.cumsum(w)
    total = cdf[-1]
    cdf /= total
    per_pick = radiance * (area * total / w)[:, None]  # radiance × area / probability
    return DirectLight("emissive meshes", MESH, np.zeros(32), samples, tri_cdf=np.ascontiguousarray(cdf),
                       tri_pos=np.ascontiguousarray(p), tri_normal=np.ascontiguousarray(normal),
                       tri_radiance=np.ascontiguousarray(per_pick))
