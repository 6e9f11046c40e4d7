"""The lights as the shadow-ray kernel reads them: a kind and a float64 parameter row each, with
how many rays it takes per texel (direct.py samples them). Units as in direct.py."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from ..errors import BakeError
from .lights import emissive_triangles
from ..scene import AreaLight, PointLight, Scene, SpotLight, SunLight

POINT, SUN, AREA, MESH, WORLD, WORLD_MAP = 0, 1, 2, 3, 4, 5
# Point, spot and sun lights: exact away from penumbrae (every ray agrees), even with a radius or an
# angle; area lights, emissive meshes and the world are noisy wherever they are partly hidden.
SHARP_KINDS = (POINT, SUN)
FIRST_SAMPLES = 4  # a point light's or sharp sun's first rays per texel, spread over its middle


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
