"""The sidebar tab: settings and the Bake button; drawing only, no logic."""
import bpy


class DETPBAKE_PT_main(bpy.types.Panel):
    bl_label = "detp_bake"
    bl_idname = "DETPBAKE_PT_main"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Lightmap"

    def draw(self, context):
        layout = self.layout
        settings = context.scene.detp_bake
        layout.use_property_split = True
        for prop in ("estimator", "photons", "bounces", "k", "resolution", "margin", "output_directory"):
            layout.prop(settings, prop)
        layout.operator("detp_bake.bake", icon="RENDER_STILL")
        layout.operator("detp_bake.revert", icon="LOOP_BACK")


classes = (DETPBAKE_PT_main,)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
