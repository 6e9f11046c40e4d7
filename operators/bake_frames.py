"""The Bake operator over a frame range (the panel's Frame Range): every frame is exported on the
main thread first (bpy is not thread-safe), then a frames job (detp_bake/run/job.py) bakes them one
after the other on its worker; Esc keeps the frames already finished, as a shorter sequence. With
Apply After Bake (and a step of 1) the lightmaps go on as image sequences that follow the timeline."""
import json
import time

from ..detp_bake import blender
from ..detp_bake.estimators import FrameState
from ..detp_bake.run import door, frames, job as job_mod, memory
from ..detp_bake.errors import BakeError
from . import common
from .job import BakeJob


class FramesBlenderJob(BakeJob):
    """A bake of the scene's frame range (the exported frames are held in memory until it ends)."""

    def __init__(self, context):
        super().__init__(context, preview=0.0)  # no live preview across frames
        s = context.scene.detp_bake
        self.kind = "frames"
        self.range_text = f"{s.frame_start}-{s.frame_end}:{s.frame_step}"
        self.moving = [o.name for o in context.scene.objects if o.detp_bake.motion == "MOVING"]
        self.static = [o.name for o in context.scene.objects if o.detp_bake.motion == "STATIC"]
        self.frame_range = None

    def prepare(self, context) -> None:
        busy = job_mod.busy_message()
        if busy:
            raise job_mod.JobBusy(busy)
        if not self.objects:
            raise BakeError("nothing to bake: no visible mesh with 'Include' set in the scene")
        self.frame_range = frames.parse_frames(self.range_text)
        s = self.bl_scene.detp_bake
        if not s.output_directory.strip() or (s.output_directory.startswith("//") and not context.blend_data.filepath):
            raise BakeError("setting 'output_directory' is relative to the .blend: save the file first "
                            "or choose an absolute folder")
        self.admission = door.admit(self.settings, out_dir=self.out_dir, frame_state=FrameState())  # run/door.py
        cluster = common.cluster(context)  # the preferences' Dask scheduler: connected by the job's worker
        scenes = {}
        t0 = time.perf_counter()
        try:
            with blender.frame_kept(self.bl_scene):
                for frame in self.frame_range.frames():
                    self.bl_scene.frame_set(frame)
                    scenes[frame] = common.export(context, [self.bl_scene.objects[n] for n in self.objects],
                                                  self.messages.append, self.created_uv)
                    held = sum(sc.positions.nbytes * 3 for sc in scenes.values())
                    free = memory.available_bytes()  # 0: cannot say
                    if free and held > 0.5 * free:
                        raise BakeError(f"the frame range's exported scenes would need more than {held / 1e9:.1f} "
                                        "GB of memory here: bake a shorter range, or from the command line "
                                        "(python -m detp_bake bake --frames), which exports frame by frame")
        except BaseException:
            blender.remove_uv_layers(self.bl_scene, self.created_uv)
            raise
        self.export_seconds = time.perf_counter() - t0
        self.messages = list(dict.fromkeys(self.messages))  # each export says the same
        names = {o.name for scene in scenes.values() for o in scene.objects}
        moving = [n for n in self.moving if n in names]  # overrides on lights, empties, ... say nothing
        static = [n for n in self.static if n in names]
        self.job = job_mod.FramesJob(scenes.__getitem__, self.frame_range, self.admission, None,
                                     moving=moving, static=static, export_seconds=self.export_seconds,
                                     cluster=cluster if hasattr(cluster, "client") else None)

    def finish(self, report) -> set:
        self.messages += self.job.notes if self.job is not None else []  # which objects move, frames kept
        if not self.succeeded(report):
            return self.failed(report)
        r = self.outcome.frames
        scene = self.bl_scene
        if scene.detp_bake.apply_after_bake and "exr" in self.settings.formats and self.frame_range.step == 1:
            first = r.frames[0]
            end = max(f for i, f in enumerate(r.frames) if f == first + i)
            uv = common.uv_layers([scene.objects[n] for n in self.objects if n in scene.objects])
            blender.apply_all(scene, r.files[first], uv, self.settings.estimator, frames=(first, end))
        last = r.sections[-1]
        scene.detp_bake.last_report = json.dumps({
            "estimator": self.settings.estimator, "photons": last["photons"], "segments": last["segments"],
            "objects": len(r.files[r.frames[-1]]), "seconds": last["seconds"], "noise": last["noise"],
            "stopped_by": last["stopped_by"], "frames": r.frames, "output_directory": self.out_dir,
            "files": r.files[r.frames[-1]]}, allow_nan=False)
        for warning in self.warnings:
            report({"WARNING"}, warning)
        done = f"{len(r.frames)} of {len(self.frame_range.frames())} frames" if r.cancelled else f"{len(r.frames)} frames"
        report({"WARNING"} if r.cancelled else {"INFO"},
               f"Baked {done} with {self.settings.estimator} to {self.out_dir}"
               + (" (cancelled: the finished frames are kept)" if r.cancelled else ""))
        return {"FINISHED"}
