"""Add-on preferences: machine-wide choices that do not belong in a .blend."""
import os

import bpy
from bpy.props import IntProperty, StringProperty


def _remember_cache_directory(self, context):
    """Numba reads its cache folder before the preferences exist: keep the choice in a file."""
    try:
        base = bpy.utils.extension_path_user(self.bl_idname, create=True)
    except ValueError:
        return
    with open(os.path.join(base, "cache_directory.txt"), "w") as f:
        f.write(bpy.path.abspath(self.cache_directory))


class DETPBakePreferences(bpy.types.AddonPreferences):
    bl_idname = __package__.rpartition(".")[0]

    threads: IntProperty(name="Threads", default=0, min=0, max=1024,
                         description="Threads for tracing and estimation when the scene says 0 (0: all cores)")
    memory_budget: IntProperty(name="Photon Memory (MB)", default=4096, min=0, soft_max=65536,
                               description="Refuse bakes whose stored photons would need more memory than this "
                                           "(the photon map keeps every hit; DETP estimators stream). 0: no limit")
    cache_directory: StringProperty(name="Kernel Cache", default="", subtype="DIR_PATH",
                                    description="Folder for compiled kernels (empty: the extension's user folder). "
                                                "Takes effect at the next start of Blender",
                                    update=_remember_cache_directory)

    def draw(self, context):
        layout = self.layout
        layout.prop(self, "threads")
        layout.prop(self, "memory_budget")
        layout.prop(self, "cache_directory")


classes = (DETPBakePreferences,)


register, unregister = bpy.utils.register_classes_factory(classes)
