"""Add-on preferences: machine-wide choices that do not belong in a .blend."""
import os

import bpy
from bpy.props import IntProperty, StringProperty

from ..detp_bake import options

_BUDGET = options.BY_NAME["memory_budget_mb"]


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
    memory_budget: IntProperty(name=_BUDGET.label, default=_BUDGET.default, min=_BUDGET.minimum,
                               soft_max=_BUDGET.soft_maximum, description=_BUDGET.help)
    cache_directory: StringProperty(name="Kernel Cache", default="", subtype="DIR_PATH",
                                    description="Folder for compiled kernels (empty: the extension's user folder). "
                                                "Takes effect at the next start of Blender",
                                    update=_remember_cache_directory)
    scheduler_address: StringProperty(name="Dask Scheduler", default="",
                                      description="Trace the photons on this Dask cluster, e.g. tcp://10.0.0.5:8786 "
                                                  "(needs the dask and distributed packages; empty: on this machine)")

    def draw(self, context):
        layout = self.layout
        layout.prop(self, "threads")
        layout.prop(self, "memory_budget")
        layout.prop(self, "cache_directory")
        row = layout.row()
        row.prop(self, "scheduler_address")
        row.operator(DETPBAKE_OT_test_cluster.bl_idname, text="Test Connection")


class DETPBAKE_OT_test_cluster(bpy.types.Operator):
    """Connect to the Dask scheduler of the preferences and report its workers and their cores"""
    bl_idname = "detp_bake.test_cluster"
    bl_label = "Test Connection"

    def execute(self, context):
        from ..detp_bake.run.distributed import Cluster
        from ..detp_bake.errors import BakeError
        address = context.preferences.addons[DETPBakePreferences.bl_idname].preferences.scheduler_address.strip()
        if not address:
            self.report({"ERROR"}, "set the Dask scheduler address first")
            return {"CANCELLED"}
        try:
            from ..operators.common import check_online
            check_online(address)
            with Cluster(address, timeout=options.CONNECT_TIMEOUT) as cluster:
                info = cluster.describe()
        except BakeError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        self.report({"INFO"}, f"{address}: {info['workers']} workers, {info['cores']} cores, "
                              f"memory limit {info['memory_limit'] / 1e9:.1f} GB per worker")
        return {"FINISHED"}


classes = (DETPBakePreferences, DETPBAKE_OT_test_cluster)


register, unregister = bpy.utils.register_classes_factory(classes)
