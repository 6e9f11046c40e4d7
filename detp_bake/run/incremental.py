"""What a lightmap depends on, as a key, so that a bake into a folder holding an earlier one does
again only what can have changed: a frame of a range (frames.py) or, in a single-frame bake, an
object (`plan`).

An object's lightmap depends on the whole scene (every triangle's geometry and materials, the
textures, the lights and the world: photons bounce everywhere), on the settings, and on the object
itself (its lightmap UVs and resolution), but not on which other objects are baked with it:
  - photons: a photon's random numbers depend on the seed and its id alone (schedule.py), and
    every surface scatters them whether it is baked or not;
  - the estimators: a texel sums the segments that cross its own disc (or its k nearest hits, or
    the photons that land on its own square) in batch order; disc clearance and rise look at the scene's triangles, not at other texels;
  - sampled direct light: a texel's shadow rays are keyed by its object and pixel (direct.py);
  - denoising and dilation work on one lightmap at a time.
Three things do depend on the others, and are in the key or stop reuse:
  - with a sun or a sky, their photons start the widest disc of the bake beyond the geometry
    (bake.disc_reach): the key holds that reach, and a bake that reuses some objects starts them
    as far out as the whole set would;
  - the sphere cache centres its spheres on whichever texel rebuilt them last, which depends on
    the texels around it: a segment crossing a disc right at a sphere's rim may be kept or dropped
    by rounding, so its sums are the same only almost always, and it is never reused;
  - an early stop (noise target, time limit, Stop and Keep) stops where all lightmaps say.
tests/test_incremental.py checks the first list, bit for bit.
"""
from __future__ import annotations

import hashlib
import json
import os
from dataclasses import asdict, dataclass, field, is_dataclass, replace
from pathlib import Path
from typing import Iterable, Optional

import numpy as np

from .. import __version__
from ..lightmap import denoise, staging
from .bake import disc_reach
from ..scene import Scene, SunLight

# Estimators whose per-texel sums cannot depend on the other texels of the bake (a single-frame
# hybrid is the disc index; see the module's doc for the sphere cache).
PER_OBJECT = ("texel_histogram", "disc_index", "detp", "photon_map", "hybrid")


def digest(parts: Iterable) -> str:
    h = hashlib.blake2b(digest_size=16)
    for part in parts:
        if part is None:
            h.update(b"none")
            continue
        if isinstance(part, str):
            part = np.frombuffer(part.encode(), np.uint8)
        a = np.ascontiguousarray(part)
        h.update(str((a.dtype.str, a.shape)).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _per_triangle(scene: Scene) -> list:
    return [scene.positions, scene.normals, scene.albedo, scene.emission, scene.tex_uvs, scene.albedo_texture,
            scene.opacity, scene.opacity_texture]


def object_signatures(scene: Scene) -> dict[str, str]:
    """A hash per object of everything the bake reads of it in world space: corner positions and
    normals, lightmap UVs, albedo, emission, texture and cut-out assignments."""
    per_triangle = _per_triangle(scene) + [scene.uvs]
    return {obj.name: digest([None if a is None else a[obj.triangles] for a in per_triangle] +
                             [np.array([obj.bake, obj.resolution])])
            for obj in scene.objects}


def lights_signature(scene: Scene) -> str:
    """A hash of the lights and the world (an HDRI world by its pixels and rotation)."""
    parts = [np.asarray(scene.world, np.float64)]
    for light in scene.lights:
        values = asdict(light) if is_dataclass(light) else vars(light)
        for key in sorted(values):
            v = values[key]
            parts.append(v if isinstance(v, str) else np.asarray(v, np.float64))
    if scene.world_map is not None:
        parts += [scene.world_map.radiance, np.asarray(scene.world_map.rotation, np.float64)]
    return digest(parts)


def scene_signature(scene: Scene) -> str:
    """Everything of the scene that reaches every lightmap: each triangle's geometry and materials
    in order, the textures' pixels, which object owns which triangles, the lights and the world,
    the scene's bounces. Not which objects are baked, nor their lightmap UVs and resolutions."""
    textures = scene.textures
    return digest(_per_triangle(scene) + [
        None if textures is None else textures.pixels, None if textures is None else textures.info,
        json.dumps([(o.name, o.first_triangle, o.triangle_count) for o in scene.objects]),
        lights_signature(scene), np.array([scene.default_bounces])])


def sky_or_sun(scene: Scene) -> bool:
    """Whether photons start beyond the geometry (a sun, a world colour or map), by the discs' reach."""
    return (any(isinstance(light, SunLight) for light in scene.lights) or scene.world_map is not None
            or float(np.mean(scene.world)) > 0.0)


def settings_key(settings) -> str:
    """The settings that reach a lightmap's file (not threads or the memory budget), as JSON."""
    values = asdict(settings)
    for name in ("threads", "memory_budget_mb", "probes", "probe_spacing", "probe_rays"):  # probes: not a lightmap's
        values.pop(name, None)
    if values.get("directional") == "none" and not values.get("shadowmask"):
        for name in ("directional", "shadowmask", "shadowmask_mode"):
            values.pop(name)  # keys of plain bakes stay as they were
    values["denoised"] = bool(settings.denoise and denoise.available())  # pyoidn may come or go
    return json.dumps(values, sort_keys=True, default=list)


def object_keys(scene: Scene, settings, names: Iterable[str], reach: float) -> dict[str, str]:
    """{object: key} for objects `names` of `scene` baked with `settings` in a set whose widest
    disc is `reach` metres (bake.disc_reach)."""
    shared = digest([__version__, settings_key(settings), scene_signature(scene),
                     np.array([reach if sky_or_sun(scene) else 0.0])])
    out = {}
    for name in names:
        obj = scene.object_named(name)
        res = obj.resolution if obj.resolution > 0 else settings.resolution
        out[name] = digest([shared, name, scene.uvs[obj.triangles], np.array([res])])
    # The objects of an atlas share one image, denoised and written together: one key for all of
    # them, so that a change to any one rebakes the atlas.
    atlases: dict = {}
    for name in out:
        image = scene.object_named(name).image
        if image:
            atlases.setdefault(image, []).append(name)
    for image, members in atlases.items():
        key = digest([image] + [out[n] for n in sorted(members)])
        for n in members:
            out[n] = key
    return out


def reusable(settings) -> bool:
    """Whether a bake with these settings gives each object a lightmap that the other objects
    baked with it cannot change (see the module's doc)."""
    return settings.estimator in PER_OBJECT and not settings.target_noise and not settings.time_limit


@dataclass
class Plan:
    """What a bake into a folder does with each object: `keys` for all, `reused` {name: the earlier
    bake's report entry} for those whose lightmaps are there and cannot have changed, `bake` the
    rest, `earlier` entries of objects not in this bake that the report keeps."""
    keys: dict
    reused: dict = field(default_factory=dict)
    bake: list = field(default_factory=list)
    earlier: list = field(default_factory=list)
    previous: Optional[dict] = None  # the earlier report.json


def previous_report(out_dir) -> Optional[dict]:
    """The report.json of an earlier single-frame bake into `out_dir` by this version, or None."""
    try:
        doc = json.loads((Path(out_dir) / "report.json").read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(doc, dict) or doc.get("version") != __version__ or not isinstance(doc.get("objects"), list):
        return None
    return doc


def _entries(doc: Optional[dict], out_dir) -> dict:
    """{object: its entry} of an earlier report, its files taken in `out_dir` (a folder copied
    elsewhere keeps the paths of the first one), those with a key and all their files only."""
    if doc is None:
        return {}
    folder = Path(out_dir).resolve()
    out = {}
    for entry in list(doc.get("earlier_objects", [])) + list(doc["objects"]):
        if isinstance(entry, dict) and entry.get("key") and entry.get("files"):
            files = [str(folder / Path(f).name) for f in entry["files"]]
            if all(os.path.isfile(f) for f in files):
                out[entry["name"]] = {**entry, "files": files}
    return out


def plan(scene: Scene, settings, out_dir, force: bool = False) -> Plan:
    """Which objects of `scene` (those with `bake` set) a bake into `out_dir` must estimate. An
    object is reused when the earlier report.json there holds its key and all its files exist;
    `force` reuses nothing."""
    names = [o.name for o in scene.objects if o.bake]
    result = Plan(object_keys(scene, settings, names, disc_reach(scene, settings, names)), bake=list(names))
    if not reusable(settings) or settings.probes != "off":
        # Probes read every lightmap of their bake (probes/gather.py): a bake with probes bakes all.
        return result
    result.previous = previous_report(out_dir)
    entries = _entries(result.previous, out_dir)
    result.earlier = [e for name, e in entries.items() if name not in result.keys]
    if force:
        return result
    for name in names:
        entry = entries.get(name)
        if entry is not None and entry["key"] == result.keys[name]:
            result.reused[name] = entry
    result.bake = [n for n in names if n not in result.reused]
    return result


def without(scene: Scene, names: Iterable[str]) -> Scene:
    """The scene with objects `names` still in it (they cast shadows and bounce light) but not baked."""
    names = set(names)
    return replace(scene, objects=[replace(o, bake=False) if o.name in names else o for o in scene.objects])


def record(result, plan: Plan) -> None:
    """Put what `plan` reused, and the keys of what was baked, into a finished bake's result
    (report.json). A bake stopped early gets no keys: its photon count is not the setting's."""
    result.reused, result.earlier = dict(plan.reused), list(plan.earlier)
    if reusable(result.settings) and result.stopped_by == "photons":
        result.keys = {name: plan.keys[name] for name in plan.bake}


def write_all_reused(plan: Plan, out_dir) -> Path:
    """report.json of a bake that found every lightmap unchanged: the earlier report, with this
    bake's objects, all reused."""
    doc = {**plan.previous, "objects": [{**e, "reused": True} for e in plan.reused.values()],
           "reused": list(plan.reused)}
    doc.pop("earlier_objects", None)
    if plan.earlier:
        doc["earlier_objects"] = plan.earlier
    target = Path(out_dir) / "report.json"
    tmp = staging.temporary(target)
    tmp.write_text(json.dumps(doc, indent=2, allow_nan=False))
    os.replace(tmp, target)
    return target
