"""Bake settings stored on the scene (`scene.detp_bake`); names are part of the scripting API."""
import bpy
from bpy.props import EnumProperty, IntProperty, PointerProperty, StringProperty

ESTIMATORS = [
    ("disc_index", "DETP: disc index", "Tangent-disc density estimation, discs indexed in a BVH (fastest)"),
    ("sphere_cache", "DETP: sphere cache", "Tangent-disc density estimation through Lastra's sphere cache"),
    ("detp", "DETP: brute force", "Every segment against every disc: slow, the reference"),
    ("photon_map", "Photon map", "Jensen's k-nearest-neighbour photon map"),
]


class DETPBakeSettings(bpy.types.PropertyGroup):
    estimator: EnumProperty(name="Estimator", items=ESTIMATORS, default="disc_index",
                            description="Density estimator that turns photons into irradiance")
    photons: IntProperty(name="Photons", default=1_000_000, min=1, max=1_000_000_000,
                         description="Photons traced from the lights")
    bounces: IntProperty(name="Bounces", default=-1, min=-1, max=1024,
                         description="Diffuse bounces; -1 uses Cycles' Light Paths › Diffuse")
    seed: IntProperty(name="Seed", default=0, min=0, description="Random seed of the photon tracer")
    k: IntProperty(name="Neighbours", default=100, min=2, description="Photon map: photons per estimate")
    resolution: IntProperty(name="Resolution", default=128, min=1, max=16384,
                            description="Lightmap width and height in pixels")
    margin: IntProperty(name="Margin", default=16, min=0, max=4096,
                        description="Pixels of dilation around the UV charts")
    output_directory: StringProperty(name="Output", default="//lightmaps/", subtype="DIR_PATH",
                                     description="Folder for the lightmap files")


classes = (DETPBakeSettings,)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.detp_bake = PointerProperty(type=DETPBakeSettings)


def unregister():
    del bpy.types.Scene.detp_bake
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
