"""Blender's render evaluation, read for the exporter (`blender.export_scene`): what F12
renders, as shared geometry, one placement per object or instance, and lights.

Python cannot build a render depsgraph, so `render_evaluation` renders a throwaway copy of the
scene with an engine that only reads the depsgraph Blender hands it. `Collector` walks that
depsgraph's object instances: meshes, curves, surfaces, text and metaballs, collection, particle
and geometry-nodes instances, each geometry extracted once and placed per instance, with Cycles'
ray visibility; `flatten` turns it into the world-space arrays of `scene.Scene`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

import bpy
import numpy as np

from ..errors import BakeError
from .common import probe_lit
from .materials import SlotRows, TextureTable, corner_colours, corner_uvs, render_uv_name
from ..scene import MAX_POWER, MAX_SIZE, AreaLight, BakeObject, PointLight, SpotLight, SunLight

GEOMETRY_TYPES = ("MESH", "CURVE", "SURFACE", "FONT", "META")
_SELF_LISTED = ("CURVE", "SURFACE", "FONT")  # Blender lists their evaluated mesh twice: as themselves and as an instance
NOT_EXPORTED = {"CURVES": "hair curves", "POINTCLOUD": "point clouds", "VOLUME": "volumes"}
_JOB: dict = {}


class _RenderEvaluation(bpy.types.RenderEngine):
    """Registered only while `render_evaluation` runs. Python cannot build a render depsgraph, but
    Blender hands one to a render engine at every final render; this engine only passes it on."""
    bl_idname = "DETP_BAKE_RENDER_EVALUATION"
    bl_label = "detp_bake export"
    bl_use_postprocess = False

    def render(self, depsgraph):
        if "fn" in _JOB and "result" not in _JOB and "error" not in _JOB:
            try:
                _JOB["result"] = _JOB["fn"](depsgraph)
            except BaseException as exc:  # raised again by render_evaluation
                _JOB["error"] = exc


def render_evaluation(bl_scene, view_layer, fn):
    """fn(depsgraph) on the render evaluation of `view_layer` (what F12 renders: render modifier
    levels, render visibility, instances), and its result. A throwaway copy of the scene, sharing
    its objects and collections, is rendered at 4×4 pixels without compositor or sequencer by an
    engine that only calls fn; the copy and any new Render Result are removed again, so the file
    and the user's last render stay as they were (render handlers do run)."""
    if _JOB:
        raise BakeError("an export is already running")
    results = {i.name for i in bpy.data.images if i.type == "RENDER_RESULT"}
    bpy.utils.register_class(_RenderEvaluation)
    copy = None
    _JOB["fn"] = fn
    try:
        copy = bl_scene.copy()
        r = copy.render
        r.engine = _RenderEvaluation.bl_idname
        r.use_compositing = r.use_sequencer = r.use_border = r.use_multiview = False
        r.resolution_x = r.resolution_y = 4
        r.resolution_percentage = 100
        try:
            bpy.ops.render.render(scene=copy.name, layer=view_layer.name)
        except RuntimeError as exc:
            raise BakeError(f"Blender could not evaluate scene '{bl_scene.name}' for rendering: {exc}") from None
        job = dict(_JOB)
    finally:
        _JOB.clear()
        if copy is not None:
            bpy.data.scenes.remove(copy)
        bpy.utils.unregister_class(_RenderEvaluation)
        for img in [i for i in bpy.data.images if i.type == "RENDER_RESULT" and i.name not in results]:
            bpy.data.images.remove(img)
    if "error" in job:
        raise job["error"]
    if "result" not in job:
        raise BakeError(f"Blender did not render view layer '{view_layer.name}' of scene '{bl_scene.name}' "
                        "(is another render running?)")
    return job["result"]


def rendered_names(view_layer) -> set:
    """Objects the render evaluation will hold as themselves: not Disabled in Renders, in a
    collection that is neither excluded from the view layer nor disabled in renders."""
    names = set()

    def walk(lc, on):
        on = on and not lc.exclude and not lc.collection.hide_render
        if on:
            names.update(o.name for o in lc.collection.objects if not o.hide_render)
        for child in lc.children:
            walk(child, on)

    walk(view_layer.layer_collection, True)
    return names


def _rays(ob, parent, kind: str) -> bool:
    """Cycles' ray visibility of an object (visible_shadow, visible_diffuse, …), and'ed with its
    instancer's for an instance, as Cycles does."""
    return bool(getattr(ob, kind, True)) and (parent is None or bool(getattr(parent, kind, True)))


def holdout(obj, view_layer) -> bool:
    return bool(getattr(obj, "is_holdout", False)) or bool(obj.holdout_get(view_layer=view_layer))


def instancers(name: str):
    """A render-evaluation callback: the objects that instance object `name`."""
    def fn(depsgraph):
        return {i.parent.original.name for i in depsgraph.object_instances
                if i.is_instance and i.object.original.name == name and i.parent is not None}
    return fn


_BYTES_PER_TRIANGLE = 8 * (9 + 9 + 6 + 3 + 3)  # positions, normals, UVs, albedo, emission (float64)


@dataclass
class _Geometry:
    """One evaluated geometry in its own space, shared by every instance of it."""
    co: np.ndarray  # (V, 3)
    tri: np.ndarray  # (T, 3) vertex indices
    normals: np.ndarray  # (T, 3, 3) corner normals
    uvs: Optional[np.ndarray]  # (T, 3, 2) lightmap UVs (bake targets only)
    material: np.ndarray  # (T,) material index
    materials: list  # the evaluated data's own materials, for objects without slots
    uv_sets: dict  # UV map name -> (T, 3, 2) float32, for textures
    render_uv: Optional[str]  # the map Cycles reads when a texture names none
    colours: dict  # colour attribute name -> (T, 3, 3) float32 linear RGB ("" = the render one)

    def uv(self, name: Optional[str]) -> Optional[np.ndarray]:
        return self.uv_sets.get(name or self.render_uv)

    def colour(self, name: str) -> Optional[np.ndarray]:
        return self.colours.get(name) if name else self.colours.get("")


def _extract(ob, uv_name: Optional[str]) -> _Geometry:
    """Triangles of an evaluated object (mesh, curve, surface, text, metaball) in object space."""
    me = ob.to_mesh()
    try:
        me.calc_loop_triangles()
        nt = len(me.loop_triangles)
        co = np.empty(len(me.vertices) * 3, np.float64)
        me.vertices.foreach_get("co", co)
        tri_v = np.empty(nt * 3, np.int64)
        me.loop_triangles.foreach_get("vertices", tri_v)
        tri_l = np.empty(nt * 3, np.int64)
        me.loop_triangles.foreach_get("loops", tri_l)
        mat_index = np.empty(nt, np.int64)
        me.loop_triangles.foreach_get("material_index", mat_index)
        corner_n = np.empty(len(me.loops) * 3, np.float64)
        me.corner_normals.foreach_get("vector", corner_n)
        uvs = None
        if uv_name is not None:
            uv = np.zeros((len(me.loops), 2))
            if uv_name in me.uv_layers:
                flat = np.empty(len(me.loops) * 2, np.float64)
                me.uv_layers[uv_name].uv.foreach_get("vector", flat)
                uv = flat.reshape(-1, 2)
            uvs = uv[tri_l.reshape(-1, 3)]
        materials = list(me.materials)
        loops = tri_l.reshape(-1, 3)
        uv_sets = {layer.name: corner_uvs(me, loops, layer.name).astype(np.float32) for layer in me.uv_layers}
        render_uv = render_uv_name(me)
        colours = {}
        for attr in me.color_attributes:
            colours[attr.name] = corner_colours(me, loops, attr.name).astype(np.float32)
        if len(me.color_attributes):
            colours[""] = corner_colours(me, loops, "").astype(np.float32)
    finally:
        ob.to_mesh_clear()
    return _Geometry(co.reshape(-1, 3), tri_v.reshape(-1, 3), corner_n.reshape(-1, 3)[tri_l.reshape(-1, 3)],
                     uvs, mat_index, materials, uv_sets, render_uv, colours)


def _place(g: _Geometry, m: np.ndarray):
    """World-space corners and unit corner normals of `g` under each of the (n, 4, 4) matrices `m`,
    instance after instance, and the mask of triangles with an area (zero-area ones carry no light
    and confuse the rasteriser). Normals go through the cofactor matrix det(A)·A⁻ᵀ, flipped where
    det(A) < 0: no matrix inverse per instance, and a flattened instance keeps its normals."""
    a, t = m[:, :3, :3], m[:, :3, 3]
    pos = np.einsum("nij,tkj->ntki", a, g.co[g.tri]) + t[:, None, None, :]
    c0, c1, c2 = a[:, :, 0], a[:, :, 1], a[:, :, 2]
    cof = np.stack([np.cross(c1, c2), np.cross(c2, c0), np.cross(c0, c1)], axis=2)
    cof *= np.where(np.einsum("ni,ni->n", c0, cof[:, :, 0]) < 0.0, -1.0, 1.0)[:, None, None]
    nrm = np.einsum("nij,tkj->ntki", cof, g.normals)
    nrm /= np.maximum(np.linalg.norm(nrm, axis=3, keepdims=True), 1e-30)
    pos, nrm = pos.reshape(-1, 3, 3), nrm.reshape(-1, 3, 3)
    area = np.linalg.norm(np.cross(pos[:, 1] - pos[:, 0], pos[:, 2] - pos[:, 0]), axis=1)
    return pos, nrm, area > 1e-12


def _setting(name: str, setting: str, value, unit: str = "", limit: Optional[float] = None) -> float:
    v = float(value)
    if np.isnan(v):
        raise BakeError(f"light '{name}': {setting} is not a number")
    if np.isinf(v):
        raise BakeError(f"light '{name}': {setting} is infinite")
    if limit is not None and abs(v) > limit:
        raise BakeError(f"light '{name}': {setting} {v:.3g}{unit} is absurd (more than {limit:.0e}{unit})")
    return v


def _light_shader(light, name: str, log) -> np.ndarray:
    """What a light's node tree multiplies its colour by in Cycles: an Emission node's Color ×
    Strength; nothing connected to the Light Output: no light (measured)."""
    tree = light.node_tree
    if tree is None or (bpy.app.version < (5, 0, 0) and not light.use_nodes):
        return np.ones(3)
    outs = [n for n in tree.nodes if n.type == "OUTPUT_LIGHT"]
    outs.sort(key=lambda n: not n.is_active_output)
    surf = outs[0].inputs.get("Surface") if outs else None
    if surf is None or not surf.is_linked:
        return np.zeros(3)
    node = surf.links[0].from_node
    if node.type == "EMISSION" and not node.inputs["Color"].is_linked and not node.inputs["Strength"].is_linked:
        return np.array(node.inputs["Color"].default_value[:3], float) * float(node.inputs["Strength"].default_value)
    log(f"light '{name}': only a plain Emission node is read from its node tree; the rest is ignored")
    return np.ones(3)


def _light(name: str, light, m: np.ndarray, log) -> Optional[object]:
    """A scene.py light from evaluated light data and its world matrix; BakeError naming the
    setting when one is NaN, infinite or absurd."""
    if not np.all(np.isfinite(m)):
        raise BakeError(f"light '{name}': its transform is not finite")
    sun = light.type == "SUN"
    energy = _setting(name, "strength" if sun else "power", light.energy, " W/m²" if sun else " W", MAX_POWER)
    colour = np.array([_setting(name, "colour", c, "", 1e6) for c in light.color[:3]])
    if getattr(light, "use_temperature", False):
        colour = colour * np.array(light.temperature_color[:3], float)
    colour = colour * _light_shader(light, name, log)
    energy *= 2.0 ** _setting(name, "exposure", getattr(light, "exposure", 0.0))
    radius = _setting(name, "radius", light.shadow_soft_size, " m", MAX_SIZE)
    if not getattr(light, "use_shadow", True):
        log(f"light '{name}': Cast Shadow is off, but its light is shadowed here (photons cannot pass through)")
    if not getattr(light, "normalize", True):
        # Unnormalised lights keep their radiance as the size changes (measured in Cycles).
        if light.type in ("POINT", "SPOT"):
            energy *= 4.0 * np.pi * radius * radius if radius > 0 else 4.0
        elif light.type == "AREA":
            sx = float(light.size) * float(np.linalg.norm(m[:3, 0]))
            sy = float(light.size if light.shape in ("SQUARE", "DISK") else light.size_y) * \
                float(np.linalg.norm(m[:3, 1]))
            energy *= sx * sy * (np.pi / 4 if light.shape in ("DISK", "ELLIPSE") else 1.0)
    power = colour * energy
    if np.abs(power).max() > MAX_POWER:
        raise BakeError(f"light '{name}': power × colour × 2^exposure = {np.abs(power).max():.3g} W is absurd "
                        f"(more than {MAX_POWER:.0e} W)")
    axis = m[:3, :3] @ np.array([0.0, 0.0, -1.0])
    axis /= max(np.linalg.norm(axis), 1e-30)
    if light.type == "POINT":
        return PointLight(name, m[:3, 3], power, radius)
    if light.type == "SPOT":
        if getattr(light, "use_square", False):
            log(f"light '{name}': a square spot is baked as a round one")
        return SpotLight(name, m[:3, 3], axis, power, _setting(name, "spot size", light.spot_size),
                         _setting(name, "spot blend", light.spot_blend), radius)
    if sun:
        return SunLight(name, axis, power, _setting(name, "angle", light.angle))
    if light.type == "AREA":
        if getattr(light, "spread", np.pi) < np.pi - 1e-6:
            log(f"light '{name}': its spread is ignored (baked as 180°)")
        return AreaLight(name, m, light.shape, _setting(name, "size", light.size, " m", MAX_SIZE),
                         _setting(name, "size Y", light.size_y, " m", MAX_SIZE), power)
    return None


class Collector:
    """The render-evaluation callback: every rendered geometry (objects and instances) as shared
    geometry plus one record per placement, and every light that reaches diffuse surfaces."""

    def __init__(self, layers: dict, log: Callable[[str], None], material_rows: Callable):
        self.layers = layers  # bake target name -> lightmap UV layer
        self.log = log
        self.material_rows = material_rows  # material or None -> materials.Surface
        self.geometry: dict = {}
        self.records: list = []  # (owner, key, matrix, slot rows, bake, emissive only, source)
        self.lights: list = []
        self.found: set = set()
        self.left_out: dict = {}
        self.instanced_lights = 0
        self._rows: dict = {}
        self._surfaces: dict = {}

    def _material_rows(self, mats) -> SlotRows:
        """The materials of an object's slots as rows; the same rows for the same materials, each
        material read (and its approximations said) once."""
        mats = [m.original if m is not None else None for m in mats or [None]]
        keys = tuple(m.as_pointer() if m is not None else 0 for m in mats)
        if keys not in self._rows:
            surfaces = []
            for m in mats:
                key = m.as_pointer() if m is not None else 0
                if key not in self._surfaces:
                    self._surfaces[key] = self.material_rows(m)
                    for note in self._surfaces[key].notes:
                        self.log(f"material '{m.name}': {note}")
                surfaces.append(self._surfaces[key])
            self._rows[keys] = SlotRows.of(surfaces)
        return self._rows[keys]

    def _skip(self, reason: str, name: str) -> None:
        names = self.left_out.setdefault(reason, [])
        if name not in names:
            names.append(name)

    def __call__(self, depsgraph):
        for inst in depsgraph.object_instances:
            ob = inst.object
            parent = inst.parent if inst.is_instance else None
            if parent is not None and parent.original == ob.original and parent.type in _SELF_LISTED:
                continue  # a curve's, text's or surface's own geometry, listed again as an instance of itself
            source = ob.original.name
            owner = f"{parent.original.name} (instances)" if parent is not None else source
            if ob.type == "LIGHT":
                name = f"{parent.original.name}/{source}" if parent is not None else source
                if not _rays(ob, parent, "visible_diffuse"):
                    self._skip("light with Diffuse ray visibility off", name)
                    continue
                light = _light(name, ob.data, np.array(inst.matrix_world, float), self.log)
                if light is not None:
                    self.lights.append(light)
                    self.instanced_lights += parent is not None
                continue
            if ob.type in NOT_EXPORTED:
                self._skip(NOT_EXPORTED[ob.type], source)
                continue
            if ob.type not in GEOMETRY_TYPES or (parent is None and not inst.show_self):
                continue
            if parent is None and probe_lit(ob.original):
                self._skip("Probe Light: it moves, the probes light it", source)
                continue
            bake = parent is None and ob.type == "MESH" and source in self.layers
            emissive_only = False
            if not bake and not _rays(ob, parent, "visible_shadow"):
                emissive_only = True  # casts no shadow: only its light-emitting faces stay
                self._skip("Shadow ray visibility off (no shadow, no bounce light)", source)
            if bake:
                key = ("target", ob.original.as_pointer())
                self.found.add(source)
            elif ob.type == "MESH":
                key = ("mesh", ob.data.as_pointer())
            else:
                key = ("object", ob.original.as_pointer(), ob.data.as_pointer())
            if key not in self.geometry:
                self.geometry[key] = _extract(ob, self.layers.get(source) if bake else None)
            g = self.geometry[key]
            slots = [s.material for s in ob.material_slots]
            n = max(len(slots), len(g.materials))
            mats = [(slots[i] if i < len(slots) else None) or (g.materials[i] if i < len(g.materials) else None)
                    for i in range(n)]
            rows = self._material_rows(mats)
            self.records.append((owner, key, np.array(inst.matrix_world, float), rows, bake, emissive_only,
                                 (source, parent.original.name if parent is not None else None)))
        return self


def _largest(c: "Collector", max_bytes: Optional[int]) -> list:
    """The five sources of the most flattened triangles (for report.json); BakeError when the whole
    scene would flatten to more than `max_bytes`, naming them."""
    counts: dict = {}
    for owner, key, *_, source in c.records:
        entry = counts.setdefault(source, [0, 0])
        entry[0] += 1
        entry[1] += len(c.geometry[key].tri)
    total = sum(t for _, t in counts.values())
    largest = sorted(counts.items(), key=lambda kv: -kv[1][1])[:5]
    top = [{"object": s, "instancer": p, "count": n, "triangles": t} for (s, p), (n, t) in largest]
    if max_bytes and total * _BYTES_PER_TRIANGLE > max_bytes:
        said = ", ".join(f"'{d['object']}'" + (f" ×{d['count']} in '{d['instancer']}'" if d["instancer"] else "") +
                         f" ({d['triangles']:,} triangles)" for d in top)
        raise BakeError(f"the scene's geometry flattens to {total:,} triangles, {total * _BYTES_PER_TRIANGLE / 1e9:.2f} "
                        f"GB, more than the budget of {max_bytes / 1e9:.2f} GB; the biggest: {said}")
    return top


def flatten(c: Collector, resolution, max_bytes: Optional[int], strict: bool = True):
    """World-space arrays, one BakeObject per owner (an object, or all instances of one instancer),
    the export statistics, and the scene's textures and per-triangle texture and opacity arrays
    (materials.TextureTable.finish). Raises BakeError past `max_bytes` before building anything big, and
    for a bake target without faces of any area (`strict`; otherwise it is not baked, and listed in
    the statistics' "no_area")."""
    top = _largest(c, max_bytes)
    groups: dict = {}
    for rec in c.records:
        groups.setdefault((rec[0], rec[4]), []).append(rec)
    pos, nrm, uvs, alb, emi, objs, surf = [], [], [], [], [], [], []
    table = TextureTable()
    first, names, no_area = 0, set(), []
    instances = instanced_tris = 0
    degenerate: dict = {}  # baked owner -> [triangles without area, triangles]
    for (owner, bake), recs in groups.items():
        start = first
        batches: dict = {}  # placements that share geometry and materials are placed together
        for _, key, m, rows, _, emissive_only, (_, parent) in recs:
            batches.setdefault((key, id(rows), emissive_only, parent is not None), (rows, []))[1].append(m)
        for (key, _, emissive_only, instanced), (rows, ms) in batches.items():
            g, n_inst = c.geometry[key], len(ms)
            p, n, keep = _place(g, np.array(ms))
            if bake:  # collapsed faces, zero-length edges: no area, no light; said by the caller
                flat = degenerate.setdefault(owner, [0, 0])
                flat[0], flat[1] = flat[0] + int(len(keep) - keep.sum()), flat[1] + len(keep)
            mi = np.tile(np.clip(g.material, 0, len(rows.albedo) - 1), n_inst)
            a, e = rows.albedo[mi], rows.emission[mi]
            surface = table.triangles(rows, g, mi, n_inst, a, c.log)
            if emissive_only:
                keep &= np.any(e != 0.0, axis=1)
            pos.append(p[keep])
            nrm.append(n[keep])
            uvs.append(np.tile(g.uvs, (n_inst, 1, 1))[keep] if g.uvs is not None
                       else np.zeros((int(keep.sum()), 3, 2)))
            alb.append(a[keep])
            emi.append(e[keep])
            surf.append({k: v[keep] for k, v in surface.items()})
            first += int(keep.sum())
            if instanced:
                instances += n_inst
                instanced_tris += int(keep.sum())
        if bake and first == start and strict:
            raise BakeError(f"object '{owner}' has no faces to bake: all its faces have zero area")
        if first == start:
            no_area += [owner] if bake else []
            continue
        name = owner
        while name in names:
            name += "'"
        names.add(name)
        size = resolution.get(owner, 0) if isinstance(resolution, dict) else int(resolution or 0)
        objs.append(BakeObject(name, start, first - start, size if bake else 0, bake))

    def cat(parts, shape):
        return np.concatenate(parts) if parts else np.zeros((0, *shape))

    arrays = (cat(pos, (3, 3)), cat(nrm, (3, 3)), cat(uvs, (3, 2)), cat(alb, (3,)), cat(emi, (3,)))
    stats = {
        "evaluation": "render",
        "triangles": first,
        "objects": sum(1 for r in c.records if r[6][1] is None),
        "instances": instances,
        "instanced_triangles": instanced_tris,
        "shared_geometries": len(c.geometry),
        "shared_triangles": int(sum(len(g.tri) for g in c.geometry.values())),
        "bytes_per_triangle": int(sum(a.itemsize * a[0].size for a in arrays)) if first else _BYTES_PER_TRIANGLE,
        "lights": len(c.lights),
        "instanced_lights": c.instanced_lights,
        "largest": top,
        "left_out": c.left_out,
        "no_area": no_area,
        "degenerate_triangles": {name: counts for name, counts in degenerate.items() if counts[0]},
    }
    surfaces = table.finish(surf)
    stats["textures"] = len(table.images)
    return arrays, objs, stats, surfaces
