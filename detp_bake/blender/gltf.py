"""A baked scene as a .glb through Blender's own glTF exporter, each baked object's lightmap on its
materials as MOZ_lightmap (docs/gltf.md).

The exporter writes the scene; a user extension of the exporter (`glTF2ExportUserExtension`, found
by the exporter in an enabled add-on's module, so this module is listed as one for the export's
duration) adds the lightmap to each material it gathers. For that the scene is prepared, and put
back exactly afterwards, whatever happens (`_prepared`):

- each baked object gets a temporary copy of its mesh whose UV layers run render UVs first (glTF's
  TEXCOORD_0), then the lightmap layer (TEXCOORD_1), then the rest: the exporter writes UV layers
  in order;
- each of its material slots gets a temporary copy of the user's own material, one per (material,
  lightmap image) pair, without the node frame *Apply* wires in: the exporter keeps one glTF
  material per Blender material, and a lightmap is per object.
"""
from __future__ import annotations

import contextlib
import json
import os
from pathlib import Path
from typing import Callable, Optional

import bpy
import numpy as np

from ..errors import BakeError
from ..lightmap import encoding, images, sh
from . import gltf_probes
from .atlas import ATLAS_UV, lightmap_of
from .lightmaps import unwire
from .common import DEFAULT_UV, FRAME_NAME, REVERT_KEY

EXTENSION = "MOZ_lightmap"
ENCODING = "RGBE"
TEMP = " (detp_bake glTF)"  # the temporary copies' names end with this
# glTF sampler constants. Nearest: blending RGBE bytes is not blending light (a GPU's bilinear filter
# before decoding is off by 2-5 % on average, benchmarks/encoding.py); decode four texels, then blend.
NEAREST, LINEAR, CLAMP = 9728, 9729, 33071
# A --directional sh bake's L1 as three more textures per lightmap (docs/gltf.md).
SH_EXTENSION = "DETP_lightmap_sh"
SH_ENCODING = "L1/L0 8-bit"
SH_SPACE = "world glTF (y up)"


def _section(out_dir, estimator: Optional[str]) -> tuple[str, dict, Path]:
    """The estimator, its section of report.json in `out_dir` and the report's path."""
    out_dir = Path(out_dir)
    path = out_dir / "report.json"
    try:
        report = json.loads(path.read_text())
    except FileNotFoundError:
        raise BakeError(f"no report.json in '{out_dir}': give the output folder of a bake") from None
    except (OSError, ValueError) as exc:
        raise BakeError(f"cannot read '{path}': {exc}") from None
    if "frames" in report:
        raise BakeError(f"'{path}' is a frame range's report: the glTF export takes one bake")
    sections = report.get("estimators") or {report.get("settings", {}).get("estimator") or report.get("estimator"):
                                            report}
    if estimator is None and len(sections) > 1:
        raise BakeError(f"'{path}' holds lightmaps of {', '.join(sections)}: choose one with --estimator")
    estimator = estimator or next(iter(sections))
    if estimator not in sections:
        raise BakeError(f"'{path}' has no {estimator} lightmaps (it has {', '.join(map(str, sections))})")
    return estimator, sections[estimator], path


def _located(listed: str, out_dir) -> str:
    """A file report.json names, or the one of that name in `out_dir` (a moved folder)."""
    return listed if os.path.isfile(listed) else str(Path(out_dir) / os.path.basename(listed))


def lightmap_files(out_dir, estimator: Optional[str] = None) -> tuple[str, dict]:
    """The estimator and {object name: EXR path} of the bake in `out_dir`, read off its report.json
    (a comparison's: the section of `estimator`). Objects whose entries name the same EXR (an atlas)
    share that path and so one image."""
    estimator, section, path = _section(out_dir, estimator)
    files = {}
    for entry in section.get("objects", []):
        exr = [p for p in entry.get("files", []) if p.endswith(f".{estimator}.exr") and not p.endswith(".raw.exr")]
        if not exr:
            raise BakeError(f"object '{entry['name']}' has no EXR lightmap in '{path}': bake with the exr format")
        found = _located(exr[0], out_dir)
        if not os.path.isfile(found):
            raise BakeError(f"lightmap '{exr[0]}' of object '{entry['name']}' is missing")
        files[entry["name"]] = found
    if not files:
        raise BakeError(f"'{path}' lists no baked objects")
    return estimator, files


def sh_files(out_dir, estimator: str) -> dict:
    """{lightmap EXR path: (L1x, L1y, L1z EXR paths)} of the objects whose report entry lists all three
    per-axis files of a `--directional sh` bake; empty for any other bake."""
    _, section, _ = _section(out_dir, estimator)
    found = {}
    for entry in section.get("objects", []):
        listed = entry.get("files", [])
        exr = [p for p in listed if p.endswith(f".{estimator}.exr") and not p.endswith(".raw.exr")]
        axes = [next((p for p in listed if p.endswith(f".{estimator}.{a}.exr")), None) for a in sh.AXIS_FILES]
        if exr and all(axes):
            paths = [_located(p, out_dir) for p in axes]
            missing = [p for p in paths if not os.path.isfile(p)]
            if missing:
                raise BakeError(f"L1 map '{missing[0]}' of object '{entry['name']}' is missing")
            found[_located(exr[0], out_dir)] = tuple(paths)
    return found


def sh_pngs(exr: str, axes: tuple) -> list:
    """The three DETP_lightmap_sh PNGs of one lightmap: L1/L0 per glTF axis. glTF is y up: its
    (x, y, z) is Blender's (x, z, −y), as the exporter writes POSITION."""
    l0 = images.read_image(exr)[::-1][..., :3]
    x, y, z = (images.read_image(a)[::-1][..., :3] for a in axes)
    return [encoding.png_bytes(encoding.ratio_encode(l0, l1)) for l1 in (x, z, -y)]


def _targets(bl_scene, files: dict, uv_layer) -> dict:
    """{object: lightmap UV layer name} for the baked objects, every one checked first."""
    targets = {}
    for name in files:
        obj = bl_scene.objects.get(name)
        if obj is None:
            raise BakeError(f"object '{name}' of report.json is not in scene '{bl_scene.name}'")
        if obj.type != "MESH":
            raise BakeError(f"object '{name}' of report.json is not a mesh")
        layer = (uv_layer.get(name) if isinstance(uv_layer, dict) else uv_layer) or DEFAULT_UV
        if layer not in obj.data.uv_layers:
            raise BakeError(f"object '{name}' has no UV layer '{layer}' (its lightmap's UVs)")
        targets[obj] = layer
    return targets


def export_gltf(bl_scene, out_dir, path, estimator: Optional[str] = None, uv_layer=None,
                log: Callable[[str], None] = print) -> dict:
    """Write `bl_scene` to the .glb `path` with the lightmaps of the bake in `out_dir`; the scene is
    left exactly as it was. `uv_layer`: one name, {object name: name}, or None for DEFAULT_UV.
    Returns a summary: the file, the estimator, the objects and images."""
    path = Path(path).resolve()
    if path.suffix.lower() != ".glb":
        raise BakeError(f"'{path}': the glTF export writes a binary .glb file")
    images.check_writable_dir(path.parent)
    estimator, files = lightmap_files(out_dir, estimator)
    # An object in an atlas shows it through the atlas UV layer (blender/atlas.py).
    layers = dict(uv_layer) if isinstance(uv_layer, dict) else dict.fromkeys(files, uv_layer) if uv_layer else {}
    for name, (image, _) in lightmap_of(bl_scene, {n: [p] for n, p in files.items()}).items():
        if image != name:
            layers[name] = ATLAS_UV
    targets = _targets(bl_scene, files, layers or None)
    if bpy.context.scene != bl_scene:
        raise BakeError(f"scene '{bl_scene.name}' is not the active scene: the glTF exporter writes the active one")
    # read_image gives row 0 at the bottom; a glTF image, as the EXR file, starts at the top (v = 1)
    pngs = {exr: encoding.png_bytes(encoding.rgbe_encode(images.read_image(exr)[::-1]))
            for exr in dict.fromkeys(files.values())}
    state = _State(pngs)
    state.sh = {exr: sh_pngs(exr, axes) for exr, axes in sh_files(out_dir, estimator).items() if exr in pngs}
    state.probes = gltf_probes.read(out_dir)
    state.probe_lit = {o.name for o in bl_scene.objects if o.type == "MESH" and gltf_probes.probe_lit(o)} \
        if state.probes else set()
    said = _write(path, targets, files, state)
    warnings = [f"glTF '{path.name}': no lightmap on {said}; written without one"] if said else []
    for warning in warnings:
        log(f"warning: {warning}")
    log(f"exported {path} with {len(pngs)} {estimator} lightmaps on {len(targets)} objects"
        + (f", SH L1 maps of {len(state.sh)} ({SH_EXTENSION})" if state.sh else "")
        + (f", {sum(len(g) for g in state.probes)} light probes lighting {len(state.probe_lit)} objects "
           f"({gltf_probes.EXTENSION})" if state.probes else ""))
    return {"gltf": str(path), "estimator": estimator, "objects": sorted(files), "images": len(pngs),
            "warnings": warnings, **({"sh": len(state.sh)} if state.sh else {}),
            **({"probes": sum(len(g) for g in state.probes), "probe_lit": sorted(state.probe_lit)}
               if state.probes else {})}


def _write(path: Path, targets: dict, files: dict, state: "_State") -> str:
    """Export to `path` under a hidden name, renamed once it holds a lightmap (a failed export leaves
    no file); returns what got none ('' when all did). BakeError when nothing did."""
    partial = path.with_name(f".{path.stem}.partial.glb")
    try:
        with _prepared(targets, files, state), _listed_as_addon():
            try:
                result = bpy.ops.export_scene.gltf(
                    filepath=str(partial), export_format="GLB", use_active_scene=True, use_renderable=True,
                    export_apply=True, export_texcoords=True, export_normals=True, export_materials="EXPORT",
                    export_cameras=True, export_animations=False)
            except RuntimeError as exc:
                raise BakeError(f"glTF export of '{path}' failed: {exc}") from None
        lit, unlit = _lightmapped(partial, files) if "FINISHED" in result and partial.is_file() else (0, [])
        said = _unlit_text(unlit, state)
        if not lit:
            raise BakeError(f"glTF export of '{path}' failed: no exported mesh carries a lightmap"
                            + (f" (none on {said})" if said else ""))
        os.replace(partial, path)
        return said
    finally:
        partial.unlink(missing_ok=True)


def _lightmapped(glb: Path, files: dict) -> tuple[int, list]:
    """(primitives with a lightmap, [(object, its material's name, why)] of those without) in the
    written .glb; a baked object the export left out counts as one without."""
    data = glb.read_bytes()
    doc = json.loads(data[20:20 + int.from_bytes(data[12:16], "little")])
    lit, unlit, seen = 0, [], set()
    for node in doc.get("nodes", []):
        if "mesh" not in node:
            continue
        seen.add(node.get("name"))
        if gltf_probes.EXTENSION in (node.get("extensions") or {}):
            continue  # lit by the probes, not by a lightmap (Probe Light)
        for prim in doc["meshes"][node["mesh"]].get("primitives", []):
            material = doc["materials"][prim["material"]] if "material" in prim else {}
            if EXTENSION in (material.get("extensions") or {}):
                lit += 1
            else:
                why = "material" if node.get("name") in files else "not baked"
                unlit.append((node.get("name"), material.get("name", ""), why))
    unlit += [(name, "", "not exported") for name in sorted(set(files) - seen)]
    return lit, unlit


def _unlit_text(unlit: list, state: "_State") -> str:
    """What has no lightmap, each object or material once, and any error of the export's hook."""
    items = []
    for obj, material, why in unlit:
        if why == "material":
            items.append(f"material '{material.removesuffix(TEMP)}' of object '{obj}'")
        elif why == "not exported":
            items.append(f"object '{obj}' (baked, but not in the export: is it rendered?)")
        else:
            items.append(f"object '{obj}' (not baked)")
    items = list(dict.fromkeys(items))
    text = ", ".join(items[:8]) + (f" and {len(items) - 8} more" if len(items) > 8 else "")
    return "; ".join(([text] if text else []) + state.errors)


class _State:
    """What the export hook reads: which temporary material shows which lightmap, and names to
    give back; filled by `_prepared`."""

    def __init__(self, pngs: dict):
        self.pngs = pngs  # EXR path -> RGBE PNG bytes
        self.materials = {}  # temporary material name -> EXR path
        self.pairs = {}  # (user's material name, EXR path) -> temporary material name
        self.gltf_names = {}  # temporary material or mesh name -> the name the glTF shows
        self.textures = {}  # EXR path -> glTF texture, made once
        self.sh = {}  # EXR path -> the three L1/L0 PNGs (x, y, z in glTF's axes) of a --directional sh bake
        self.probes = []  # the bake's probe grids, in glTF's axes (gltf_probes.py)
        self.probe_lit = set()  # names of the objects lit by them
        self.sampler = None  # the one sampler all lightmaps share
        self.linear = None  # the L1/L0 maps' sampler: ratios may be blended
        self.done, self.errors = set(), []


_STATE: Optional[_State] = None


class glTF2ExportUserExtension:
    """The exporter's hook: MOZ_lightmap on the materials of baked objects, the user's names on
    the temporary copies. The exporter logs and swallows a hook's exceptions, so they are kept."""

    def gather_material_hook(self, gltf_material, blender_material, export_settings):
        state = _STATE
        name = getattr(blender_material, "original", blender_material).name
        if state is None:
            return
        if name not in state.materials:  # a probe-lit object's material (_without_probe_frame)
            if name in state.gltf_names:
                gltf_material.name = state.gltf_names[name]
            return
        try:
            exr = state.materials[name]
            gltf_material.name = state.gltf_names[name]
            if gltf_material.extensions is None:
                gltf_material.extensions = {}
            gltf_material.extensions[EXTENSION] = _extension(state, exr)
            if exr in state.sh:
                gltf_material.extensions[SH_EXTENSION] = _sh_extension(state, exr)
            state.done.add(name)
        except Exception as exc:  # noqa: BLE001 (the exporter would hide it)
            state.errors.append(f"material '{name}': {exc!r}")

    def gather_scene_hook(self, gltf_scene, blender_scene, export_settings):
        state = _STATE
        if state is None or not state.probes:
            return
        try:
            if gltf_scene.extensions is None:
                gltf_scene.extensions = {}
            gltf_scene.extensions[gltf_probes.EXTENSION] = gltf_probes.scene_extension(state.probes)
        except Exception as exc:  # noqa: BLE001 (the exporter would hide it)
            state.errors.append(f"light probes: {exc!r}")

    def gather_node_hook(self, gltf_node, blender_object, export_settings):
        state = _STATE
        if state is not None and getattr(blender_object, "name", None) in state.probe_lit:
            if gltf_node.extensions is None:
                gltf_node.extensions = {}
            gltf_node.extensions[gltf_probes.EXTENSION] = gltf_probes.node_extension()

    def gather_mesh_hook(self, gltf_mesh, blender_mesh, blender_object, vertex_groups, modifiers, materials,
                         export_settings):
        state = _STATE
        name = getattr(blender_mesh, "original", blender_mesh).name
        if state is not None and name in state.gltf_names:
            gltf_mesh.name = state.gltf_names[name]


def _extension(state: _State, exr: str):
    """The MOZ_lightmap of a material: one texture per lightmap image, its PNG in the .glb."""
    from io_scene_gltf2.io.com import gltf2_io
    from io_scene_gltf2.io.com.gltf2_io_extensions import Extension
    from io_scene_gltf2.io.exp.binary_data import BinaryData
    texture = state.textures.get(exr)
    if texture is None:
        stem = os.path.basename(exr)[:-len(".exr")]
        image = gltf2_io.Image(buffer_view=BinaryData(state.pngs[exr]), extensions=None, extras=None,
                               mime_type="image/png", name=stem, uri=None)
        if state.sampler is None:
            state.sampler = gltf2_io.Sampler(extensions=None, extras=None, mag_filter=NEAREST, min_filter=NEAREST,
                                             name=None, wrap_s=CLAMP, wrap_t=CLAMP)
        texture = state.textures[exr] = gltf2_io.Texture(extensions=None, extras=None, name=stem,
                                                         sampler=state.sampler, source=image)
    return Extension(name=EXTENSION, required=False, extension={
        "index": texture, "texCoord": 1, "intensity": 1.0, "extras": {"encoding": ENCODING}})


def _sh_extension(state: _State, exr: str):
    """DETP_lightmap_sh of a material: its lightmap's three L1/L0 textures, made once per lightmap."""
    from io_scene_gltf2.io.com import gltf2_io
    from io_scene_gltf2.io.com.gltf2_io_extensions import Extension
    from io_scene_gltf2.io.exp.binary_data import BinaryData
    if state.linear is None:
        state.linear = gltf2_io.Sampler(extensions=None, extras=None, mag_filter=LINEAR, min_filter=LINEAR,
                                        name=None, wrap_s=CLAMP, wrap_t=CLAMP)
    textures = []
    for axis, png in zip("xyz", state.sh[exr]):
        key = (exr, axis)
        if key not in state.textures:
            stem = f"{os.path.basename(exr)[:-len('.exr')]}.L1{axis}"
            image = gltf2_io.Image(buffer_view=BinaryData(png), extensions=None, extras=None,
                                   mime_type="image/png", name=stem, uri=None)
            state.textures[key] = gltf2_io.Texture(extensions=None, extras=None, name=stem,
                                                   sampler=state.linear, source=image)
        textures.append(state.textures[key])
    return Extension(name=SH_EXTENSION, required=False, extension={
        "l1": textures, "texCoord": 1, "encoding": SH_ENCODING, "space": SH_SPACE})


@contextlib.contextmanager
def _listed_as_addon():
    """The exporter looks for user extensions in the modules of enabled add-ons: this module is
    listed as one while the export runs, then the list (and its unsaved mark) is as before."""
    global _STATE
    prefs = bpy.context.preferences
    dirty = prefs.is_dirty
    entry = prefs.addons.new()
    entry.module = __name__
    try:
        yield
    finally:
        prefs.addons.remove(entry)
        prefs.is_dirty = dirty
        _STATE = None


@contextlib.contextmanager
def _prepared(targets: dict, files: dict, state: _State):
    """The scene as the exporter should see it (module docstring), put back on the way out."""
    global _STATE
    meshes, made, slots = {}, [], []
    try:
        for obj, layer in targets.items():
            original = obj.data
            copy = original.copy()
            copy.name = original.name + TEMP
            meshes[obj] = original
            made.append(copy)
            state.gltf_names[copy.name] = original.name
            _order_uvs(copy, layer)
            obj.data = copy
            used = _used_slots(copy, len(obj.material_slots))
            for index, slot in enumerate(obj.material_slots):
                if index not in used:  # a slot no face uses: the exporter leaves it out
                    continue
                temp = _material_for(obj, index, files[obj.name], state, made)
                if slot.link == "OBJECT":
                    slots.append((slot, slot.material))
                    slot.material = temp
                else:
                    copy.materials[index] = temp
            if not obj.material_slots:
                copy.materials.append(_material_for(obj, 0, files[obj.name], state, made))
        for name in state.probe_lit - {o.name for o in targets}:
            _without_probe_frame(bpy.data.objects[name], state, made, slots)
        _name_split_materials(state)
        _STATE = state
        yield
    finally:
        _STATE = None
        for slot, material in reversed(slots):
            slot.material = material
        for obj, original in meshes.items():
            obj.data = original
        for block in reversed(made):
            (bpy.data.meshes if isinstance(block, bpy.types.Mesh) else bpy.data.materials).remove(block)


def _used_slots(mesh, slots: int) -> set:
    """The material slots some face of `mesh` uses (an index past the last slot is the last's)."""
    index = np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("material_index", index)
    return set(np.clip(np.unique(index), 0, max(slots - 1, 0)).tolist())


def _user_material(obj, index: int):
    """The material the user gave slot `index`: the one *Apply* replaced by a copy, if it did."""
    slot = obj.material_slots[index] if index < len(obj.material_slots) else None
    record = json.loads(obj[REVERT_KEY]) if REVERT_KEY in obj else {"slots": []}
    for entry in record["slots"]:
        if entry["index"] == index and entry["copy"] is not None:
            return bpy.data.materials.get(entry["original"]) if entry["original"] else None
    return slot.material if slot is not None else None


def _material_for(obj, index: int, exr: str, state: _State, made: list):
    """The temporary material of slot `index`, one per (user's material, lightmap image)."""
    user = _user_material(obj, index)
    key = (user.name if user is not None else f"{obj.name} lightmap", exr)
    if key in state.pairs:
        return bpy.data.materials[state.pairs[key]]
    if user is not None:
        temp = user.copy()
    else:
        temp = bpy.data.materials.new(key[0])
        if temp.node_tree is None or bpy.app.version < (5, 0, 0):
            temp.use_nodes = True  # Blender 5 gives every material a node tree
    temp.name = key[0] + TEMP
    made.append(temp)
    if temp.node_tree is not None and temp.node_tree.nodes.get(FRAME_NAME) is not None:
        unwire(temp)
    state.materials[temp.name] = exr
    state.pairs[key] = temp.name
    state.gltf_names[temp.name] = key[0]
    return temp


def _without_probe_frame(obj, state: _State, made: list, slots: list) -> None:
    """A probe-lit object's slots show the user's own material (a temporary copy without the probe
    frame *Apply* wired in), so the glTF carries its real shading."""
    for index, slot in enumerate(obj.material_slots):
        user = gltf_probes.user_material_of(obj, index, FRAME_NAME, _user_material)
        if user is None:
            continue
        temp = user.copy()
        temp.name = user.name + TEMP
        made.append(temp)
        if temp.node_tree.nodes.get(FRAME_NAME) is not None:
            unwire(temp)
        state.gltf_names[temp.name] = user.name
        slots.append((slot, slot.material))
        slot.material = temp


def _name_split_materials(state: _State) -> None:
    """A material split over several lightmaps is named after each: 'White (Floor.texel_histogram)'."""
    images_of = {}
    for user, exr in state.pairs:
        images_of.setdefault(user, set()).add(exr)
    for (user, exr), temp in state.pairs.items():
        if len(images_of[user]) > 1:
            state.gltf_names[temp] = f"{user} ({os.path.basename(exr)[:-len('.exr')]})"


def _order_uvs(mesh, lightmap: str) -> None:
    """Render UVs first, the lightmap layer second, the rest after, render UVs active: glTF's
    TEXCOORD_0 and TEXCOORD_1. A mesh with only the lightmap layer gets a copy of it first."""
    layers = mesh.uv_layers
    names = [layer.name for layer in layers]
    render = next((n for n in names if layers[n].active_render and n != lightmap), None)
    render = render or next((n for n in names if n != lightmap), None)
    data = {}
    for name in names:
        uv = np.empty(2 * len(mesh.loops), np.float32)
        layers[name].uv.foreach_get("vector", uv)
        data[name] = uv
    order = [render, lightmap] + [n for n in names if n not in (render, lightmap)]
    for name in names:
        layers.remove(layers[name])
    for name in order:
        layer = layers.new(name=name or lightmap + " render", do_init=False)
        layer.uv.foreach_set("vector", data[name or lightmap])
    layers.active_index = 0
    layers[0].active_render = True
