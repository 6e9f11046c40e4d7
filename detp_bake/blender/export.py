"""Blender data → `scene.Scene`: the scene as F12 renders it (evaluation.py), its materials
(materials.py), lights and world (world.py), with lightmap UVs for the objects to bake."""
from __future__ import annotations

from typing import Callable, Iterable, Optional

import bpy
import numpy as np

from ..errors import BakeError
from .probe_volumes import probe_volumes
from ..scene import Scene
from .common import DEFAULT_UV, probe_lit, uses_nodes
from .evaluation import Collector, flatten, holdout, instancers, render_evaluation, rendered_names
from .materials import Surface, read_surface
from .world import export_world
from .atlas import ATLAS_UV, pack as atlas_pack
from .identity import fingerprints
from .uv import check_can_add, ensure_lightmap_uvs


def material_surface(mat) -> Surface:
    """The lightmap view of a material (materials.read_surface)."""
    return read_surface(mat, uses_nodes(mat) if mat is not None else False)


def material_albedo_emission(mat) -> tuple[np.ndarray, np.ndarray]:
    """A material's constant diffuse albedo and emitted radiance (textures not applied)."""
    s = material_surface(mat)
    return s.albedo, s.emission


def _non_finite_vertices(mesh) -> int:
    """How many of the mesh's vertices have a NaN or infinite coordinate (one array read, no loop)."""
    co = np.empty(len(mesh.vertices) * 3, np.float64)
    mesh.vertices.foreach_get("co", co)
    return int((~np.isfinite(co.reshape(-1, 3))).any(axis=1).sum())


def _unbakeable(obj) -> str:
    """Why a mesh object can have no lightmap ('' when it can): no faces, vertices that are not
    finite numbers (their faces would be dropped in silence), a transform that is not finite, or
    flattened by a zero scale (it still takes part in the light transport as what it is: nothing,
    or a flat sheet)."""
    if len(obj.data.polygons) == 0:
        return "no faces, only loose vertices or edges"
    bad = _non_finite_vertices(obj.data)
    if bad:
        return (f"{bad} of its {len(obj.data.vertices)} vertices {'is' if bad == 1 else 'are'} not finite "
                "(NaN or infinite coordinates): fix or delete them")
    m = np.array(obj.matrix_world, float)
    if not np.isfinite(m).all():
        return "its transform is not finite (NaN or infinite location, rotation or scale)"
    m = m[:3, :3]
    if abs(np.linalg.det(m)) <= 1e-12 * max(np.abs(m).max(), 1e-30) ** 3:
        return "flattened by a zero scale"
    return ""


def scene_bounces(bl_scene) -> int:
    """Cycles' Light Paths › Diffuse bounces, capped by Total bounces."""
    cycles = getattr(bl_scene, "cycles", None)
    if cycles is None:
        return 4
    return int(min(cycles.diffuse_bounces, cycles.max_bounces))


def _targets(bl_scene, view_layer, objects, log) -> list:
    """The objects to bake: every rendered mesh that can take a lightmap (others said through `log`,
    the exporter's `warn`)
    when `objects` is None, else the named ones, each checked (BakeError naming the first that cannot)."""
    rendered = rendered_names(view_layer)
    if objects is None:
        targets = [o for o in bl_scene.objects if o.type == "MESH" and o.name in rendered
                   and not holdout(o, view_layer) and not probe_lit(o)]
        unbakeable = {o.name: why for o in targets for why in [_unbakeable(o)] if why}
        if unbakeable:
            said = ", ".join(f"'{n}' ({why})" for n, why in list(unbakeable.items())[:6])
            log(f"no lightmap for {said}" + (f" and {len(unbakeable) - 6} more" if len(unbakeable) > 6 else ""))
            targets = [o for o in targets if o.name not in unbakeable]
    else:
        targets = []
        for name in objects:
            obj = bl_scene.objects.get(name)
            if obj is None or obj.name not in rendered:
                owners = render_evaluation(bl_scene, view_layer, instancers(name))
                if owners:
                    raise BakeError(f"object '{name}' is only an instance (in {', '.join(sorted(owners)[:3])}): "
                                    "lightmaps are baked on real mesh objects; make it real (Object › Apply › "
                                    "Make Instances Real) to bake one for it")
                if obj is None:
                    raise BakeError(f"object '{name}' is not in scene '{bl_scene.name}'")
                raise BakeError(f"object '{name}' is not rendered (Disable in Renders, or its collection is "
                                f"excluded from view layer '{view_layer.name}' or disabled in renders)")
            if obj.type != "MESH":
                raise BakeError(f"object '{name}' is a {obj.type.lower()}, not a mesh: convert it to a mesh "
                                "to bake a lightmap for it")
            if probe_lit(obj):
                raise BakeError(f"object '{name}' has Probe Light on: it moves and the baked probes light it, so it "
                                "gets no lightmap; turn Probe Light off to bake one")
            if holdout(obj, view_layer):
                raise BakeError(f"object '{name}' is a holdout, which Cycles bakes black: turn Holdout off "
                                "to bake it")
            why = _unbakeable(obj)
            if why:
                raise BakeError(f"object '{name}' cannot get a lightmap: {why}")
            targets.append(obj)
    return targets


def export_scene(bl_scene, depsgraph=None, objects: Optional[Iterable[str]] = None,
                 uv_layer=None, resolution=0, log: Callable[[str], None] = print,
                 created: Optional[list] = None, max_bytes: Optional[int] = None, atlas=None,
                 warn: Optional[Callable[[str], None]] = None) -> Scene:
    """The scene as F12 renders it (`render_evaluation`): every rendered mesh, curve, surface, text
    and metaball, and every instance of one, is geometry in world space; `objects` (default: every
    rendered mesh object) get lightmaps, and must be real mesh objects. `depsgraph` only names the
    view layer (default: the context's); a render depsgraph is used as it is.

    `uv_layer` names the lightmap UV layer: one name for all, or {object name: layer} for some; a
    named layer must exist. Objects with no name given use DEFAULT_UV, created with xatlas charts
    (blender/uv.py) where missing (said through `log`, and listed in `created` as (object, layer) so a cancelled
    bake can remove it again). `resolution` is one size for all or {object name: size}.
    `max_bytes` limits the flattened geometry (BakeError naming the biggest contributors). `atlas`:
    the BakeSettings of a bake into atlases (lightmaps 'atlas'): the objects' islands are packed
    (blender/atlas.py) and baked through the atlas UV layer, at the atlas size. `warn` (default
    `log`) says the meshes that get no lightmap when every mesh is baked (report.json keeps them)."""
    warn = log if warn is None else warn  # (a list of warnings that is callable can be empty)
    view_layer = depsgraph.view_layer if depsgraph is not None else bpy.context.view_layer
    targets = _targets(bl_scene, view_layer, objects, warn)
    if not targets:
        raise BakeError(f"scene '{bl_scene.name}' has no rendered mesh object to bake")
    named = uv_layer if isinstance(uv_layer, dict) else {o.name: uv_layer for o in targets if uv_layer}
    for obj in targets:
        layer = named.get(obj.name)
        if layer is not None and layer not in obj.data.uv_layers:
            raise BakeError(f"object '{obj.name}' has no UV layer '{layer}'")
    layers = {o.name: named.get(o.name) or DEFAULT_UV for o in targets}
    in_atlas = atlas is not None and atlas.lightmaps == "atlas"
    for obj in targets:
        check_can_add(obj, layers[obj.name])
        if in_atlas:
            check_can_add(obj, ATLAS_UV)
    sizes = {o.name: int((resolution.get(o.name, 0) if isinstance(resolution, dict) else resolution) or 0)
             for o in targets}
    densities = {o.name: atlas.texel_density * (o.detp_bake.density_scale if hasattr(o, "detp_bake") else 1.0)
                 for o in targets} if in_atlas else {}
    made = ensure_lightmap_uvs(targets, layers, sizes, densities)
    if created is not None:
        created.extend((name, layers[name]) for name in made)
    if made:
        log(f"created UV layer '{layers[made[0]]}' with xatlas charts on {', '.join(made[:5])}"
            + (f" and {len(made) - 5} more" if len(made) > 5 else ""))
    if in_atlas:
        in_atlas = atlas_pack(bl_scene, targets, layers, atlas, log, created)
        layers = {name: ATLAS_UV for name in layers}
        resolution = {name: side for name, (_, side) in in_atlas.items()}

    collector = Collector(layers, log, material_surface)
    if depsgraph is not None and depsgraph.mode == "RENDER":
        collector(depsgraph)
    else:
        render_evaluation(bl_scene, view_layer, collector)
    for name in layers:
        if name not in collector.found:
            if objects is not None:
                raise BakeError(f"object '{name}' is not in the render (F12 does not show it), so it cannot be baked")
            warn(f"object '{name}' is not in the render (F12 does not show its own faces): not baked")
    for reason, names in collector.left_out.items():
        log(f"left out ({reason}): {', '.join(names[:5])}" + (f" and {len(names) - 5} more" if len(names) > 5 else ""))
    (pos, nrm, uvs, alb, emi), objs, stats, surfaces = flatten(collector, resolution, max_bytes,
                                                                strict=objects is not None)
    for name in stats.pop("no_area", []):
        warn(f"no lightmap for '{name}': all its faces have zero area")
    world, world_map = export_world(bl_scene.world, log)
    for obj in objs:
        obj.image = in_atlas[obj.name][0] if in_atlas and obj.name in in_atlas else ""
    scene = Scene(positions=pos, normals=nrm, uvs=uvs, albedo=alb, emission=emi, objects=objs,
                  lights=collector.lights, world=world, default_bounces=scene_bounces(bl_scene),
                  world_map=world_map, **surfaces)
    baked = {o.name for o in objs if o.bake}
    stats["geometry"] = fingerprints(o for o in targets if o.name in baked)  # for the glTF export (identity.py)
    stats["file"] = bpy.data.filepath
    scene.export_stats = stats
    scene.probe_volumes = probe_volumes(bl_scene, view_layer)
    return scene
