"""The 3D View sidebar tab "Lightmap": settings in collapsible sub-panels, the Bake button, the last
bake's statistics and the lightmap tools. Drawing only; the operators do the work."""
import json

import bpy

from ..detp_bake import estimators, options
from ..operators import common


class _Panel:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Lightmap"


class DETPBAKE_PT_main(_Panel, bpy.types.Panel):
    bl_label = "detp_bake"
    bl_idname = "DETPBAKE_PT_main"

    def draw(self, context):
        layout = self.layout
        s = context.scene.detp_bake
        layout.prop(s, "estimator")
        active = common.ACTIVE
        if active is not None and active.job is not None:
            self.draw_running(layout, active)
        else:
            row = layout.row()
            row.scale_y = 1.5
            row.operator("detp_bake.bake", icon="RENDER_STILL")
        row = layout.row(align=True)
        row.operator("detp_bake.apply", icon="MATERIAL")
        row.operator("detp_bake.revert", icon="LOOP_BACK")
        layout.operator("detp_bake.open_image", icon="IMAGE_DATA")
        layout.prop(s, "show_probes", icon="LIGHTPROBE_VOLUME" if bpy.app.version >= (4, 1, 0) else "LIGHTPROBE_GRID")
        layout.operator("detp_bake.export_gltf", icon="EXPORT")

    @staticmethod
    def draw_running(layout, active):
        """The running job: what it does, the photons and noise of the live preview, Stop and Keep."""
        col = layout.column(align=True)
        col.label(text=active.status(), icon="TIME")
        if active.snapshot is not None:
            noise = active.snapshot.noise
            col.label(text=f"{active.snapshot.photons:,} photons" +
                      (f" · noise {100 * noise:.2g} %" if noise is not None else ""))
        row = layout.row()
        row.scale_y = 1.5
        if active.kind == "bake":
            row.operator("detp_bake.stop", icon="PAUSE")
        col.label(text="Esc cancels and restores the scene")


class DETPBAKE_PT_photons(_Panel, bpy.types.Panel):
    bl_label = "Photons"
    bl_parent_id = "DETPBAKE_PT_main"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        s = context.scene.detp_bake
        layout.prop(s, "direct")
        if s.direct == "sampled":
            layout.prop(s, "direct_samples")
            layout.prop(s, "indirect_spacing")
        layout.prop(s, "photons")
        layout.prop(s, "target_noise")
        layout.prop(s, "time_limit")
        layout.prop(s, "bounces")
        layout.prop(s, "seed")
        layout.prop(s, "threads")
        layout.prop(s, "denoise")
        layout.prop(s, "live_preview")
        if s.live_preview:
            layout.prop(s, "live_preview_interval")


class DETPBAKE_PT_estimator(_Panel, bpy.types.Panel):
    bl_label = "Estimator"
    bl_parent_id = "DETPBAKE_PT_main"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        s = context.scene.detp_bake
        if s.estimator == "photon_map":
            layout.prop(s, "k")
            return
        if not estimators.get(s.estimator).discs:
            layout.label(text="No setting: each photon counts in the texel it lands in")
            if not s.denoise:
                layout.label(text="Meant to be denoised: turn Denoise on", icon="ERROR")
            return
        layout.prop(s, "radius_mode")
        layout.prop(s, "radius_texels" if s.radius_mode == "TEXELS" else "radius")
        layout.prop(s, "kernel")
        if s.estimator == "sphere_cache" or (s.estimator == "hybrid" and s.hybrid_moving == "sphere_cache"):
            layout.prop(s, "q")
        if s.estimator == "hybrid":
            layout.prop(s, "hybrid_moving")


class DETPBAKE_PT_frames(_Panel, bpy.types.Panel):
    bl_label = "Frame Range"
    bl_parent_id = "DETPBAKE_PT_main"
    bl_options = {"DEFAULT_CLOSED"}

    def draw_header(self, context):
        self.layout.prop(context.scene.detp_bake, "use_frame_range", text="")

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        s = context.scene.detp_bake
        layout.active = s.use_frame_range
        col = layout.column(align=True)
        col.prop(s, "frame_start")
        col.prop(s, "frame_end")
        col.prop(s, "frame_step")
        if s.use_frame_range and s.estimator != "hybrid":
            layout.label(text="Hybrid indexes static objects once", icon="INFO")


class DETPBAKE_PT_lightmaps(_Panel, bpy.types.Panel):
    bl_label = "Lightmaps"
    bl_parent_id = "DETPBAKE_PT_main"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        s = context.scene.detp_bake
        layout.prop(s, "lightmaps")
        # Every size setting stays in view; those that do nothing in this mode (options.Option.lightmaps,
        # what the command line refuses) are greyed out.
        if s.lightmaps == "atlas":
            names = ["texel_density", "atlas_size", "atlas_padding", "atlas_charts", "resolution"]
        else:
            names = ["resolution_mode", "resolution" if s.resolution_mode == "FIXED" else "texel_density",
                     "atlas_size", "atlas_padding", "atlas_charts"]
        for name in names:
            row = layout.row()
            declared = options.BY_NAME.get(name)
            row.active = name == "texel_density" or declared is None or declared.lightmaps in ("", s.lightmaps)
            row.prop(s, name)
        layout.prop(s, "margin")
        layout.prop(s, "directional")
        lights = sorted((o for o in context.scene.objects if o.type == "LIGHT"), key=lambda o: o.name)
        col = layout.column(heading="Shadowmask", align=True)
        for light in lights:  # one toggle per light: the command line's --shadowmask list
            col.prop(light.detp_bake, "shadowmask", text=light.name)
        if not lights:
            col.label(text="No lights in the scene")
        row = layout.row()
        row.active = any(light.detp_bake.shadowmask for light in lights)
        row.prop(s, "shadowmask_mode")
        _draw_probes(layout, context, s)
        layout.prop(s, "output_directory")
        layout.prop(s, "formats")
        layout.prop(s, "apply_after_bake")
        layout.prop(s, "rebake_all")
        row = layout.row(align=True)
        row.operator("detp_bake.unwrap", text="Unwrap: Lightmap Pack").method = "LIGHTMAP_PACK"
        row.operator("detp_bake.unwrap", text="xatlas").method = "XATLAS"


def _draw_probes(layout, context, s) -> None:
    """Light probes: the mode, its settings, and the count and memory before baking."""
    layout.prop(s, "probes")
    row = layout.row()
    row.active = s.probes == "auto"
    row.prop(s, "probe_spacing")
    row = layout.row()
    row.active = s.probes != "off"
    row.prop(s, "probe_rays")
    if s.probes != "off":
        from ..detp_bake.blender.probe_volumes import panel_cost
        count, size, exact = panel_cost(context.scene, context.view_layer, s.probes, s.probe_spacing)
        layout.label(text=f"{'' if exact else 'At most '}{count:,} probes, {size / 1e6:.1f} MB")


class DETPBAKE_PT_object(_Panel, bpy.types.Panel):
    bl_label = "Active Object"
    bl_parent_id = "DETPBAKE_PT_main"
    bl_options = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context):
        return context.active_object is not None

    def draw(self, context):
        layout = self.layout
        obj = context.active_object
        if obj.type == "LIGHT":
            layout.prop(obj.detp_bake, "shadowmask", text="Shadowmask")
        if obj.type != "MESH":
            col = layout.column(align=True)
            kind = "instancer" if obj.instance_type != "NONE" else obj.type.lower()
            col.label(text=f"This {kind} lights and shadows the bake,", icon="INFO")
            col.label(text="but lightmaps are baked on mesh objects.")
            col.label(text="To bake one for it: Object > Apply > Make Instances Real"
                      if obj.instance_type != "NONE" else "To bake one for it: Object > Convert > Mesh")
            return
        layout.use_property_split = True
        o = obj.detp_bake
        layout.prop(o, "include")
        layout.prop(o, "density_scale" if context.scene.detp_bake.lightmaps == "atlas" else "resolution")
        layout.prop(o, "uv_layer")
        layout.prop(o, "probe_light")
        if context.scene.detp_bake.use_frame_range:
            layout.prop(o, "motion")


class DETPBAKE_PT_compare(_Panel, bpy.types.Panel):
    bl_label = "Compare"
    bl_parent_id = "DETPBAKE_PT_main"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        layout.prop(context.scene.detp_bake, "compare_estimators")
        row = layout.row(align=True)
        row.operator("detp_bake.compare", icon="SPLITSCREEN")
        row.operator("detp_bake.compare_clear", icon="X")


class DETPBAKE_PT_stats(_Panel, bpy.types.Panel):
    bl_label = "Last Bake"
    bl_parent_id = "DETPBAKE_PT_main"

    def draw(self, context):
        layout = self.layout
        text = context.scene.detp_bake.last_report
        if not text:
            layout.label(text="No bake yet")
            return
        r = json.loads(text)
        col = layout.column(align=True)
        col.label(text=f"{r['estimator']}: {r['objects']} lightmaps")
        if r.get("reused"):
            col.label(text=f"{len(r['reused'])} unchanged since the last bake: kept")
        if "photons" in r:
            col.label(text=f"{r['photons']:,} photons, {r['segments']:,} segments")
        measured = {name: v for name, v in (r.get("noise") or {}).items() if v is not None}
        if measured:  # per cent of the scene's mean irradiance (None: not measured, a small bake)
            worst = max(measured, key=measured.get)
            col.label(text=f"Noise: {measured[worst]:.2g} % at most ({worst})")
        if r.get("charts"):  # the most fragmented lightmap: its charts, their median width, border texels
            name, c = min(r["charts"].items(), key=lambda item: item[1]["median_width"])
            col.label(text=f"Charts: {c['count']:,} in '{name}', {c['median_width']:.1f} texels wide, "
                           f"{100 * c['border']:.0f} % border")
        if r.get("stopped_by", "photons") != "photons":
            col.label(text=f"Stopped by {r['stopped_by'].replace('_', ' ')}")
        for phase in ("export", "validity", "direct", "build", "trace", "estimate", "denoise", "write"):
            if phase in r.get("seconds", {}):
                col.label(text=f"{phase.capitalize()}: {r['seconds'][phase]:.2f} s")


classes = (DETPBAKE_PT_main, DETPBAKE_PT_photons, DETPBAKE_PT_estimator, DETPBAKE_PT_frames, DETPBAKE_PT_lightmaps,
           DETPBAKE_PT_object, DETPBAKE_PT_compare, DETPBAKE_PT_stats)


register, unregister = bpy.utils.register_classes_factory(classes)
