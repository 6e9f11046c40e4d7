"""Baked images back into Blender: load them, wire them into the objects' materials under a node
frame, and undo exactly that (`revert`), recorded on the object."""
from __future__ import annotations

import json
from typing import Callable, Optional

import bpy

from ..errors import BakeError
from ..lightmap import sh
from . import sh_nodes
from .atlas import ATLAS_UV, lightmap_of
from .common import DEFAULT_UV, FRAME_NAME, PROBE_PROPERTY, REVERT_KEY, uses_nodes


def load_image(path: str, name: str, sequence: bool = False, data: bool = False):
    """Load (or reload) a baked EXR as a linear image datablock named `name`; `sequence`: the
    first file of a numbered image sequence (<object>.<estimator>.<frame:04d>.exr); `data`: signed
    numbers no colour transform may touch, alpha a channel of its own (a directional map)."""
    img = bpy.data.images.get(name)
    if img is not None and bpy.path.abspath(img.filepath) == path and (img.source == "SEQUENCE") == sequence:
        img.reload()
        return img
    img = bpy.data.images.load(path, check_existing=False)
    img.name = name
    img.colorspace_settings.is_data = data
    if data:
        img.alpha_mode = "CHANNEL_PACKED"  # the dominant map's directionality: not an opacity
    if sequence:
        img.source = "SEQUENCE"
    return img


def _base_colour_source(nt):
    """The socket or constant feeding the surface's base colour, and the socket feeding its
    normal (a Normal Map or Bump node; None: the surface's own normal)."""
    for node in nt.nodes:
        if node.type in ("BSDF_PRINCIPLED", "BSDF_DIFFUSE"):
            sock = node.inputs["Base Color" if node.type == "BSDF_PRINCIPLED" else "Color"]
            normal = node.inputs["Normal"]
            normal = normal.links[0].from_socket if normal.is_linked else None
            if sock.is_linked:
                return sock.links[0].from_socket, None, normal
            return None, tuple(sock.default_value), normal
    return None, (0.8, 0.8, 0.8, 1.0), None


def _wire(mat, image, uv_name: str, frames: Optional[tuple] = None, l1: Optional[dict] = None) -> None:
    """Add the lightmap frame: UV Map → Image × base colour → Emission → an EEVEE output made
    active, so the viewport shows the baked lighting while Cycles keeps the original shading.
    `frames` (first, last): the image is a sequence whose file numbers are the scene's frames.
    `l1` ({L1x, L1y, L1z: image}): a directional lightmap, shaded by the SH group (sh_nodes.py)
    against the material's normal before the multiply."""
    def light(nt, frame, x0, normal):
        uv = nt.nodes.new("ShaderNodeUVMap")
        uv.uv_map = uv_name
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = image
        tex.interpolation = "Linear"
        if frames is not None:
            # Blender shows file number (frame − frame_start + 1, held within the duration) + offset.
            first, last = frames
            user = tex.image_user
            user.frame_duration = last - first + 1
            user.frame_start = first
            user.frame_offset = first - 1
            user.use_cyclic = False
            user.use_auto_refresh = True
        for i, node in enumerate((uv, tex)):
            node.parent = frame
            node.location = (x0 + 250.0 * i, -400.0)
        nt.links.new(uv.outputs["UV"], tex.inputs["Vector"])
        if l1:
            return sh_nodes.wire(nt, frame, tex.outputs["Color"], l1, uv.outputs["UV"], normal, x0 + 250.0)
        return tex.outputs["Color"]
    wire_light(mat, light)


def wire_light(mat, light: Callable) -> None:
    """Add the node frame that shows baked light: `light(nt, frame, x0, normal)` adds its nodes
    (a lightmap, a probe's SH) and returns the socket of E/π; × base colour → Emission → an EEVEE
    output made active. `normal`: the socket of the surface's shading normal, None for its own."""
    nt = mat.node_tree
    previous = [n.name for n in nt.nodes if n.type == "OUTPUT_MATERIAL" and n.is_active_output]
    src, const, normal = _base_colour_source(nt)
    frame = nt.nodes.new("NodeFrame")
    frame.name = frame.label = FRAME_NAME
    x0 = max((n.location.x for n in nt.nodes if n is not frame), default=0.0) + 300.0
    mix = nt.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    mix.blend_type = "MULTIPLY"
    mix.inputs["Factor"].default_value = 1.0
    emit = nt.nodes.new("ShaderNodeEmission")
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    out.target = "EEVEE"
    for i, node in enumerate((mix, emit, out)):
        node.parent = frame
        node.location = (x0 + 250.0 * (i + 2), -400.0)
    a, b = mix.inputs[6], mix.inputs[7]  # the RGBA pair of ShaderNodeMix
    if src is not None:
        nt.links.new(src, a)
    else:
        a.default_value = const
    nt.links.new(light(nt, frame, x0, normal), b)
    nt.links.new(mix.outputs[2], emit.inputs["Color"])
    nt.links.new(emit.outputs["Emission"], out.inputs["Surface"])
    out.is_active_output = True
    mat[REVERT_KEY] = json.dumps({"active_outputs": previous}, allow_nan=False)


def unwire(mat) -> None:
    """Remove Apply's node frame from material `mat`, its own output active again as before."""
    nt = mat.node_tree
    frame = nt.nodes.get(FRAME_NAME)
    if frame is not None:
        for node in [n for n in nt.nodes if n.parent == frame]:
            nt.nodes.remove(node)
        nt.nodes.remove(frame)
        sh_nodes.remove_unused()
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


def apply_lightmap(obj, image, uv_name: str, shared: bool = False, frames: Optional[tuple] = None,
                   l1: Optional[dict] = None, light: Optional[Callable] = None) -> None:
    """Show `image` on `obj`'s materials. A material other baked objects also use is copied for
    this object (`shared`), and so is every material of a mesh other objects share (the copy goes
    in an object-level slot, so the other objects keep theirs); an empty slot gets a new material.
    `l1` ({L1x, L1y, L1z: image}): shade it as a directional lightmap. `light` (see `wire_light`)
    instead of `image`: other baked light (a probe's SH). All of it is undone by `revert`."""
    if REVERT_KEY in obj:
        raise BakeError(f"object '{obj.name}' already shows a lightmap: revert it first")
    record = {"slots": [], "added_slots": 0, "image": image.name if image is not None else "",
              "l1_images": [i.name for i in (l1 or {}).values()]}
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
        elif shared or shared_mesh or not uses_nodes(original):
            mat = original.copy()
            mat.name = f"{original.name} ({obj.name} lightmap)"
            _use_nodes(mat)
            if mat.node_tree.nodes.get(FRAME_NAME) is not None:
                unwire(mat)  # copied from a material that shows another lightmap
            entry["copy"] = mat.name
            slot.material = mat
        else:
            mat = original
        record["slots"].append(entry)
        if mat.node_tree.nodes.get(FRAME_NAME) is None:
            if light is not None:
                wire_light(mat, light)
            else:
                _wire(mat, image, uv_name, frames, l1)
    obj[REVERT_KEY] = json.dumps(record, allow_nan=False)


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
                unwire(mat)
    added = record.get("added_slots", 0)
    if added and added == len(obj.data.materials):
        obj.data.materials.clear()  # pop() leaves the object's slot count behind (Blender 4.5, 5.2)
    else:
        for _ in range(added):
            obj.data.materials.pop()
    del obj[REVERT_KEY]
    for key in [k for k in obj.keys() if k.startswith(PROBE_PROPERTY)]:
        del obj[key]  # a probe-lit object's SH (blender/probe_light.py)
    sh_nodes.remove_unused()  # a removed copy may have been the last user of the SH group
    for name in [record.get("image", ""), *record.get("l1_images", [])]:
        img = bpy.data.images.get(name)
        if img is not None and img.users == 0:
            bpy.data.images.remove(img)
    return True


def shared_materials(obj, objects) -> set:
    """Names of `obj`'s materials that another of `objects` also uses (those get copies)."""
    others = {s.material.name for o in objects if o is not obj for s in o.material_slots if s.material}
    return {s.material.name for s in obj.material_slots if s.material and s.material.name in others}


def _directional_images(paths: list, estimator: str, image_name: str, notes: set) -> Optional[dict]:
    """A directional bake's images among a lightmap's files, loaded: {L1x, L1y, L1z: image} (sh),
    {"dir": image} (dominant), or None; what Apply cannot show of a shadowmask goes into `notes`."""
    if any(p.endswith(f".{estimator}.shadowmask.exr") for p in paths):
        notes.add(SHADOWMASK_NOTE)
    for names in (sh.AXIS_FILES, ("dir",)):
        found = {n: next((p for p in paths if p.endswith(f".{estimator}.{n}.exr")), None) for n in names}
        if all(found.values()):
            return {n: load_image(path, f"{image_name}.{estimator}.{n}", data=True) for n, path in found.items()}
    return None


SHADOWMASK_NOTE = (
    "shadowmask: Apply shows the lightmap only (with --shadowmask-mode subtract it lacks the masked lights' "
    "direct light): Blender cannot multiply one light by a texture on the receiving surface (EEVEE takes no "
    "light nodes, Cycles' light nodes are evaluated at the light, and a material cannot tell one light's "
    "share from another's); an engine adds each masked light, unshadowed, times its channel of "
    "<object>.<estimator>.shadowmask.exr")


def apply_all(bl_scene, files: dict, uv_layer, estimator: str, objects: Optional[dict] = None,
              copy_materials: bool = False, frames: Optional[tuple] = None,
              log: Optional[Callable[[str], None]] = None) -> list:
    """Load each baked EXR and wire it into its object's materials; returns the objects.
    `uv_layer`: one name, {object name: name}, or None for DEFAULT_UV. `objects` maps a lightmap's
    object name to the object to apply it to (default: the scene's object of that name);
    `copy_materials` gives each object its own material copies even when nobody shares them.
    `frames` (first, last): `files` are the first frame's of a range baked at every frame, shown as
    image sequences that follow the timeline. A directional bake's maps (sh or dominant) are shaded
    against each material's normal; `log` hears what Apply cannot show (a shadowmask)."""
    targets, lightmap = {}, lightmap_of(bl_scene, files)  # an atlas goes to each of its objects
    for name in lightmap:
        obj = (objects or {}).get(name) or bl_scene.objects.get(name)
        if obj is not None:
            targets[name] = obj
    notes = set()
    for name, obj in targets.items():
        image_name, paths = lightmap[name]
        exr = [p for p in paths if p.endswith(".exr")]
        if not exr:
            raise BakeError("applying lightmaps needs the EXR format in 'formats'")
        layer = uv_layer.get(name) if isinstance(uv_layer, dict) else uv_layer
        if image_name != name:  # an atlas: its objects' charts lie in the atlas UV layer
            layer = ATLAS_UV
        revert(obj)  # a new bake replaces the last one
        stem = obj.name if image_name == name else image_name
        image = load_image(exr[0], f"{stem}.{estimator}", sequence=frames is not None)
        l1 = _directional_images(exr, estimator, stem, notes)
        shared = copy_materials or bool(shared_materials(obj, list(targets.values())))
        apply_lightmap(obj, image, layer or DEFAULT_UV, shared, frames, l1)
    for note in sorted(notes):
        if log is not None:
            log(note)
    return list(targets.values())
