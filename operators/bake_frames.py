"""The Bake operator over a frame range (the panel's Frame Range): every frame is exported on the
main thread first (bpy is not thread-safe), then the worker thread bakes them one after the other
with frames.bake_frames; Esc keeps the frames already finished, as a shorter sequence. With Apply
After Bake (and a step of 1) the lightmaps go on as image sequences that follow the timeline."""
import json

from ..detp_bake import blender, frames, memory
from ..detp_bake.errors import BakeCancelled, BakeError
from .bake import BakeJob


class FramesJob(BakeJob):
    """A BakeJob whose `run` bakes a frame range (the exported frames are held in memory)."""

    def __init__(self, context):
        super().__init__(context)
        s = context.scene.detp_bake
        self.range_text = f"{s.frame_start}-{s.frame_end}:{s.frame_step}"
        self.moving = [o.name for o in context.scene.objects if o.detp_bake.motion == "MOVING"]
        self.static = [o.name for o in context.scene.objects if o.detp_bake.motion == "STATIC"]
        self.scenes = {}
        self.frames_result = None

    def prepare(self, context) -> None:
        self.frame_range = frames.parse_frames(self.range_text)
        with blender.frame_kept(context.scene):
            for frame in self.frame_range.frames():
                context.scene.frame_set(frame)
                super().prepare(context)
                self.scenes[frame] = self.scene
                held = sum(sc.positions.nbytes * 3 for sc in self.scenes.values())
                free = memory.available_bytes()  # 0: cannot say
                if free and held > 0.5 * free:
                    blender.remove_uv_layers(context.scene, self.created_uv)
                    raise BakeError(f"the frame range's exported scenes would need more than {held / 1e9:.1f} GB "
                                    "of memory here: bake a shorter range, or from the command line (python -m "
                                    "detp_bake bake --frames), which exports frame by frame")
        self.messages = list(dict.fromkeys(self.messages))  # each export says the same
        names = {o.name for scene in self.scenes.values() for o in scene.objects}
        self.moving = [n for n in self.moving if n in names]  # overrides on lights, empties, ... say nothing
        self.static = [n for n in self.static if n in names]

    def run(self) -> None:
        try:
            self.frames_result = frames.bake_frames(self.scenes.__getitem__, self.frame_range, self.settings,
                                                    self.out_dir, self._on_progress, self.cancel, self.moving,
                                                    self.static, self.messages.append)
            self.cancelled = self.frames_result.cancelled
        except BakeCancelled:
            self.cancelled = True
        except BakeError as exc:
            self.error = str(exc)
        except Exception as exc:  # a bug: say so instead of dying silently in a thread
            import traceback
            traceback.print_exc()
            self.error = f"unexpected error: {exc!r}"
        self.scenes.clear()

    def finish(self, context, report) -> set:
        for msg in self.messages:
            report({"INFO"}, msg)
        r = self.frames_result
        if self.error or r is None or not r.frames:
            blender.remove_uv_layers(context.scene, self.created_uv)
            if self.error:
                report({"ERROR"}, self.error)
            else:
                report({"WARNING"}, "Bake cancelled: no frame was finished")
            return {"CANCELLED"}
        s = context.scene.detp_bake
        if s.apply_after_bake and "exr" in self.settings.formats and self.frame_range.step == 1:
            first = r.frames[0]
            end = max(f for i, f in enumerate(r.frames) if f == first + i)
            from . import common
            uv = common.uv_layers([context.scene.objects[n] for n in self.objects if n in context.scene.objects])
            blender.apply_all(context.scene, r.files[first], uv, self.settings.estimator, frames=(first, end))
        last = r.sections[-1]
        context.scene.detp_bake.last_report = json.dumps({
            "estimator": self.settings.estimator, "photons": last["photons"], "segments": last["segments"],
            "objects": len(r.files[r.frames[-1]]), "seconds": last["seconds"], "noise": last["noise"],
            "stopped_by": last["stopped_by"], "frames": r.frames, "output_directory": self.out_dir,
            "files": r.files[r.frames[-1]]})
        done = f"{len(r.frames)} of {len(self.frame_range.frames())} frames" if r.cancelled else f"{len(r.frames)} frames"
        report({"WARNING"} if r.cancelled else {"INFO"},
               f"Baked {done} with {self.settings.estimator} to {self.out_dir}"
               + (" (cancelled: the finished frames are kept)" if r.cancelled else ""))
        return {"FINISHED"}
