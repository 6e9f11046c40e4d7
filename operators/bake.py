"""`detp_bake.bake`: export on the main thread, trace and estimate in a worker thread, progress in
the status bar, Esc to cancel, one undo step for the result. In background mode it runs at once."""
import json
import threading
import time
import traceback

import bpy

from ..detp_bake import bake, blender, images
from ..detp_bake.errors import BakeCancelled, BakeError
from . import common

PHASES = {"direct": (0.0, 0.1), "prepare": (0.1, 0.15), "trace": (0.15, 0.9), "estimate": (0.9, 0.97),
          "write": (0.97, 1.0)}


class BakeJob:
    """One bake, split where Blender needs it: `prepare` and `finish` touch Blender data and run on
    the main thread; `run` is core work only and may run in a worker thread. A cancel at any point
    leaves the scene as it was: UV layers the export created are removed again."""

    def __init__(self, context):
        self.settings = common.bake_settings(context)
        self.out_dir = common.output_directory(context)
        self.objects = [o.name for o in common.bake_targets(context)]
        self.cancel = threading.Event()
        self.cluster = common.cluster(context)  # connected in `run`, off the main thread
        self.progress = bake.Progress("export", 0.0, "Exporting scene")
        self.created_uv = []
        self.messages = []
        self.result = None
        self.error = None
        self.cancelled = False
        self.thread = None
        self.scene = None
        self.export_seconds = 0.0

    def prepare(self, context) -> None:
        """Check everything that can be checked, then export. Raises BakeError."""
        self.settings.validate()
        if not self.objects:
            raise BakeError("nothing to bake: no visible mesh with 'Include' set in the scene")
        if not context.scene.detp_bake.output_directory.strip() or (
                context.scene.detp_bake.output_directory.startswith("//") and not bpy.data.filepath):
            raise BakeError("setting 'output_directory' is relative to the .blend: save the file first "
                            "or choose an absolute folder")
        images.check_writable_dir(self.out_dir)
        t0 = time.perf_counter()
        try:
            self.scene = common.export(context, [context.scene.objects[n] for n in self.objects],
                                       self.messages.append, self.created_uv)
        except BaseException:
            blender.remove_uv_layers(context.scene, self.created_uv)
            raise
        self.export_seconds = time.perf_counter() - t0

    def _on_progress(self, p: bake.Progress) -> None:
        self.progress = p

    def run(self) -> None:
        try:
            with self.cluster as cluster:
                result = bake.compute(self.scene, self.settings, self._on_progress, self.cancel, cluster)
            result.seconds["export"] = self.export_seconds
            bake.write(result, self.out_dir, self._on_progress, self.cancel)
            self.result = result
        except BakeCancelled:
            self.cancelled = True
        except BakeError as exc:
            self.error = str(exc)
        except Exception as exc:  # a bug: say so instead of dying silently in a thread
            traceback.print_exc()
            self.error = f"unexpected error: {exc!r}"

    def start(self) -> None:
        self.thread = threading.Thread(target=self.run, name="detp_bake", daemon=True)
        self.thread.start()

    @property
    def done(self) -> bool:
        return self.thread is None or not self.thread.is_alive()

    @property
    def fraction(self) -> float:
        lo, hi = PHASES.get(self.progress.phase, (0.0, 0.0))
        return lo + (hi - lo) * min(1.0, max(0.0, self.progress.fraction))

    def finish(self, context, report) -> set:
        """Apply the result (main thread) or undo the export's changes; returns operator status."""
        for msg in self.messages:
            report({"INFO"}, msg)
        if self.cancelled or self.error or self.result is None:
            blender.remove_uv_layers(context.scene, self.created_uv)
            if self.error:
                report({"ERROR"}, self.error)
            else:
                report({"WARNING"}, "Bake cancelled: nothing was written or changed")
            return {"CANCELLED"}
        r = self.result
        s = context.scene.detp_bake
        if s.apply_after_bake and "exr" in r.settings.formats:
            uv = common.uv_layers([context.scene.objects[n] for n in self.objects if n in context.scene.objects])
            blender.apply_all(context.scene, r.files, uv, r.settings.estimator)
        summary = r.report()
        s.last_report = json.dumps({"estimator": r.settings.estimator, "photons": summary["photons"],
                                    "segments": summary["segments"], "objects": len(r.files),
                                    "seconds": summary["seconds"], "files": r.files,
                                    "noise": summary["noise"], "stopped_by": summary["stopped_by"],
                                    "output_directory": self.out_dir})
        total = sum(v for k, v in r.seconds.items() if k != "rasterise")
        for warning in r.warnings:
            report({"WARNING"}, warning)
        report({"INFO"}, f"Baked {len(r.files)} lightmaps with {r.settings.estimator} in {total:.1f} s "
                         f"({summary['photons']:,} photons) to {self.out_dir}")
        return {"FINISHED"}


class DETPBAKE_OT_bake(bpy.types.Operator):
    """Bake irradiance lightmaps for the selected meshes (all included meshes if none is selected)"""
    bl_idname = "detp_bake.bake"
    bl_label = "Bake Lightmaps"
    bl_options = {"REGISTER", "UNDO"}

    _running = False

    @classmethod
    def poll(cls, context):
        return common.idle(cls, context)

    def _prepare(self, context):
        if context.scene.detp_bake.use_frame_range:
            from .bake_frames import FramesJob
            job = FramesJob(context)
        else:
            job = BakeJob(context)
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
        job.run()
        return job.finish(context, self.report)

    def invoke(self, context, event):
        if bpy.app.background:
            return self.execute(context)
        job = self._prepare(context)
        if job is None:
            return {"CANCELLED"}
        self._job = job
        DETPBAKE_OT_bake._running = True
        job.start()
        wm = context.window_manager
        wm.progress_begin(0, 100)
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        job = self._job
        if event.type == "ESC" and event.value == "PRESS":
            job.cancel.set()
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        context.window_manager.progress_update(int(100 * job.fraction))
        text = "Cancelling…" if job.cancel.is_set() else job.progress.message
        if context.workspace is not None:
            context.workspace.status_text_set(f"detp_bake: {text}   (Esc to cancel)")
        if not job.done:
            return {"RUNNING_MODAL"}
        self._end(context)
        return job.finish(context, self.report)

    def cancel(self, context):
        self._job.cancel.set()
        if self._job.thread is not None:
            self._job.thread.join()
        self._end(context)
        blender.remove_uv_layers(context.scene, self._job.created_uv)

    def _end(self, context):
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        if context.workspace is not None:
            context.workspace.status_text_set(None)
        DETPBAKE_OT_bake._running = False


classes = (DETPBAKE_OT_bake,)
