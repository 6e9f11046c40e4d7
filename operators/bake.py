"""`detp_bake.bake` and `detp_bake.revert`: bake the selected (or all) meshes and wire the result."""
import bpy

from ..detp_bake.errors import BakeCancelled, BakeError


def _settings(context):
    from ..detp_bake.bake import BakeSettings
    from ..detp_bake.estimators import EstimatorSettings
    s = context.scene.detp_bake
    return BakeSettings(estimator=s.estimator, photons=s.photons,
                        bounces=None if s.bounces < 0 else s.bounces, seed=s.seed,
                        resolution=s.resolution, margin=s.margin,
                        estimator_settings=EstimatorSettings(k=s.k))


class DETPBAKE_OT_bake(bpy.types.Operator):
    """Bake irradiance lightmaps for the selected meshes (all visible meshes if none selected)"""
    bl_idname = "detp_bake.bake"
    bl_label = "Bake Lightmaps"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        from ..detp_bake import bake, blender_scene
        settings = _settings(context)
        names = [o.name for o in context.selected_objects if o.type == "MESH"] or None
        out_dir = bpy.path.abspath(context.scene.detp_bake.output_directory)
        try:
            settings.validate()
            scene = blender_scene.export_scene(context.scene, context.evaluated_depsgraph_get(), names,
                                               None, settings.resolution,
                                               lambda msg: self.report({"INFO"}, msg))
            result = bake.bake(scene, settings, out_dir)
            blender_scene.apply_all(context.scene, result.files, None, settings.estimator)
        except BakeError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        except BakeCancelled:
            self.report({"WARNING"}, "Bake cancelled")
            return {"CANCELLED"}
        self.report({"INFO"}, f"Baked {len(result.files)} lightmaps in "
                    f"{sum(result.seconds.values()):.1f} s")
        return {"FINISHED"}


class DETPBAKE_OT_revert(bpy.types.Operator):
    """Remove the baked lightmaps from the selected objects' materials, restoring them exactly"""
    bl_idname = "detp_bake.revert"
    bl_label = "Revert Lightmaps"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        from ..detp_bake import blender_scene
        objs = context.selected_objects or list(context.scene.objects)
        n = sum(blender_scene.revert(o) for o in objs)
        self.report({"INFO"}, f"Reverted {n} objects")
        return {"FINISHED"}


classes = (DETPBAKE_OT_bake, DETPBAKE_OT_revert)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
