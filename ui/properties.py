"""Bake settings stored on the scene (`scene.detp_bake`) and on objects (`object.detp_bake`).
The property names are part of the scripting API: scripts and tests use them. Defaults, limits
and choices come from the core (BakeSettings, EstimatorSettings, the estimator registry), as the
command line's do."""
import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty,
                       StringProperty)

from ..detp_bake import bake, estimators, images, sites

_B, _E = bake.BakeSettings, estimators.EstimatorSettings
ESTIMATORS = [(n, estimators.get(n).label, estimators.get(n).description) for n in estimators.names()]


class DETPBakeSettings(bpy.types.PropertyGroup):
    estimator: EnumProperty(name="Estimator", items=ESTIMATORS, default=_B.estimator,
                            description="Density estimator that turns photons into irradiance")
    photons: IntProperty(name="Photons", default=_B.photons, min=0, max=bake.MAX_PHOTONS,
                         soft_max=50_000_000, description="Photons traced from the lights: more means less noise; "
                         f"0: automatic, {bake.PHOTONS_PER_TEXEL} per lightmap texel to bake")
    direct: EnumProperty(name="Direct Light", default=_B.direct,
                         items=[("sampled", "Shadow Rays", "Direct light sampled with shadow rays at every texel; "
                                 "photons carry indirect light only (sharp shadows, least noise)"),
                                ("photons", "Photons", "Photons carry direct light too and the estimator sees "
                                 "every segment (the paper's experiments)")],
                         description="How direct light is found")
    direct_samples: IntProperty(name="Shadow Rays", default=_B.direct_samples, min=1, max=bake.MAX_DIRECT_SAMPLES, soft_max=256,
                                description="Shadow rays per texel for each light with extent (area, sphere, "
                                            "sun disc, sky, emissive meshes); point lights need one")
    indirect_spacing: IntProperty(name="Indirect Spacing", default=_B.indirect_spacing, min=0, max=bake.MAX_SPACING,
                                  description="Estimate indirect light every this many texels and blend between "
                                              f"them (0: automatic, {sites.AUTO_SPACING} on lightmaps of {sites.AUTO_FROM}² and "
                                              "more; 1: every texel). Indirect "
                                              "light is smooth: fewer sites cost less for the same noise")
    target_noise: FloatProperty(name="Noise Target", default=_B.target_noise, min=0.0, max=100.0, soft_max=10.0,
                                subtype="PERCENTAGE",
                                description="Stop tracing once every lightmap's relative noise is at most this "
                                            "(0: off); Photons is then the most to trace")
    time_limit: FloatProperty(name="Time Limit", default=_B.time_limit, min=0.0, soft_max=3600.0, subtype="TIME_ABSOLUTE",
                              unit="TIME_ABSOLUTE",
                              description="Stop tracing before the bake has run this many seconds (0: off)")
    denoise: BoolProperty(name="Denoise", default=_B.denoise,
                          description="Denoise the lightmaps with Intel Open Image Denoise (chart-aware)")
    bounces: IntProperty(name="Bounces", default=-1, min=-1, max=bake.MAX_BOUNCES, soft_max=16,
                         description="Diffuse bounces before a photon lands (-1: Cycles' Light Paths > Diffuse)")
    seed: IntProperty(name="Seed", default=_B.seed, min=0, description="Random seed: the same seed gives the same lightmaps")
    radius_mode: EnumProperty(name="Disc Radius", default="TEXELS",
                              items=[("TEXELS", "Texels", "Disc radius in texels of each object's lightmap"),
                                     ("WORLD", "World", "Disc radius in scene units (metres)")],
                              description="How the DETP disc radius is given")
    radius_texels: FloatProperty(name="Radius", default=estimators.RADIUS_TEXELS_INDIRECT, min=0.05, soft_max=8.0,
                                 description="DETP disc radius in texels: larger is smoother but blurrier")
    radius: FloatProperty(name="Radius", default=0.05, min=1e-5, subtype="DISTANCE", unit="LENGTH",
                          description="DETP disc radius in scene units")
    k: IntProperty(name="Neighbours", default=_E.k, min=2, soft_max=5000,
                   description="Photon map: hits per estimate; noise is about 1/sqrt(k)")
    q: FloatProperty(name="Sphere Ratio", default=_E.q, min=0.05, max=0.95,
                     description="Sphere cache: radius ratio of successive spheres (best near 0.6-0.7)")
    resolution_mode: EnumProperty(name="Size", default="FIXED",
                                  items=[("FIXED", "Resolution", "The same lightmap size for every object"),
                                         ("DENSITY", "Texel Density", "Lightmap size from each object's area")],
                                  description="How lightmap sizes are chosen")
    resolution: IntProperty(name="Resolution", default=_B.resolution, min=1, max=bake.MAX_RESOLUTION, soft_min=16, soft_max=4096,
                            description="Lightmap width and height in pixels")
    texel_density: FloatProperty(name="Texels per Metre", default=32.0, min=0.01, soft_max=1024.0,
                                 description="Lightmap texels per metre of surface, when sizing by density")
    margin: IntProperty(name="Margin", default=_B.margin, min=0, max=4096,
                        description="Pixels of dilation around the UV charts, against seams under filtering")
    output_directory: StringProperty(name="Output", default="//lightmaps/", subtype="DIR_PATH",
                                     description="Folder for the lightmap files (// is the .blend's folder)")
    formats: EnumProperty(name="Formats", options={"ENUM_FLAG"}, default={f.upper() for f in _B.formats},
                          items=[("EXR", "EXR", "32-bit float OpenEXR (the data)"),
                                 ("PNG", "PNG", "8-bit sRGB preview")],
                          description="Files written per object")
    live_preview: BoolProperty(name="Live Preview", default=True,
                               description="Show the lightmaps refining on the objects while the bake runs "
                                           "(the photon map's less often; Esc restores the materials)")
    live_preview_interval: FloatProperty(name="Preview Every", default=1.0, min=0.1, soft_max=10.0,
                                         subtype="TIME_ABSOLUTE", unit="TIME_ABSOLUTE",
                                         description="Seconds between live preview updates")
    apply_after_bake: BoolProperty(name="Apply After Bake", default=True,
                                   description="Show the lightmaps on the objects' materials when the bake ends")
    threads: IntProperty(name="Threads", default=_B.threads, min=0, max=1024,
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
    hybrid_moving: EnumProperty(name="Moving Texels", default="sphere_cache",
                                items=[("sphere_cache", "Sphere Cache", "The paper's choice"),
                                       ("disc_index", "Disc Index", "A small index of their own, built every frame")],
                                description="Hybrid: how the moving objects' texels are estimated")
    last_report: StringProperty(name="Last Bake", default="", options={"HIDDEN"},
                                description="Statistics of the last bake (JSON)")


class DETPBakeObjectSettings(bpy.types.PropertyGroup):
    include: BoolProperty(name="Include", default=True, description="Bake a lightmap for this object")
    resolution: IntProperty(name="Resolution Override", default=0, min=0, max=bake.MAX_RESOLUTION,
                            description="This object's lightmap size (0: use the scene setting)")
    uv_layer: StringProperty(name="Lightmap UV", default="Lightmap",
                             description="UV layer that holds this object's lightmap charts")
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
    del bpy.types.Object.detp_bake
    del bpy.types.Scene.detp_bake
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
