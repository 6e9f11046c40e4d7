"""Export glTF with Lightmaps: the scene as a .glb with the lightmaps of the panel's last bake on
its materials (detp_bake/blender/gltf.py does the work; docs/gltf.md)."""
import json

import bpy
from bpy.props import StringProperty
from bpy_extras.io_utils import ExportHelper

from ..detp_bake.blender import gltf, identity
from ..detp_bake.errors import BakeError
from . import common


def last_bake(context) -> tuple:
    """The output folder and estimator of the panel's last bake (Last Bake's record), else the
    Output setting and the panel's estimator (a file opened in a new session)."""
    s = context.scene.detp_bake
    try:
        record = json.loads(s.last_report) if s.last_report else {}
    except ValueError:
        record = {}
    return record.get("output_directory") or common.output_directory(context), record.get("estimator") or s.estimator


class DETPBAKE_OT_export_gltf(bpy.types.Operator, ExportHelper):
    """Write the scene as a .glb with the last bake's lightmaps on its materials (MOZ_lightmap, RGBE); the scene is
    left as it is"""
    bl_idname = "detp_bake.export_gltf"
    bl_label = "Export glTF with Lightmaps"
    filename_ext = ".glb"
    filter_glob: StringProperty(default="*.glb", options={"HIDDEN"})

    @classmethod
    def poll(cls, context):
        if not common.idle(cls, context):
            return False
        if context.mode != "OBJECT":
            cls.poll_message_set("Switch to Object Mode first")
            return False
        return True

    def execute(self, context):
        out_dir, estimator = last_bake(context)
        meshes = [o for o in context.scene.objects if o.type == "MESH"]
        try:
            identity.check_lightmaps(context.scene, out_dir)  # this scene's lightmaps, of its geometry as it is
            done = gltf.export_gltf(context.scene, out_dir, self.filepath, estimator, common.uv_layers(meshes),
                                    log=lambda message: None)
        except BakeError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        for warning in done["warnings"]:
            self.report({"WARNING"}, warning)
        self.report({"INFO"}, f"Exported {done['gltf']}: {len(done['objects'])} objects, {done['images']} "
                              f"{done['estimator']} lightmaps from {out_dir}")
        return {"FINISHED"}


classes = (DETPBAKE_OT_export_gltf,)
