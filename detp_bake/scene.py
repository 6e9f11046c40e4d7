"""Plain scene data: what the photon tracer and the texel rasteriser need, and nothing of Blender.

The Blender adapter (the `blender` package) fills these dataclasses; tests build them by hand. All
geometry is in world space, metres; colours are linear RGB; powers are watts as Cycles reads them
(docs/design.md, Units; `lights.py` holds the exact conventions).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Optional, Union

import numpy as np

from .errors import BakeError


@dataclass
class PointLight:
    """Isotropic: intensity power/(4π) W/sr. radius > 0 makes it a sphere light of the same power
    (Cycles' point light with Soft Falloff off; with it on, Cycles is d²/(d²+r²) dimmer nearby)."""
    name: str
    position: np.ndarray
    power: np.ndarray  # RGB watts
    radius: float = 0.0


@dataclass
class SpotLight:
    """A point light's intensity inside a cone around `direction`, smoothed by `blend` at its rim."""
    name: str
    position: np.ndarray
    direction: np.ndarray  # unit axis of the cone, the way light travels
    power: np.ndarray
    spot_size: float  # full cone angle, radians
    blend: float = 0.0
    radius: float = 0.0


@dataclass
class SunLight:
    """Parallel light: `irradiance` W/m² on a surface facing it; `angle` is the disc's full angle."""
    name: str
    direction: np.ndarray  # unit, the way light travels
    irradiance: np.ndarray
    angle: float = 0.0


@dataclass
class AreaLight:
    """One-sided Lambertian emitter facing the local -Z axis of `matrix`; emits exactly `power`."""
    name: str
    matrix: np.ndarray  # 4x4 world matrix (scale included)
    shape: str  # SQUARE, RECTANGLE, DISK, ELLIPSE
    size_x: float
    size_y: float
    power: np.ndarray


Light = Union[PointLight, SpotLight, SunLight, AreaLight]

# Beyond these a setting is a typing slip, not a scene (FLT_MAX is what Blender stores for "inf"
# in most fields): a sun 10⁶ km away still needs under 10²⁰ W as a point light.
MAX_POWER = 1e20  # W, or W/m² for a sun
MAX_SIZE = 1e9  # m


def _finite(light, setting: str, value, unit: str = "", limit: Optional[float] = None, low=None) -> np.ndarray:
    v = np.asarray(value, np.float64)
    if np.isnan(v).any():
        raise BakeError(f"light '{light.name}': {setting} is not a number")
    if np.isinf(v).any():
        raise BakeError(f"light '{light.name}': {setting} is infinite")
    if limit is not None and v.size and np.abs(v).max() > limit:
        raise BakeError(f"light '{light.name}': {setting} {np.abs(v).max():.3g}{unit} is absurd "
                        f"(more than {limit:.0e}{unit})")
    if low is not None and v.size and v.min() < low:
        raise BakeError(f"light '{light.name}': {setting} {v.min():.3g}{unit} is below {low:g}{unit}")
    return v


def check_light(light: "Light") -> None:
    """BakeError naming the light and the setting when a value is NaN, infinite or absurd.
    Negative power is allowed: Cycles subtracts such a light, and so do the photons."""
    if isinstance(light, SunLight):
        _finite(light, "strength", light.irradiance, " W/m²", MAX_POWER)
        _finite(light, "angle", light.angle, " rad", low=0.0)
        if light.angle > np.pi + 1e-6:
            raise BakeError(f"light '{light.name}': angle {light.angle:.3g} rad is more than π")
    else:
        _finite(light, "power", light.power, " W", MAX_POWER)
    if isinstance(light, (PointLight, SpotLight)):
        _finite(light, "position", light.position, " m", MAX_SIZE)
        _finite(light, "radius", light.radius, " m", MAX_SIZE, low=0.0)
    if isinstance(light, (SpotLight, SunLight)):
        d = _finite(light, "direction", light.direction)
        if not np.linalg.norm(d) > 0.0:
            raise BakeError(f"light '{light.name}': its direction is zero (a zero scale?)")
    if isinstance(light, SpotLight):
        size = float(_finite(light, "spot size", light.spot_size, " rad"))
        if not 0.0 < size <= np.pi + 1e-6:
            raise BakeError(f"light '{light.name}': spot size {size:.3g} rad is not in (0, π]")
        blend = float(_finite(light, "spot blend", light.blend))
        if not 0.0 <= blend <= 1.0:
            raise BakeError(f"light '{light.name}': spot blend {blend:.3g} is not in [0, 1]")
    if isinstance(light, AreaLight):
        m = _finite(light, "transform", light.matrix, "", MAX_SIZE)
        _finite(light, "size", (light.size_x, light.size_y), " m", MAX_SIZE, low=0.0)
        if m.shape != (4, 4) or not np.linalg.norm(np.cross(m[:3, 0], m[:3, 1])) > 0.0:
            raise BakeError(f"light '{light.name}': its transform has a zero scale")
        if light.shape.upper() not in ("SQUARE", "RECTANGLE", "DISK", "ELLIPSE"):
            raise BakeError(f"light '{light.name}': unknown area shape '{light.shape}'")


@dataclass
class ProbeVolume:
    """A Light Probe Volume: probes at the cell centres of the unit cube [−1, 1]³ under `matrix`,
    cut into `resolution` (x, y, z) cells (probes/placement.py)."""
    name: str
    matrix: np.ndarray  # 4x4 world matrix
    resolution: tuple


@dataclass
class BakeObject:
    """A run of consecutive triangles that belongs to one object; `bake` objects get a lightmap."""
    name: str
    first_triangle: int
    triangle_count: int
    resolution: int = 0
    bake: bool = True
    image: str = ""  # the atlas its charts lie in (lightmap/atlas.py), shared with others; "": its own lightmap

    @property
    def triangles(self) -> slice:
        return slice(self.first_triangle, self.first_triangle + self.triangle_count)


@dataclass
class Scene:
    """Triangles with per-corner shading normals and lightmap UVs, per-triangle materials, lights.

    positions: (T, 3, 3) corner positions; normals: (T, 3, 3) corner shading normals;
    uvs: (T, 3, 2) lightmap UVs in [0, 1]; albedo: (T, 3) diffuse reflectance;
    emission: (T, 3) emitted radiance W/(m² sr), from both faces as in Cycles; world: constant sky radiance.
    """
    positions: np.ndarray
    normals: np.ndarray
    uvs: np.ndarray
    albedo: np.ndarray
    emission: np.ndarray
    objects: list[BakeObject]
    lights: list[Light] = field(default_factory=list)
    world: np.ndarray = field(default_factory=lambda: np.zeros(3))
    default_bounces: int = 4
    # Textures (textures.py): albedo[t] × the RGB of albedo_texture[t] is a triangle's albedo where
    # that index is ≥ 0; opacity[t] × the alpha of opacity_texture[t] how much light it stops
    # (1: opaque). tex_uvs (T, 3, 2) are the UVs both textures are read at. None: untextured, opaque.
    textures: Optional[object] = None  # transport.textures.Textures: built from the scene, so not imported here
    # An HDRI world (environment.py); when set it replaces `world`.
    world_map: Optional[object] = None  # transport.environment.EnvironmentMap (likewise)
    tex_uvs: Optional[np.ndarray] = None
    albedo_texture: Optional[np.ndarray] = None
    opacity: Optional[np.ndarray] = None
    opacity_texture: Optional[np.ndarray] = None
    # What the exporter found (blender.export_scene): instance and triangle counts, bytes per
    # triangle, what it left out and why. Plain JSON-able values, for report.json.
    export_stats: dict = field(default_factory=dict)
    # The scene's Light Probe Volumes (ProbeVolume), for a bake with probes = 'volumes'.
    probe_volumes: list = field(default_factory=list)

    @property
    def triangle_count(self) -> int:
        return len(self.positions)

    def bounds(self) -> tuple[np.ndarray, float]:
        """Centre and radius of a sphere around all geometry and positional lights."""
        pts = [self.positions.reshape(-1, 3)]
        for light in self.lights:
            if isinstance(light, (PointLight, SpotLight)):
                pts.append(np.asarray(light.position, float).reshape(1, 3))
            elif isinstance(light, AreaLight):
                pts.append(np.asarray(light.matrix, float)[:3, 3].reshape(1, 3))
        pts = np.concatenate(pts).astype(np.float64)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        centre = 0.5 * (lo + hi)
        radius = float(np.linalg.norm(hi - lo)) * 0.5
        return centre, max(radius, 1e-3) * 1.01

    def ray_offset(self) -> float:
        """How far off a surface rays leave it (shadow rays, photon bounces): 1e-5 of the scene's size."""
        return max(1e-5 * self.bounds()[1], 1e-6)

    def recentred(self) -> tuple["Scene", np.ndarray]:
        """(a copy moved so that the centre of its geometry's box is the origin, the offset
        subtracted), or (self, zeros) when the origin already lies within the geometry's bounding
        sphere. Rays, hits, texels and discs are float32 in places: 10 km from the origin float32
        keeps about a millimetre, which shifts rays off their surfaces and darkens the bake.
        Lightmaps do not depend on where the scene stands, so the bake works around its centre."""
        if not self.triangle_count:
            return self, np.zeros(3)
        pts = self.positions.reshape(-1, 3)
        lo, hi = pts.min(axis=0).astype(np.float64), pts.max(axis=0).astype(np.float64)
        centre = 0.5 * (lo + hi)
        if not np.linalg.norm(centre) > 0.5 * np.linalg.norm(hi - lo):
            return self, np.zeros(3)
        lights = []
        for light in self.lights:
            if isinstance(light, (PointLight, SpotLight)):
                light = replace(light, position=np.asarray(light.position, np.float64) - centre)
            elif isinstance(light, AreaLight):
                matrix = np.array(light.matrix, np.float64)
                matrix[:3, 3] -= centre
                light = replace(light, matrix=matrix)
            lights.append(light)
        return replace(self, positions=self.positions.astype(np.float64) - centre, lights=lights), centre

    def object_named(self, name: str) -> BakeObject:
        for obj in self.objects:
            if obj.name == name:
                return obj
        raise BakeError(f"object '{name}' is not in the scene")

    def check(self) -> None:
        """Raise BakeError for data that would make the bake meaningless, naming the culprit."""
        t = self.triangle_count
        for name, arr, shape in (("positions", self.positions, (t, 3, 3)),
                                 ("normals", self.normals, (t, 3, 3)),
                                 ("uvs", self.uvs, (t, 3, 2)),
                                 ("albedo", self.albedo, (t, 3)),
                                 ("emission", self.emission, (t, 3))):
            if arr.shape != shape:
                raise BakeError(f"scene {name} has shape {arr.shape}, expected {shape}")
        self._check_textures()
        covered = np.zeros(t, bool)
        for obj in self.objects:
            if obj.first_triangle < 0 or obj.first_triangle + obj.triangle_count > t:
                raise BakeError(f"object '{obj.name}' refers to triangles outside the scene")
            covered[obj.triangles] = True
        if t and not covered.all():
            raise BakeError("some triangles belong to no object")
        for name, arr in (("positions", self.positions), ("normals", self.normals), ("uvs", self.uvs),
                          ("albedo", self.albedo), ("emission", self.emission)):
            bad = ~np.isfinite(arr.reshape(t, -1)).all(axis=1)
            if bad.any():
                owner = self.objects[int(self.object_index()[np.argmax(bad)])].name
                raise BakeError(f"object '{owner}': its {name} contain NaN or infinite values")
        world = np.asarray(self.world, np.float64)
        if world.shape != (3,) or not np.all(np.isfinite(world)) or np.abs(world).max() > MAX_POWER:
            raise BakeError(f"the world colour {world.tolist()} is not a finite colour")
        for light in self.lights:
            check_light(light)
        if not any(o.bake for o in self.objects):
            raise BakeError("no object to bake: select or include at least one mesh object")
        for obj in self.objects:
            if obj.bake and obj.triangle_count == 0:
                raise BakeError(f"object '{obj.name}' has no faces to bake")

    def _check_textures(self) -> None:
        t = self.triangle_count
        k = len(self.textures.info) if self.textures is not None else 0
        for name, arr in (("albedo_texture", self.albedo_texture), ("opacity_texture", self.opacity_texture)):
            if arr is None:
                continue
            if arr.shape != (t,):
                raise BakeError(f"scene {name} has shape {arr.shape}, expected ({t},)")
            if np.any(arr >= k) or np.any(arr < -1):
                raise BakeError(f"scene {name} refers to a texture that is not there")
            if np.any(arr >= 0) and (self.tex_uvs is None or self.tex_uvs.shape != (t, 3, 2)):
                raise BakeError(f"scene {name} is set but tex_uvs is missing or not ({t}, 3, 2)")
        if self.opacity is not None and (self.opacity.shape != (t,) or not np.all(np.isfinite(self.opacity))):
            raise BakeError("scene opacity must be one finite value per triangle")

    def object_index(self) -> np.ndarray:
        """Index into `objects` for every triangle."""
        idx = np.empty(self.triangle_count, np.int32)
        for i, obj in enumerate(self.objects):
            idx[obj.triangles] = i
        return idx
