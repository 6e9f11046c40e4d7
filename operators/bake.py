"""`detp_bake.bake`: export on the main thread, the job (trace, estimate, write) on its worker,
progress and the live preview in the viewport, Esc to cancel, Stop and Keep to end early with
what there is, one undo step for the result. In background mode it runs at once."""

import bpy

from ..detp_bake.run import job as job_mod
from ..detp_bake.errors import BakeError
from . import common
from .bake_frames import FramesBlenderJob
from .job import BakeJob


class JobOperator:
    """The modal half every job operator shares: timer, status bar, Esc, the end."""

    job_class = BakeJob

    def make_job(self, context):
        return self.job_class(context)

    def _prepare(self, context):
        job = self.make_job(context)
        try:
            job.prepare(context)
        except BakeError as exc:
            self.report({"ERROR"}, str(exc))
            return None
        return job

    def execute(self, context):
        """Synchronous: background mode and scripts."""
        job = self._prepare(context)
        if job is None:
            return {"CANCELLED"}
        common.ACTIVE = job
        try:
            job.run()
        finally:
            common.ACTIVE = None
        return self.finish(context, job)

    def finish(self, context, job):
        return job.finish(self.report)

    def invoke(self, context, event):
        if bpy.app.background:
            return self.execute(context)
        job = self._prepare(context)
        if job is None:
            return {"CANCELLED"}
        self._job = job
        common.ACTIVE = job
        if not job_mod.warming():  # else it starts once the kernels are compiled (modal)
            job.start()
        wm = context.window_manager
        wm.progress_begin(0, 100)
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        job = self._job
        if event.type == "ESC" and event.value == "PRESS":
            job.job.cancel()
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        if job.job.thread is None:  # waiting for the warm-up
            if job.job.cancelling:
                job.outcome = job_mod.Cancelled("export")
            elif not job_mod.warming():
                job.start()
        done = job.handle(job.job.poll())
        if job.progress is not None:
            context.window_manager.progress_update(int(100 * job.progress.overall))
        if context.workspace is not None:
            context.workspace.status_text_set(f"detp_bake: {job.status()}   (Esc to cancel)")
        for area in context.screen.areas if context.screen else ():
            if area.type == "VIEW_3D":
                area.tag_redraw()  # the panel's live line
        if not done:
            return {"RUNNING_MODAL"}
        self._end(context)
        return self.finish(context, job)

    def cancel(self, context):
        """Blender ends the operator (file load, quit): stop the worker and restore the scene."""
        job = self._job
        job.job.cancel()
        if job.job.thread is not None:
            job.job.thread.join()
        self._end(context)
        job.restore()

    def _end(self, context):
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        if context.workspace is not None:
            context.workspace.status_text_set(None)
        common.ACTIVE = None


class DETPBAKE_OT_bake(JobOperator, bpy.types.Operator):
    """Bake irradiance lightmaps for the selected meshes (all included meshes if none is selected)"""
    bl_idname = "detp_bake.bake"
    bl_label = "Bake Lightmaps"
    bl_options = {"REGISTER", "UNDO"}

    def make_job(self, context):
        if context.scene.detp_bake.use_frame_range:  # the panel's Frame Range
            return FramesBlenderJob(context)
        return BakeJob(context)

    @classmethod
    def poll(cls, context):
        return common.idle(cls, context)


class DETPBAKE_OT_stop(bpy.types.Operator):
    """End the running bake after the current batch and keep what it has, as a finished bake with
    the photons traced so far"""
    bl_idname = "detp_bake.stop"
    bl_label = "Stop and Keep"

    @classmethod
    def poll(cls, context):
        return common.ACTIVE is not None and common.ACTIVE.kind == "bake" and common.ACTIVE.job is not None

    def execute(self, context):
        common.ACTIVE.job.stop()
        return {"FINISHED"}


classes = (DETPBAKE_OT_bake, DETPBAKE_OT_stop)
