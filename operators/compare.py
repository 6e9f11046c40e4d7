"""`detp_bake.compare` bakes the same photons with several estimators and shows them side by side:
a collection of linked duplicates, one row per estimator, each showing its own lightmaps, with a
label; plus a comparison image. `detp_bake.compare_clear` removes all of it."""
import bpy
import numpy as np
from bpy.props import EnumProperty
from mathutils import Matrix

from ..detp_bake import bake, blender, comparison, estimators, images
from ..detp_bake.errors import BakeCancelled, BakeError
from ..ui.properties import ESTIMATORS
from . import common

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


def run_compare(context, names, report, progress=None, cancel=None) -> dict:
    """Bake, write, build the side-by-side scene and the image. Returns a summary dict."""
    settings = common.bake_settings(context)
    out_dir = common.output_directory(context)
    objects = common.bake_targets(context)
    if not objects:
        raise BakeError("nothing to compare: no visible mesh with 'Include' set")
    images.check_writable_dir(out_dir)
    created = []
    try:
        scene = common.export(context, objects, lambda m: report({"INFO"}, m), created)
        results = bake.compute_many(scene, settings, names, progress, cancel)
        for result in results.values():
            bake.write(result, out_dir, progress, cancel)
    except BaseException:
        blender.remove_uv_layers(context.scene, created)
        raise
    clear(context)
    seconds = {n: r.seconds["estimate"] for n, r in results.items()}
    first = results[names[0]]
    picture, diffs = comparison.comparison_image({n: r.images for n, r in results.items()}, first.masks, seconds)
    png = f"{out_dir.rstrip('/')}/compare.png"
    images.write_png(png, picture)
    img = bpy.data.images.load(png, check_existing=False)
    img.name = IMAGE

    coll = bpy.data.collections.new(COLLECTION)
    context.scene.collection.children.link(coll)
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
        blender.apply_all(context.scene, results[name].files, uv, name, objects=dups, copy_materials=True)
        curve = bpy.data.curves.new(f"detp_bake label {name}", "FONT")
        curve.body = f"{name}\n{seconds[name]:.2f} s   diff {100 * diffs[name]:.1f} %"
        curve.size = max(0.1, (hi[2] - lo[2]) * 0.08)
        label = bpy.data.objects.new(f"detp_bake label {name}", curve)
        label.location = (lo[0] + (i + 1) * step, lo[1], hi[2] + curve.size)
        label.rotation_euler = (np.pi / 2, 0.0, 0.0)
        label[MARK] = name
        coll.objects.link(label)
    if not bpy.app.background:
        for window in context.window_manager.windows:
            for area in window.screen.areas:
                if area.type == "IMAGE_EDITOR":
                    area.spaces.active.image = img
    return {"estimators": names, "seconds": seconds, "difference": diffs, "image": png}


class DETPBAKE_OT_compare(bpy.types.Operator):
    """Bake the same photons with several estimators and show them side by side next to the scene"""
    bl_idname = "detp_bake.compare"
    bl_label = "Compare Estimators"
    bl_options = {"REGISTER", "UNDO"}

    estimators: EnumProperty(name="Estimators", options={"ENUM_FLAG"}, items=ESTIMATORS,
                             default=set(estimators.compare_defaults()))

    @classmethod
    def poll(cls, context):
        return common.idle(cls, context)

    def invoke(self, context, event):
        self.estimators = set(context.scene.detp_bake.compare_estimators)
        return self.execute(context)

    def execute(self, context):
        names = estimators.compare_order(self.estimators)
        if len(names) < 1:
            self.report({"ERROR"}, "choose at least one estimator to compare")
            return {"CANCELLED"}
        wm = context.window_manager
        wm.progress_begin(0, 100)
        try:
            summary = run_compare(context, names, self.report,
                                  lambda p: wm.progress_update(int(100 * p.fraction)))
        except BakeError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        except BakeCancelled:
            self.report({"WARNING"}, "Comparison cancelled")
            return {"CANCELLED"}
        finally:
            wm.progress_end()
        parts = ", ".join(f"{n} {summary['seconds'][n]:.2f} s" for n in names)
        self.report({"INFO"}, f"Compared {parts}; image {summary['image']}")
        return {"FINISHED"}


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
