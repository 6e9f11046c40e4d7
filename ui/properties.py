"""Bake settings stored on the scene (`scene.detp_bake`) and on objects (`object.detp_bake`).
The property names are part of the scripting API: scripts and tests use them. A bake setting's
label, default, limits, choices and help come from the core's options.py (`_option`), as the
command line's do; the panel's own choices (sizes by density, preview, frames) are declared here."""
import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty,
                       StringProperty)

from ..detp_bake.run import bake
from ..detp_bake import estimators, options

ESTIMATORS = [(n, estimators.get(n).label, estimators.get(n).description) for n in estimators.names()]
_PROPERTY = {bool: BoolProperty, int: IntProperty, float: FloatProperty}
_UNIT = {"PERCENTAGE": {"subtype": "PERCENTAGE"}, "TIME": {"subtype": "TIME_ABSOLUTE", "unit": "TIME_ABSOLUTE"},
         "LENGTH": {"subtype": "DISTANCE", "unit": "LENGTH"}, "NONE": {}}


def _option(name: str, **panel):
    """The property of setting `name` (options.py): its label, default, range, choices and help;
    `panel` adds what only the panel needs (soft limits)."""
    opt = options.BY_NAME[name]
    kw = {"name": opt.label, "default": opt.default, "description": opt.help}
    if opt.choices:
        return EnumProperty(items=list(opt.choice_list), **kw, **panel)
    if opt.kind is not bool:
        low = opt.minimum if opt.auto is None else min(opt.minimum, opt.auto)
        kw.update({"min": low} if low is not None else {})
        kw.update({"max": opt.maximum} if opt.maximum is not None else {})
        kw.update({"soft_max": opt.soft_maximum} if opt.soft_maximum is not None else {})
        kw.update(_UNIT[opt.unit])
    return _PROPERTY[opt.kind](**kw, **panel)


class DETPBakeSettings(bpy.types.PropertyGroup):
    estimator: _option("estimator")
    photons: _option("photons")
    direct: _option("direct")
    direct_samples: _option("direct_samples")
    indirect_spacing: _option("indirect_spacing")
    target_noise: _option("target_noise")
    time_limit: _option("time_limit")
    denoise: _option("denoise")
    bounces: _option("bounces")
    seed: _option("seed")
    radius_mode: EnumProperty(name="Disc Radius", default="TEXELS",
                              items=[("TEXELS", "Texels", "Disc radius in texels of each object's lightmap"),
                                     ("WORLD", "World", "Disc radius in scene units (metres)")],
                              description="How the DETP disc radius is given")
    radius_texels: _option("radius_texels")
    radius: _option("radius", soft_min=0.001)
    k: _option("k")
    q: _option("q")
    kernel: _option("kernel")
    resolution_mode: EnumProperty(name="Size", default="FIXED",
                                  items=[("FIXED", "Resolution", "The same lightmap size for every object"),
                                         ("DENSITY", "Texel Density", "Lightmap size from each object's area")],
                                  description="How lightmap sizes are chosen")
    resolution: _option("resolution", soft_min=16)
    texel_density: _option("texel_density")
    lightmaps: _option("lightmaps")
    atlas_size: _option("atlas_size")
    atlas_padding: _option("atlas_padding")
    atlas_charts: _option("atlas_charts")
    margin: _option("margin")
    directional: _option("directional")
    # The shadowmask's lights: a toggle on each light object (DETPBakeObjectSettings.shadowmask)
    shadowmask_mode: _option("shadowmask_mode")
    probes: _option("probes")
    probe_spacing: _option("probe_spacing")
    probe_rays: _option("probe_rays")
    output_directory: StringProperty(name="Output", default="//lightmaps/", subtype="DIR_PATH",
                                     description="Folder for the lightmap files (// is the .blend's folder)")
    formats: EnumProperty(name="Formats", options={"ENUM_FLAG"}, default={f.upper() for f in bake.BakeSettings.formats},
                          items=[("EXR", "EXR", "32-bit float OpenEXR (the data)"),
                                 ("PNG", "PNG", "8-bit sRGB preview")],
                          description="Files written per object")
    live_preview: BoolProperty(name="Live Preview", default=True,
                               description="Show the lightmaps refining on the objects while the bake runs "
                                           "(the photon map's less often; Esc restores the materials)")
    live_preview_interval: FloatProperty(name="Preview Every", default=1.0, min=0.1, soft_max=10.0,
                                         subtype="TIME_ABSOLUTE", unit="TIME_ABSOLUTE",
                                         description="Seconds between live preview updates")
    rebake_all: BoolProperty(name="Rebake All", default=False,
                             description="Bake every object again, also those whose lightmaps in the output folder "
                                         "are unchanged since the last bake (the command line's --force)")
    apply_after_bake: BoolProperty(name="Apply After Bake", default=True,
                                   description="Show the lightmaps on the objects' materials when the bake ends")
    threads: IntProperty(name="Threads", default=options.default("threads"), min=0, max=1024,
                         description="Threads for tracing and estimation (0: the add-on preference, or all cores)")
    compare_estimators: EnumProperty(name="Compare", options={"ENUM_FLAG"},
                                     default=set(estimators.compare_defaults()),
                                     items=ESTIMATORS, description="Estimators shown side by side by Compare")
    use_frame_range: BoolProperty(name="Frame Range", default=False,
                                  description="Bake every frame of a range: <object>.<estimator>.<frame>.exr, the "
                                              "same photons every frame so static regions do not flicker")
    frame_start: IntProperty(name="Start", default=1, description="First frame to bake")
    frame_end: IntProperty(name="End", default=24, description="Last frame to bake")
    frame_step: IntProperty(name="Step", default=1, min=1, description="Bake every n-th frame of the range")
    hybrid_moving: _option("hybrid_moving")
    show_probes: BoolProperty(name="Show Probes", default=False, update=lambda self, context: _show_probes(self),
                              description="Draw the baked light probes of the output folder (probes.npz) in the "
                                          "viewport as small spheres shaded by their light; invalid probes in red")
    last_report: StringProperty(name="Last Bake", default="", options={"HIDDEN"},
                                description="Statistics of the last bake (JSON)")


def _show_probes(settings) -> None:
    from ..detp_bake.blender import probe_view
    probe_view.show(settings.show_probes)


class DETPBakeObjectSettings(bpy.types.PropertyGroup):
    include: BoolProperty(name="Include", default=True, description="Bake a lightmap for this object")
    resolution: IntProperty(name="Resolution Override", default=0, min=0, max=options.MAX_RESOLUTION,
                            description="This object's lightmap size (0: use the scene setting)")
    density_scale: FloatProperty(name="Density Scale", default=1.0, min=0.01, soft_max=16.0,
                                 description="Atlases: this object's texels per metre, times the scene's")
    # Lights: one channel of the shadowmask (options.py's `shadowmask` list, read by bake_settings)
    shadowmask: BoolProperty(name=options.BY_NAME["shadowmask"].label, default=False,
                             description=f"Lights: this light's shadows go into the shadowmask, one RGBA channel each "
                                         f"(up to {options.MAX_SHADOWMASK} lights, in name order)")
    uv_layer: StringProperty(name="Lightmap UV", default=options.UV_LAYER,
                             description="UV layer that holds this object's lightmap charts")
    probe_light: BoolProperty(name="Probe Light", default=False,
                              description="A moving object: Apply lights it with the baked light probes at its "
                                          "position (updated as frames change) instead of a lightmap")
    motion: EnumProperty(name="Motion", default="AUTO",
                         items=[("AUTO", "Auto", "Moving when its evaluated geometry, placement or material "
                                 "changes over the frame range"),
                                ("STATIC", "Static", "Treat it as static over the frame range"),
                                ("MOVING", "Moving", "Treat it as moving over the frame range")],
                         description="Frame ranges: whether this object counts as moving (the hybrid estimator "
                                     "indexes the static objects' discs once)")


classes = (DETPBakeSettings, DETPBakeObjectSettings)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.detp_bake = PointerProperty(type=DETPBakeSettings)
    bpy.types.Object.detp_bake = PointerProperty(type=DETPBakeObjectSettings)


def unregister():
    from ..detp_bake.blender import probe_view
    probe_view.show(False)
    del bpy.types.Object.detp_bake
    del bpy.types.Scene.detp_bake
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
