"""`detp_bake.compare` bakes the same photons with several estimators and shows them side by side:
a collection of linked duplicates, one row per estimator, each showing its own lightmaps, with a
label; plus a comparison image and one report (comparison.report_files). It runs as a job, like
Bake: modal, with progress and Esc. `detp_bake.compare_clear` removes all of it."""
import bpy
import numpy as np
from bpy.props import EnumProperty
from mathutils import Matrix

from ..detp_bake import blender, estimators, options
from . import common
from .bake import JobOperator
from .job import BlenderJob

COLLECTION = "detp_bake compare"
MARK = "detp_bake_compare"
IMAGE = "detp_bake compare"


def clear(context) -> int:
    """Remove the comparison collection, its duplicates, labels, material copies and images."""
    removed = 0
    coll = bpy.data.collections.get(COLLECTION)
    for obj in [o for o in bpy.data.objects if MARK in o]:
        blender.revert(obj)
        data = obj.data if obj.type == "FONT" else None
        bpy.data.objects.remove(obj)
        if data is not None and data.users == 0:
            bpy.data.curves.remove(data)
        removed += 1
    if coll is not None:
        bpy.data.collections.remove(coll)
    img = bpy.data.images.get(IMAGE)
    if img is not None:
        bpy.data.images.remove(img)
    return removed


class CompareJob(BlenderJob):
    """A comparison: its finish lays the estimators' lightmaps out side by side."""

    def finish(self, report) -> set:
        if not self.succeeded(report):
            return self.failed(report)
        scene = self.bl_scene
        objects = [scene.objects[n] for n in self.objects if n in scene.objects]
        summary = self.outcome.comparison
        lay_out(scene, objects, self.outcome.results, self.names, summary)
        for warning in dict.fromkeys(self.warnings):
            report({"WARNING"}, warning)
        parts = ", ".join(f"{n} {summary['seconds'][n]:.2f} s" for n in self.names)
        report({"INFO"}, f"Compared {parts}; report {summary['report']}")
        return {"FINISHED"}


def lay_out(scene, objects, results, names, summary) -> None:
    """The side-by-side scene: a row of linked duplicates per estimator, each with its own
    lightmaps and a label, and the comparison image in every Image Editor."""
    clear(bpy.context)
    seconds, diffs = summary["seconds"], summary["difference_to_first"]
    img = bpy.data.images.load(summary["image"], check_existing=False)
    img.name = IMAGE
    coll = bpy.data.collections.new(COLLECTION)
    scene.collection.children.link(coll)
    corners = np.array([o.matrix_world @ v.co for o in objects for v in o.data.vertices]) if objects else np.zeros((1, 3))
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    step = (hi[0] - lo[0]) * 1.25 + 0.5
    uv = common.uv_layers(objects)
    for i, name in enumerate(names):
        offset = Matrix.Translation(((i + 1) * step, 0.0, 0.0))
        dups = {}
        for obj in objects:
            dup = obj.copy()  # linked duplicate: shares the mesh and its lightmap UVs
            dup.name = f"{obj.name} [{name}]"
            dup.parent = None
            dup.matrix_world = offset @ obj.matrix_world
            dup[MARK] = name
            if blender.REVERT_KEY in dup:
                del dup[blender.REVERT_KEY]  # the original's record, not the duplicate's
            for c in list(dup.users_collection):
                c.objects.unlink(dup)
            coll.objects.link(dup)
            dups[obj.name] = dup
        blender.apply_all(scene, results[name].files, uv, name, objects=dups, copy_materials=True)
        curve = bpy.data.curves.new(f"detp_bake label {name}", "FONT")
        curve.body = f"{name}\n{seconds[name]:.2f} s   diff {100 * diffs[name]:.1f} %"
        curve.size = max(0.1, (hi[2] - lo[2]) * 0.08)
        label = bpy.data.objects.new(f"detp_bake label {name}", curve)
        label.location = (lo[0] + (i + 1) * step, lo[1], hi[2] + curve.size)
        label.rotation_euler = (np.pi / 2, 0.0, 0.0)
        label[MARK] = name
        coll.objects.link(label)
    if not bpy.app.background:
        for window in bpy.context.window_manager.windows:
            for area in window.screen.areas:
                if area.type == "IMAGE_EDITOR":
                    area.spaces.active.image = img


class DETPBAKE_OT_compare(JobOperator, bpy.types.Operator):
    """Bake the same photons with several estimators and show them side by side next to the scene"""
    bl_idname = "detp_bake.compare"
    bl_label = "Compare Estimators"
    bl_options = {"REGISTER", "UNDO"}

    estimators: EnumProperty(name="Estimators", options={"ENUM_FLAG"}, items=list(options.BY_NAME["estimator"].choice_list),
                             default=set(estimators.compare_defaults()))

    @classmethod
    def poll(cls, context):
        return common.idle(cls, context)

    def make_job(self, context):
        return CompareJob(context, estimators.compare_order(self.estimators))

    def invoke(self, context, event):
        self.estimators = set(context.scene.detp_bake.compare_estimators)
        if not self.estimators:
            self.report({"ERROR"}, "choose at least one estimator to compare")
            return {"CANCELLED"}
        return JobOperator.invoke(self, context, event)

    def execute(self, context):
        if not self.estimators:
            self.report({"ERROR"}, "choose at least one estimator to compare")
            return {"CANCELLED"}
        return JobOperator.execute(self, context)


class DETPBAKE_OT_compare_clear(bpy.types.Operator):
    """Remove the side-by-side comparison and everything it added"""
    bl_idname = "detp_bake.compare_clear"
    bl_label = "Clear Comparison"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        n = clear(context)
        self.report({"INFO"}, f"Removed {n} comparison objects" if n else "No comparison to clear")
        return {"FINISHED"}


classes = (DETPBAKE_OT_compare, DETPBAKE_OT_compare_clear)
