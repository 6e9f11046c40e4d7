"""The one Blender adapter: Blender data → `scene.Scene`, and baked images back into materials.

Everything else in the core takes numpy arrays; this module alone imports `bpy`. Export reads the
evaluated depsgraph (modifiers applied) in world space. Applying a lightmap adds a node frame named
FRAME_NAME to each material and remembers on the object what it changed, so `revert` restores the
materials, slots and images exactly as they were.
"""
from __future__ import annotations

import json
from typing import Callable, Iterable, Optional

import bpy
import numpy as np

from .errors import BakeError
from .blender_eval import Collector, flatten, holdout, instancers, render_evaluation, rendered_names
from .scene import Scene

FRAME_NAME = "detp_bake lightmap"
REVERT_KEY = "detp_bake_revert"
DEFAULT_UV = "Lightmap"
DEFAULT_ALBEDO = (0.8, 0.8, 0.8)


# --------------------------------------------------------------------------- export

def _has_nodes(idblock) -> bool:
    """Node-based shading in use (`use_nodes` is deprecated in Blender 5, where it always is)."""
    if idblock.node_tree is None:
        return False
    return bpy.app.version >= (5, 0, 0) or bool(idblock.use_nodes)


def _socket(node, *names):
    for name in names:
        sock = node.inputs.get(name)
        if sock is not None:
            return sock
    return None


def _rgb(sock) -> np.ndarray:
    v = sock.default_value
    return np.array([v[0], v[1], v[2]], float) if hasattr(v, "__len__") else np.full(3, float(v))


def _value(sock, default=0.0) -> float:
    return float(sock.default_value) if sock is not None else default


def _surface_shader(mat):
    nt = mat.node_tree
    outputs = [n for n in nt.nodes if n.type == "OUTPUT_MATERIAL"]
    outputs.sort(key=lambda n: (not n.is_active_output, n.target not in ("ALL", "CYCLES")))
    for out in outputs:
        surf = out.inputs.get("Surface")
        if surf is not None and surf.is_linked:
            return surf.links[0].from_node
    return None


def material_albedo_emission(mat) -> tuple[np.ndarray, np.ndarray]:
    """Diffuse albedo and emitted radiance of a material, from constant socket values."""
    if mat is None:
        return np.array(DEFAULT_ALBEDO), np.zeros(3)
    if not _has_nodes(mat):
        return np.array(mat.diffuse_color[:3], float), np.zeros(3)
    node = _surface_shader(mat)
    if node is None or node.type not in ("BSDF_PRINCIPLED", "BSDF_DIFFUSE", "EMISSION"):
        found = [n for n in mat.node_tree.nodes if n.type in ("BSDF_PRINCIPLED", "BSDF_DIFFUSE")]
        node = found[0] if found else node
    if node is None:
        return np.array(mat.diffuse_color[:3], float), np.zeros(3)
    if node.type == "EMISSION":
        return np.zeros(3), _rgb(node.inputs["Color"]) * _value(node.inputs.get("Strength"), 1.0)
    if node.type == "BSDF_DIFFUSE":
        return _rgb(node.inputs["Color"]), np.zeros(3)
    if node.type == "BSDF_PRINCIPLED":
        base = _rgb(node.inputs["Base Color"])
        diffuse = base * (1.0 - _value(_socket(node, "Metallic"))) * \
            (1.0 - _value(_socket(node, "Transmission Weight", "Transmission")))
        colour = _socket(node, "Emission Color", "Emission")
        emission = _rgb(colour) * _value(_socket(node, "Emission Strength"), 1.0) if colour else np.zeros(3)
        return diffuse, emission
    return np.array(mat.diffuse_color[:3], float), np.zeros(3)


def unwrap_into(obj, uv_name: str, unwrap: Callable[[], None]) -> None:
    """Run a UV operator (`unwrap`, called in edit mode with all faces selected) into `uv_name`,
    creating the layer if needed; the active UV layer, selection and mode are restored."""
    me = obj.data
    previous = me.uv_layers.active.name if me.uv_layers.active else None
    view_layer = bpy.context.view_layer
    selected = [o for o in view_layer.objects if o.select_get()]
    active = view_layer.objects.active
    if uv_name not in me.uv_layers:
        me.uv_layers.new(name=uv_name)
    me.uv_layers.active = me.uv_layers[uv_name]
    try:
        for other in selected:
            other.select_set(False)
        obj.select_set(True)
        view_layer.objects.active = obj
        bpy.ops.object.mode_set(mode="EDIT")
        bpy.ops.mesh.select_all(action="SELECT")
        unwrap()
        bpy.ops.object.mode_set(mode="OBJECT")
    finally:
        obj.select_set(False)
        for other in selected:
            other.select_set(True)
        view_layer.objects.active = active
    if previous is not None and previous in me.uv_layers:
        me.uv_layers.active = me.uv_layers[previous]


def ensure_lightmap_uv(obj, uv_name: str, margin: float = 1.0) -> bool:
    """Create `uv_name` with Blender's Lightmap Pack when it is missing; keep the active UV layer.
    Returns True when the layer was created."""
    if uv_name in obj.data.uv_layers:
        return False
    unwrap_into(obj, uv_name, lambda: bpy.ops.uv.lightmap_pack(
        PREF_CONTEXT="ALL_FACES", PREF_PACK_IN_ONE=True, PREF_NEW_UVLAYER=False, PREF_MARGIN_DIV=margin))
    return True


def remove_uv_layers(bl_scene, created: Iterable) -> None:
    """Undo `ensure_lightmap_uv` for (object name, layer) pairs, e.g. after a cancelled bake."""
    for name, layer in created:
        obj = bl_scene.objects.get(name)
        if obj is not None and layer in obj.data.uv_layers:
            obj.data.uv_layers.remove(obj.data.uv_layers[layer])


def _world_radiance(world) -> np.ndarray:
    if world is None:
        return np.zeros(3)
    if _has_nodes(world):
        for node in world.node_tree.nodes:
            if node.type == "OUTPUT_WORLD" and node.is_active_output:
                surf = node.inputs.get("Surface")
                if surf is not None and surf.is_linked and surf.links[0].from_node.type == "BACKGROUND":
                    bg = surf.links[0].from_node
                    return _rgb(bg.inputs["Color"]) * _value(bg.inputs.get("Strength"), 1.0)
                return np.zeros(3)
        return np.zeros(3)
    return np.array(world.color[:3], float)


def scene_bounces(bl_scene) -> int:
    """Cycles' Light Paths › Diffuse bounces, capped by Total bounces."""
    cycles = getattr(bl_scene, "cycles", None)
    if cycles is None:
        return 4
    return int(min(cycles.diffuse_bounces, cycles.max_bounces))


def export_scene(bl_scene, depsgraph=None, objects: Optional[Iterable[str]] = None,
                 uv_layer=None, resolution=0, log: Callable[[str], None] = print,
                 created: Optional[list] = None, max_bytes: Optional[int] = None) -> Scene:
    """The scene as F12 renders it (`render_evaluation`): every rendered mesh, curve, surface, text
    and metaball, and every instance of one, is geometry in world space; `objects` (default: every
    rendered mesh object) get lightmaps, and must be real mesh objects. `depsgraph` only names the
    view layer (default: the context's); a render depsgraph is used as it is.

    `uv_layer` names the lightmap UV layer: one name for all, or {object name: layer} for some; a
    named layer must exist. Objects with no name given use DEFAULT_UV, created by Lightmap Pack
    where missing (said through `log`, and listed in `created` as (object, layer) so a cancelled
    bake can remove it again). `resolution` is one size for all or {object name: size}.
    `max_bytes` limits the flattened geometry (BakeError naming the biggest contributors)."""
    view_layer = depsgraph.view_layer if depsgraph is not None else bpy.context.view_layer
    rendered = rendered_names(view_layer)
    if objects is None:
        targets = [o for o in bl_scene.objects if o.type == "MESH" and o.name in rendered
                   and not holdout(o, view_layer)]
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
            if holdout(obj, view_layer):
                raise BakeError(f"object '{name}' is a holdout, which Cycles bakes black: turn Holdout off "
                                "to bake it")
            targets.append(obj)
    if not targets:
        raise BakeError(f"scene '{bl_scene.name}' has no rendered mesh object to bake")
    named = uv_layer if isinstance(uv_layer, dict) else {o.name: uv_layer for o in targets if uv_layer}
    for obj in targets:
        layer = named.get(obj.name)
        if layer is not None and layer not in obj.data.uv_layers:
            raise BakeError(f"object '{obj.name}' has no UV layer '{layer}'")
    layers = {o.name: named.get(o.name) or DEFAULT_UV for o in targets}
    for obj in targets:
        if ensure_lightmap_uv(obj, layers[obj.name]):
            log(f"object '{obj.name}': created UV layer '{layers[obj.name]}' with Lightmap Pack")
            if created is not None:
                created.append((obj.name, layers[obj.name]))

    collector = Collector(layers, log, material_albedo_emission)
    if depsgraph is not None and depsgraph.mode == "RENDER":
        collector(depsgraph)
    else:
        render_evaluation(bl_scene, view_layer, collector)
    for name in layers:
        if name not in collector.found:
            if objects is not None:
                raise BakeError(f"object '{name}' is not in the render (F12 does not show it), so it cannot be baked")
            log(f"object '{name}' is not in the render (F12 does not show its own faces): not baked")
    for reason, names in collector.left_out.items():
        log(f"left out ({reason}): {', '.join(names[:5])}" + (f" and {len(names) - 5} more" if len(names) > 5 else ""))
    (pos, nrm, uvs, alb, emi), objs, stats = flatten(collector, resolution, max_bytes, strict=objects is not None)
    scene = Scene(positions=pos, normals=nrm, uvs=uvs, albedo=alb, emission=emi, objects=objs,
                  lights=collector.lights, world=_world_radiance(bl_scene.world),
                  default_bounces=scene_bounces(bl_scene))
    scene.export_stats = stats
    return scene



# --------------------------------------------------------------------------- images and materials

def load_image(path: str, name: str):
    """Load (or reload) a baked EXR as a linear image datablock named `name`."""
    img = bpy.data.images.get(name)
    if img is not None and bpy.path.abspath(img.filepath) == path:
        img.reload()
        return img
    img = bpy.data.images.load(path, check_existing=False)
    img.name = name
    img.colorspace_settings.is_data = False
    return img


def _base_colour_source(nt):
    """The socket or constant feeding the surface's base colour."""
    for node in nt.nodes:
        if node.type in ("BSDF_PRINCIPLED", "BSDF_DIFFUSE"):
            sock = node.inputs["Base Color" if node.type == "BSDF_PRINCIPLED" else "Color"]
            if sock.is_linked:
                return sock.links[0].from_socket, None
            return None, tuple(sock.default_value)
    return None, (0.8, 0.8, 0.8, 1.0)


def _wire(mat, image, uv_name: str) -> None:
    """Add the lightmap frame: UV Map → Image × base colour → Emission → an EEVEE output made
    active, so the viewport shows the baked lighting while Cycles keeps the original shading."""
    nt = mat.node_tree
    previous = [n.name for n in nt.nodes if n.type == "OUTPUT_MATERIAL" and n.is_active_output]
    src, const = _base_colour_source(nt)
    frame = nt.nodes.new("NodeFrame")
    frame.name = frame.label = FRAME_NAME
    x0 = max((n.location.x for n in nt.nodes if n is not frame), default=0.0) + 300.0
    uv = nt.nodes.new("ShaderNodeUVMap")
    uv.uv_map = uv_name
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = image
    tex.interpolation = "Linear"
    mix = nt.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    mix.blend_type = "MULTIPLY"
    mix.inputs["Factor"].default_value = 1.0
    emit = nt.nodes.new("ShaderNodeEmission")
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    out.target = "EEVEE"
    for i, node in enumerate((uv, tex, mix, emit, out)):
        node.parent = frame
        node.location = (x0 + 250.0 * i, -400.0)
    nt.links.new(uv.outputs["UV"], tex.inputs["Vector"])
    a, b = mix.inputs[6], mix.inputs[7]  # the RGBA pair of ShaderNodeMix
    if src is not None:
        nt.links.new(src, a)
    else:
        a.default_value = const
    nt.links.new(tex.outputs["Color"], b)
    nt.links.new(mix.outputs[2], emit.inputs["Color"])
    nt.links.new(emit.outputs["Emission"], out.inputs["Surface"])
    out.is_active_output = True
    mat[REVERT_KEY] = json.dumps({"active_outputs": previous})


def _unwire(mat) -> None:
    nt = mat.node_tree
    frame = nt.nodes.get(FRAME_NAME)
    if frame is not None:
        for node in [n for n in nt.nodes if n.parent == frame]:
            nt.nodes.remove(node)
        nt.nodes.remove(frame)
    state = json.loads(mat.get(REVERT_KEY, "{}"))
    for name in state.get("active_outputs", []):
        node = nt.nodes.get(name)
        if node is not None:
            node.is_active_output = True
    if REVERT_KEY in mat:
        del mat[REVERT_KEY]


def _use_nodes(mat) -> None:
    """Blender 5 gives every material a node tree and deprecates `use_nodes`."""
    if mat.node_tree is None or bpy.app.version < (5, 0, 0):
        mat.use_nodes = True


def apply_lightmap(obj, image, uv_name: str, shared: bool = False) -> None:
    """Show `image` on `obj`'s materials. A material other baked objects also use is copied for
    this object (`shared`), and so is every material of a mesh other objects share (the copy goes
    in an object-level slot, so the other objects keep theirs); an empty slot gets a new material.
    All of it is undone by `revert`."""
    if REVERT_KEY in obj:
        raise BakeError(f"object '{obj.name}' already shows a lightmap: revert it first")
    record = {"slots": [], "added_slots": 0, "image": image.name}
    if not obj.material_slots:
        obj.data.materials.append(None)
        record["added_slots"] = 1
    shared_mesh = obj.data.users > 1
    for index, slot in enumerate(obj.material_slots):
        entry = {"index": index, "original": slot.material.name if slot.material else None,
                 "copy": None, "link": slot.link}
        original = slot.material
        if shared_mesh and slot.link == "DATA":
            slot.link = "OBJECT"
            entry["object_material"] = slot.material.name if slot.material else None
        if original is None:
            mat = bpy.data.materials.new(f"{obj.name} lightmap")
            _use_nodes(mat)
            entry["copy"] = mat.name
            slot.material = mat
        elif shared or shared_mesh or not _has_nodes(original):
            mat = original.copy()
            mat.name = f"{original.name} ({obj.name} lightmap)"
            _use_nodes(mat)
            if mat.node_tree.nodes.get(FRAME_NAME) is not None:
                _unwire(mat)  # copied from a material that shows another lightmap
            entry["copy"] = mat.name
            slot.material = mat
        else:
            mat = original
        record["slots"].append(entry)
        if mat.node_tree.nodes.get(FRAME_NAME) is None:
            _wire(mat, image, uv_name)
    obj[REVERT_KEY] = json.dumps(record)


def revert(obj) -> bool:
    """Undo `apply_lightmap` on one object exactly; False when there was nothing to undo."""
    if REVERT_KEY not in obj:
        return False
    record = json.loads(obj[REVERT_KEY])
    for entry in record["slots"]:
        index, original, copy = entry["index"], entry["original"], entry["copy"]
        slot = obj.material_slots[index] if index < len(obj.material_slots) else None
        if copy is not None:
            made = bpy.data.materials.get(copy)
            if slot is not None:
                if "object_material" in entry:  # we switched this slot to object level
                    slot.material = bpy.data.materials.get(entry["object_material"] or "")
                    slot.link = entry["link"]
                else:
                    slot.material = bpy.data.materials.get(original) if original else None
            if made is not None and made.users == 0:
                bpy.data.materials.remove(made)
        elif original is not None:
            mat = bpy.data.materials.get(original)
            if mat is not None and mat.node_tree:
                _unwire(mat)
    for _ in range(record.get("added_slots", 0)):
        obj.data.materials.pop()
    del obj[REVERT_KEY]
    img = bpy.data.images.get(record.get("image", ""))
    if img is not None and img.users == 0:
        bpy.data.images.remove(img)
    return True


def apply_all(bl_scene, files: dict, uv_layer, estimator: str, objects: Optional[dict] = None,
              copy_materials: bool = False) -> list:
    """Load each baked EXR and wire it into its object's materials; returns the objects.
    `uv_layer`: one name, {object name: name}, or None for DEFAULT_UV. `objects` maps a lightmap's
    object name to the object to apply it to (default: the scene's object of that name);
    `copy_materials` gives each object its own material copies even when nobody shares them."""
    targets = {}
    for name in files:
        obj = (objects or {}).get(name) or bl_scene.objects.get(name)
        if obj is not None:
            targets[name] = obj
    users: dict = {}
    for obj in targets.values():
        for slot in obj.material_slots:
            if slot.material is not None:
                users.setdefault(slot.material.name, set()).add(obj.name)
    for name, obj in targets.items():
        exr = [p for p in files[name] if p.endswith(".exr")]
        if not exr:
            raise BakeError("applying lightmaps needs the EXR format in 'formats'")
        layer = uv_layer.get(name) if isinstance(uv_layer, dict) else uv_layer
        revert(obj)  # a new bake replaces the last one
        image = load_image(exr[0], f"{obj.name}.{estimator}")
        shared = copy_materials or any(len(users.get(s.material.name, ())) > 1
                                       for s in obj.material_slots if s.material)
        apply_lightmap(obj, image, layer or DEFAULT_UV, shared)
    return list(targets.values())


# --------------------------------------------------------------------------- Cycles reference

def cycles_bake(bl_scene, object_names: Iterable[str], uv_name: str = DEFAULT_UV, resolution: int = 64,
                samples: int = 256, bounces: Optional[int] = None, margin: int = 0,
                seed: int = 0) -> dict:
    """Cycles' own Diffuse bake (DIRECT+INDIRECT, no COLOR: E/π, our unit) of each object, as
    (H, W, 3) float32 arrays with row 0 at the bottom. Render settings, selection, nodes and
    images are restored afterwards; this is the reference every quality test compares against."""
    cyc = bl_scene.cycles
    saved = {k: getattr(cyc, k) for k in ("device", "samples", "use_adaptive_sampling", "use_denoising",
                                          "sample_clamp_direct", "sample_clamp_indirect",
                                          "diffuse_bounces", "seed")}
    engine = bl_scene.render.engine
    view_layer = bpy.context.view_layer
    selected = [o for o in view_layer.objects if o.select_get()]
    active = view_layer.objects.active
    out = {}
    try:
        bl_scene.render.engine = "CYCLES"
        cyc.device = "CPU"
        cyc.samples = int(samples)
        cyc.use_adaptive_sampling = False
        cyc.use_denoising = False
        cyc.sample_clamp_direct = 0.0
        cyc.sample_clamp_indirect = 0.0
        cyc.seed = int(seed)
        if bounces is not None:
            cyc.diffuse_bounces = int(bounces)
        for name in object_names:
            obj = bl_scene.objects[name]
            img = bpy.data.images.new(f"detp_bake reference {name}", resolution, resolution,
                                      alpha=False, float_buffer=True)
            added = []
            try:
                for slot in obj.material_slots:
                    mat = slot.material
                    if mat is None or mat.node_tree is None:
                        raise BakeError(f"object '{name}': Cycles bake needs node materials in every slot")
                    node = mat.node_tree.nodes.new("ShaderNodeTexImage")
                    node.image = img
                    previous = mat.node_tree.nodes.active
                    mat.node_tree.nodes.active = node
                    added.append((mat, node, previous))
                for o in view_layer.objects:
                    o.select_set(False)
                obj.select_set(True)
                view_layer.objects.active = obj
                res = bpy.ops.object.bake(type="DIFFUSE", pass_filter={"DIRECT", "INDIRECT"},
                                          uv_layer=uv_name, margin=int(margin), margin_type="EXTEND",
                                          use_clear=True, target="IMAGE_TEXTURES")
                if "FINISHED" not in res:
                    raise BakeError(f"object '{name}': Cycles bake did not finish")
                px = np.empty(resolution * resolution * 4, np.float32)
                img.pixels.foreach_get(px)
                out[name] = px.reshape(resolution, resolution, 4)[..., :3].copy()
            finally:
                for mat, node, previous in added:
                    mat.node_tree.nodes.remove(node)
                    if previous is not None:
                        mat.node_tree.nodes.active = previous
                bpy.data.images.remove(img)
    finally:
        for k, v in saved.items():
            setattr(cyc, k, v)
        bl_scene.render.engine = engine
        for o in view_layer.objects:
            o.select_set(o in selected)
        view_layer.objects.active = active
    return out
