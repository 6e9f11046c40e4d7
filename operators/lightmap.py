"""Operators on lightmaps that exist: apply, revert, open in an Image Editor, and unwrap (create
the lightmap UV layer) before a bake."""
import json
import os

import bpy
import numpy as np
from bpy.props import EnumProperty

from ..detp_bake import blender
from ..detp_bake.lightmap import images
from ..detp_bake.errors import BakeError
from . import common


def _files_for(context, objects, estimator):
    """Each object's lightmap in the output folder: as report.json maps them (names that collide
    as file names get distinct files), else by the object's file name."""
    out = common.output_directory(context)
    mapped = {}
    try:
        with open(os.path.join(out, "report.json")) as f:
            report = json.load(f)
        if report.get("settings", {}).get("estimator") == estimator:
            mapped = {o["name"]: [p for p in o.get("files", []) if p.endswith(".exr")] for o in report["objects"]}
    except (OSError, ValueError, KeyError, TypeError):
        pass
    found = {}
    for obj in objects:
        paths = [p for p in mapped.get(obj.name, []) if os.path.isfile(p)]
        if not paths:
            path = os.path.join(out, f"{images.file_stem(obj.name)}.{estimator}.exr")
            paths = [path] if os.path.isfile(path) else []
        if paths:
            found[obj.name] = paths
    return found


class DETPBAKE_OT_apply(bpy.types.Operator):
    """Show the baked lightmaps (from the output folder) on the selected objects' materials"""
    bl_idname = "detp_bake.apply"
    bl_label = "Apply Lightmaps"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        objects = common.bake_targets(context)
        estimator = context.scene.detp_bake.estimator
        files = _files_for(context, objects, estimator)
        out = common.output_directory(context)
        if not files and not os.path.isfile(os.path.join(out, "probes.npz")):
            self.report({"ERROR"}, f"no {estimator} lightmaps in {out}: bake first")
            return {"CANCELLED"}
        try:
            if files:
                blender.apply_all(context.scene, files, common.uv_layers(objects), estimator,
                                  log=lambda note: self.report({"WARNING"}, note))
        except BakeError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        # after the lightmaps: a marked object that got one shows probe light instead
        lit = common.apply_probes(context.scene, out, lambda note: self.report({"WARNING"}, note))
        missing = len(objects) - len(files)
        self.report({"INFO"}, f"Applied {len(files)} lightmaps" + (f"; {missing} objects have none" if missing else "")
                    + (f"; probe light on {lit} objects" if lit else ""))
        return {"FINISHED"}


class DETPBAKE_OT_revert(bpy.types.Operator):
    """Remove the baked lightmaps from the selected objects' materials, restoring them exactly"""
    bl_idname = "detp_bake.revert"
    bl_label = "Revert Lightmaps"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        objs = context.selected_objects or list(context.scene.objects)
        n = sum(blender.revert(o) for o in objs)
        self.report({"INFO"}, f"Reverted {n} objects" if n else "Nothing to revert")
        return {"FINISHED"}


class DETPBAKE_OT_open_image(bpy.types.Operator):
    """Open the active object's lightmap in an Image Editor"""
    bl_idname = "detp_bake.open_image"
    bl_label = "Open in Image Editor"

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and blender.REVERT_KEY in obj

    def execute(self, context):
        obj = context.active_object
        image = bpy.data.images.get(json.loads(obj[blender.REVERT_KEY]).get("image", ""))
        if image is None:
            self.report({"ERROR"}, f"object '{obj.name}' has no lightmap image")
            return {"CANCELLED"}
        for window in context.window_manager.windows:
            for area in window.screen.areas:
                if area.type == "IMAGE_EDITOR":
                    area.spaces.active.image = image
                    return {"FINISHED"}
        if bpy.app.background or context.window is None:
            self.report({"INFO"}, f"lightmap image: {image.name} ({image.filepath})")
            return {"FINISHED"}
        bpy.ops.wm.window_new()
        area = context.window_manager.windows[-1].screen.areas[0]
        area.type = "IMAGE_EDITOR"
        area.spaces.active.image = image
        return {"FINISHED"}


class DETPBAKE_OT_unwrap(bpy.types.Operator):
    """Create (or redo) the lightmap UV layer of the selected meshes, leaving other UV layers alone"""
    bl_idname = "detp_bake.unwrap"
    bl_label = "Unwrap Lightmap UVs"
    bl_options = {"REGISTER", "UNDO"}

    method: EnumProperty(name="Method", default="LIGHTMAP_PACK", items=[
        ("LIGHTMAP_PACK", "Lightmap Pack", "Blender's Lightmap Pack: fast, one chart per face"),
        ("XATLAS", "xatlas", "xatlas charts: fewer seams, tighter packing, slower")])

    def execute(self, context):
        objects = [o for o in common.bake_targets(context) if o.type == "MESH"]
        if not objects:
            self.report({"ERROR"}, "select mesh objects to unwrap")
            return {"CANCELLED"}
        if context.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
        s = context.scene.detp_bake
        for obj in objects:
            layer = obj.detp_bake.uv_layer
            res = obj.detp_bake.resolution or s.resolution
            if self.method == "XATLAS":
                used = blender.xatlas_unwrap(obj, layer, res)
                self.report({"INFO"}, f"'{obj.name}': xatlas charts use {100 * used:.0f} % of the lightmap")
            else:
                # Lightmap Pack leaves 2 / int(100 / margin) of UV space between charts: about 3 texels.
                blender.lightmap_pack(obj, layer, margin=float(np.clip(150.0 / res, 0.001, 1.0)))
        self.report({"INFO"}, f"Unwrapped {len(objects)} objects into '{objects[0].detp_bake.uv_layer}' "
                              f"with {'xatlas' if self.method == 'XATLAS' else 'Lightmap Pack'}")
        return {"FINISHED"}


classes = (DETPBAKE_OT_apply, DETPBAKE_OT_revert, DETPBAKE_OT_open_image, DETPBAKE_OT_unwrap)
