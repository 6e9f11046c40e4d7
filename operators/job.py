"""A core job (detp_bake/run/job.py) inside Blender: the main thread's half of it.

`prepare` checks and exports the scene; the job then runs on its worker; `handle` reads its
events on the main thread (progress for the status bar and the panel, the live preview written
into the objects' images, warnings kept for the end); `finish` restores what the preview changed
and applies the result, or removes the UV layers the export created. Both use the scene that was
exported, whatever scene is current by then.
"""
import contextlib
import json
import time

import bpy

from ..detp_bake import blender
from ..detp_bake.run import door, job as job_mod
from ..detp_bake.errors import BakeError
from . import common


class BlenderJob:
    def __init__(self, context, names=None, preview=None):
        """`names` None: a bake; a list: a comparison. `preview`: seconds between live previews
        (None: the scene's setting; 0: none)."""
        self.bl_scene = context.scene
        s = self.bl_scene.detp_bake
        self.kind = "bake" if names is None else "compare"
        self.settings = common.bake_settings(context)
        self.names = names
        self.out_dir = common.output_directory(context)
        self.objects = [o.name for o in common.bake_targets(context)]
        self.preview_interval = (s.live_preview_interval if s.live_preview else 0.0) if preview is None else preview
        if self.kind == "compare":
            self.preview_interval = 0.0  # the comparison shows its own rows at the end
        self.created_uv = []
        self.messages = []  # the export's notes
        self.warnings = []
        self.job = None
        self.preview = None
        self.progress = None  # the last Progress event
        self.snapshot = None  # the last Preview event (photons, noise), without its images
        self.outcome = None
        self.export_seconds = 0.0

    def prepare(self, context) -> None:
        """Check everything that can be checked, then export. Raises BakeError."""
        busy = job_mod.busy_message()
        if busy:
            raise job_mod.JobBusy(busy)
        if not self.objects:
            raise BakeError(f"nothing to {self.kind}: no visible mesh with 'Include' set in the scene")
        s = self.bl_scene.detp_bake
        if not s.output_directory.strip() or (s.output_directory.startswith("//") and not bpy.data.filepath):
            raise BakeError("setting 'output_directory' is relative to the .blend: save the file first "
                            "or choose an absolute folder")
        self.admission = door.admit(self.settings, self.names, self.out_dir)  # checked once (run/door.py)
        cluster = common.cluster(context)  # the preferences' Dask scheduler: connected by the job's worker
        t0 = time.perf_counter()
        try:
            scene = common.export(context, [self.bl_scene.objects[n] for n in self.objects],
                                  self.messages.append, self.created_uv)
        except BaseException:
            blender.remove_uv_layers(self.bl_scene, self.created_uv)
            raise
        self.export_seconds = time.perf_counter() - t0
        # A bake keeps the lightmaps of objects unchanged since the last bake into the same folder
        # (incremental.py), as the command line does, unless Rebake All says otherwise.
        self.job = job_mod.Job(scene, self.admission, None, self.names, export_seconds=self.export_seconds,
                               preview=self.preview_interval, reuse=self.names is None,
                               force=bool(self.bl_scene.detp_bake.rebake_all),
                               cluster=None if isinstance(cluster, contextlib.AbstractContextManager)
                               and not hasattr(cluster, "client") else cluster)
        if self.preview_interval > 0:
            self.preview = blender.LivePreview(self.bl_scene, self.objects,
                                               common.uv_layers([self.bl_scene.objects[n] for n in self.objects]))

    def start(self) -> None:
        self.job.start()

    def handle(self, events) -> bool:
        """Take in events on the main thread; True once the terminal one has come."""
        for event in events:
            if isinstance(event, job_mod.Status):
                self.progress = event
            elif isinstance(event, job_mod.Preview):
                self.snapshot = event
                if self.preview is not None and not self.job.cancelling:
                    self.preview.update(event.images)
            elif isinstance(event, job_mod.Notice):
                self.warnings.append(event.message)
            elif isinstance(event, job_mod.TERMINAL):
                self.outcome = event
        return self.outcome is not None

    def run(self) -> None:
        """Synchronous (background mode, scripts): the events are handled as they come."""
        for event in self.job.events():
            self.handle([event])

    def status(self) -> str:
        """The status bar's line."""
        if self.job.cancelling:
            return "Cancelling…"
        if self.job.thread is None and job_mod.warming():
            return "Waiting for the kernels to compile (the first bake of this session only)"
        text = self.progress.message if self.progress is not None else f"Starting the {self.kind}"
        if self.progress is not None and self.progress.eta is not None:
            text += f" · {self.progress.eta:.0f} s left"
        if self.job.stopping:
            text += " · stopping after this batch"
        return text

    def end(self) -> None:
        """Undo the live preview (a finished bake applies its files afterwards) and free memory."""
        if self.preview is not None:
            self.preview.end()
        job_mod.release_memory()

    def restore(self) -> None:
        """Nothing kept: the scene as it was before the job."""
        self.end()
        blender.remove_uv_layers(self.bl_scene, self.created_uv)

    def succeeded(self, report) -> bool:
        """Say the export's notes; True, with the live preview undone, when the job has a result
        (a finish then applies it), False when it has none (a finish then returns `failed`)."""
        for msg in self.messages:
            report({"INFO"}, msg)
        if not isinstance(self.outcome, job_mod.Result):
            return False
        self.end()
        return True

    def failed(self, report) -> set:
        """Report a job that ended without a result, restoring the scene; {'CANCELLED'}."""
        self.restore()
        if isinstance(self.outcome, job_mod.Error):
            report({"ERROR"}, self.outcome.message)
        else:
            report({"WARNING"}, f"{self.kind.capitalize()} cancelled: nothing was written or changed")
        return {"CANCELLED"}


class BakeJob(BlenderJob):
    """A bake: its finish applies the lightmaps and records the last bake's statistics."""

    def finish(self, report) -> set:
        """Apply the result (main thread) or undo the export's changes; returns operator status."""
        if not self.succeeded(report):
            return self.failed(report)
        r = self.outcome.results.get(self.settings.estimator)  # None: every lightmap was reused
        reused = dict(self.outcome.reused)
        files = {**reused, **(r.files if r is not None else {})}
        scene = self.bl_scene
        s = scene.detp_bake
        if s.apply_after_bake and "exr" in self.settings.formats:
            uv = common.uv_layers([scene.objects[n] for n in self.objects if n in scene.objects])
            blender.apply_all(scene, files, uv, self.settings.estimator,
                              log=lambda note: report({"WARNING"}, note))
            common.apply_probes(scene, self.out_dir, lambda note: report({"WARNING"}, note))
        kept = (f"; {len(reused)} unchanged since the last bake, kept (Rebake All bakes them again)"
                if reused else "")
        for warning in self.warnings:
            report({"WARNING"}, warning)
        if r is None:
            s.last_report = json.dumps({"estimator": self.settings.estimator, "objects": len(files), "files": files,
                                        "reused": sorted(reused), "output_directory": self.out_dir}, allow_nan=False)
            report({"INFO"}, f"All {len(files)} lightmaps unchanged since the last bake into {self.out_dir}: kept")
            return {"FINISHED"}
        summary = r.report()
        s.last_report = json.dumps({"estimator": r.settings.estimator, "photons": summary["photons"],
                                    "segments": summary["segments"], "objects": len(files),
                                    "seconds": summary["seconds"], "files": files, "reused": sorted(reused),
                                    "noise": summary["noise"], "stopped_by": summary["stopped_by"],
                                    "charts": {o["name"]: o["charts"] for o in summary["objects"] if "charts" in o},
                                    "output_directory": self.out_dir}, allow_nan=False)
        total = sum(v for k, v in r.seconds.items() if k != "rasterise")
        report({"INFO"}, f"Baked {len(r.files)} lightmaps with {r.settings.estimator} in {total:.1f} s "
                         f"({summary['photons']:,} photons) to {self.out_dir}{kept}")
        return {"FINISHED"}
