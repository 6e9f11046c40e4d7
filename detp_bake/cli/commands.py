"""What each command does: a bake, a comparison, a frame range, the glTF export, each checked
before any long work (settings, the .blend, the output folder, object names, UV layers), then run
as a job (run/job.py) whose events go to stderr (output.py).
"""
from __future__ import annotations

import contextlib
import sys
import time
from pathlib import Path
from typing import Optional

from ..run import bake as bake_mod, door, frames, job as job_mod
from ..run.distributed import Cluster
from ..run.memory import geometry_budget
from ..run.results import NOISE_UNIT
from ..lightmap import images
from . import output
from ..errors import BakeCancelled, BakeError
from .arguments import settings_from_args


class StderrProgress:
    """Progress lines on stderr, at most one per phase every `interval` seconds."""

    def __init__(self, interval: float = 2.0):
        self.interval = interval
        self.last: dict = {}

    def __call__(self, p: bake_mod.Progress) -> None:
        now = time.monotonic()
        if p.fraction >= 1.0 or now - self.last.get(p.phase, -1e9) >= self.interval:
            self.last[p.phase] = now
            print(f"detp_bake: {p.message}", file=sys.stderr, flush=True)


def _log(msg: str) -> None:
    print(f"detp_bake: {msg}", file=sys.stderr, flush=True)


def _open_scene(args, settings, bl_scene, warn=output.log, names=None):
    """Check the inputs, open the .blend (unless Blender has one open) and export it; the bake's
    admission (door.py: its settings and output folder checked, once) comes back with the scene."""
    blender, bl_scene, admission = _check_and_open(args, settings, bl_scene, warn, names)
    t0 = time.perf_counter()
    created = []
    scene = blender.export_scene(bl_scene, None, args.objects, args.uv_layer, settings.resolution, _log,
                                 created, max_bytes=geometry_budget(settings.memory_budget_mb) or None,
                                 atlas=settings, warn=warn)
    _warn_created(args, created, warn)
    for name, (flat, total) in scene.export_stats.get("degenerate_triangles", {}).items():
        warn(f"object '{name}': {flat} of its {total} triangles have no area (collapsed faces, zero-length edges) "
             "and are left out; they carry no light, so its lightmap is as it would be without them "
             "(Mesh > Clean Up > Degenerate Dissolve removes them)")
    _log(f"exported {scene.triangle_count} triangles, {len(scene.lights)} lights; "
         f"baking {sum(o.bake for o in scene.objects)} objects")
    return blender, bl_scene, scene, admission, time.perf_counter() - t0


def _warn_created(args, created, warn) -> None:
    if created and not args.save:
        names = [name for name, _ in created]
        warn(f"UV layer '{created[0][1]}' created on {', '.join(names[:5])}"
             f"{f' and {len(names) - 5} more' if len(names) > 5 else ''} is not stored anywhere (no --save): "
             "the lightmaps match it only in a scene saved with it (use --save, or add the layer in Blender)")


def _check_and_open(args, settings, bl_scene, warn=output.log, names=None):
    """Check the inputs (the bake's through door.admit) and open the .blend (unless Blender has one
    open). Returns (the blender adapter, the scene, the admission)."""
    if args.apply and "exr" not in settings.formats:
        raise BakeError("--apply needs the exr format in --format")
    if args.save and (Path(args.save).is_dir() or args.save.endswith(("/", "\\"))):
        raise BakeError(f"--save '{args.save}' is a folder: give the .blend file to save, "
                        f"e.g. --save {Path(args.save) / 'baked.blend'}")
    admission = door.admit(settings, names, args.out)
    if args.save:
        images.check_writable_dir(Path(args.save).resolve().parent)
    elif args.apply:
        warn("--apply without --save: the lightmaps are wired into the materials in memory only, and "
             "nothing lasting happens (add --save OUT.blend)")
    resources = getattr(args, "resources", None)  # main's: the cluster is closed when the command ends
    if resources is not None:
        args.cluster = resources.enter_context(cluster_for(args))
    try:
        from .. import blender
    except ImportError as exc:
        if exc.name != "bpy":
            raise
        raise BakeError("the 'bpy' module is not installed: run inside Blender or install the bpy wheel "
                        "(make demo sets one up)") from None
    if bl_scene is None:
        bl_scene = blender.open_blend(Path(args.scene))
    return blender, bl_scene, admission


def _check_cancel(cancel) -> None:
    if cancel is not None and cancel():
        raise BakeCancelled()


def _run_job(job: job_mod.Job, cancel=None, said=(), main: Optional[job_mod.MainThread] = None) -> job_mod.Result:
    """Run a job to its end, its progress and warnings on stderr as the worker sends them (but the
    warnings in `said`, which the command line has said already, and nothing once cancelled);
    `cancel()` true (a signal, interrupt.py) cancels it. `main`: calls the worker makes on this
    thread (a frame's export), run here between polls."""
    progress = StderrProgress()
    said = set(said)

    def tell(event):  # on the worker thread: in order with what the worker itself prints
        if job.cancelling or (cancel is not None and cancel()):
            return
        if isinstance(event, job_mod.Status):
            progress(event)
        elif isinstance(event, job_mod.Notice) and event.message not in said:
            _log(f"warning: {event.message}")

    job.listener = tell
    job.start()
    try:
        while True:
            if main is not None:
                main.serve()
            for event in job.poll():
                if isinstance(event, job_mod.Error):
                    raise BakeError(event.message)
                if isinstance(event, job_mod.Cancelled):
                    raise BakeCancelled()
                if isinstance(event, job_mod.Result):
                    return event
            if cancel is not None and cancel() and not job.cancelling:
                job.cancel()  # the worker stops within a batch and removes what it staged
            time.sleep(0.05)
    except KeyboardInterrupt:
        job.cancel()
        if main is not None:
            main.close()  # a worker waiting for a frame's export is let go
        job.thread.join()
        raise BakeCancelled() from None


def run_compare(args, bl_scene=None, cancel=None) -> dict:
    """The same photons through several estimators: their lightmaps, compare.png, compare.json and
    one report.json with a section per estimator, all written together."""
    warn = output.Warnings()
    settings = settings_from_args(args)
    if args.frames is not None or args.moving or args.static or args.force:
        raise BakeError("--frames, --moving, --static and --force are for 'bake', not 'compare'")
    blender, bl_scene, scene, admission, export_seconds = _open_scene(args, settings, bl_scene, warn, args.estimators)
    _check_cancel(cancel)
    done = _run_job(job_mod.Job(scene, admission, None, args.estimators, export_seconds=export_seconds,
                                warnings=list(warn), cluster=getattr(args, "cluster", None)), cancel, warn)
    summary = done.comparison
    for name in summary["estimators"]:
        _log(f"{name}: estimate {summary['seconds'][name]:.2f} s, difference to {summary['reference']} "
             f"{100 * summary['difference_to_first'][name]:.1f} %")
    warnings = list(dict.fromkeys(w for r in done.results.values() for w in r.warnings))
    return {"command": "compare", "files": {n: r.files for n, r in done.results.items()},
            "extra": summary["extra"], "report": summary["report"], "warnings": warnings,
            **{k: summary[k] for k in ("estimators", "seconds", "difference_to_first", "trace_seconds", "photons")}}


def _log_noise(result) -> None:
    if result.stopped_by != "photons":
        _log(f"stopped by {result.stopped_by.replace('_', ' ')} after {result.stats.photons:,} photons")
    line = output.noise_line(result.noise, result.noise_unmeasured, result.noise_unit != NOISE_UNIT)
    if line:
        _log(line)


def run_bake(args, bl_scene=None, cancel=None) -> dict:
    """Bake with parsed `args`; `bl_scene` is the open Blender scene (None: open args.scene).
    `cancel()` true stops it before anything is written. Returns the summary `main` prints."""
    warn = output.Warnings()
    settings = settings_from_args(args)
    if args.gltf:
        _check_gltf(args, settings)
    if args.frames is not None or args.moving or args.static:
        return run_frames(args, settings, bl_scene, cancel, warn)
    blender, bl_scene, scene, admission, export_seconds = _open_scene(args, settings, bl_scene, warn)
    out_dir = admission.out_dir
    _check_cancel(cancel)
    done = _run_job(job_mod.Job(scene, admission, export_seconds=export_seconds, warnings=list(warn),
                                cluster=getattr(args, "cluster", None), reuse=True, force=args.force), cancel, warn)
    if done.reused:
        names = list(done.reused)
        _log(f"reused {len(names)} lightmap{'s' if len(names) > 1 else ''} unchanged since the last bake into "
             f"{out_dir}: {', '.join(names[:8])}{' …' if len(names) > 8 else ''} (--force bakes them again)")
    result = done.results.get(settings.estimator)
    if result is not None:
        _log_noise(result)
    files = {**done.reused, **(result.files if result is not None else {})}
    report = done.report
    # The files are in place: from here on a signal no longer undoes the bake.
    saved = None
    if args.apply:
        blender.apply_all(bl_scene, files, args.uv_layer, settings.estimator, log=_log)
        blender.apply_marked(bl_scene, report.parent, log=_log)  # objects marked Probe Light
    if args.save:
        saved = Path(args.save).resolve()
        blender.save_blend(saved, files)
        _log(f"saved {saved}")
    gltf = _export_after_bake(args, bl_scene, report.parent, settings.estimator) if args.gltf else []
    return {"command": "bake", "files": files, "report": str(report), "saved": str(saved) if saved else None,
            "extra": gltf,
            "estimator": settings.estimator, "photons": result.stats.photons if result is not None else 0,
            "stopped_by": result.stopped_by if result is not None else "reused",
            "reused": list(done.reused),
            "noise": result.noise_percent() if result is not None else {},
            "warnings": list(result.warnings) if result is not None else list(warn)}


def _check_gltf(args, settings) -> None:
    """--gltf is checked with the other inputs, before any work."""
    if args.frames is not None or args.moving or args.static:
        raise BakeError("--gltf exports one bake, not a frame range")
    if "exr" not in settings.formats:
        raise BakeError("--gltf needs the exr format in --format (the .glb's lightmaps are made from it)")
    if Path(args.gltf).suffix.lower() != ".glb":
        raise BakeError(f"--gltf '{args.gltf}': give the .glb file to write")
    images.check_writable_dir(Path(args.gltf).resolve().parent)


def _export_after_bake(args, bl_scene, out_dir, estimator) -> list:
    """--gltf: the scene in memory with this bake's lightmaps, as a .glb (blender/gltf.py)."""
    from ..blender.gltf import export_gltf
    done = export_gltf(bl_scene, out_dir, args.gltf, estimator, args.uv_layer, _log)
    return [done["gltf"]]


def run_export_gltf(args, bl_scene=None, cancel=None) -> dict:
    """`export-gltf BAKED.blend --lightmaps DIR --out scene.glb`: every input is checked before
    the .blend is opened (blender/gltf.py checks the rest before it changes anything)."""
    if Path(args.out).suffix.lower() != ".glb":
        raise BakeError(f"--out '{args.out}': give the .glb file to write")
    images.check_writable_dir(Path(args.out).resolve().parent)
    if not (Path(args.lightmaps) / "report.json").is_file():
        raise BakeError(f"no report.json in '{args.lightmaps}': give the output folder of a bake (--lightmaps)")
    try:
        from ..blender import files as blend_files, gltf, identity
    except ImportError as exc:
        if exc.name != "bpy":
            raise
        raise BakeError("the 'bpy' module is not installed: run inside Blender or install the bpy wheel") from None
    gltf.lightmap_files(args.lightmaps, args.estimator)  # a bad report is named before the scene is opened
    if bl_scene is None:
        bl_scene = blend_files.open_blend(Path(args.scene))
    identity.check_lightmaps(bl_scene, args.lightmaps)  # this file's lightmaps, of its geometry as it is
    _check_cancel(cancel)
    done = gltf.export_gltf(bl_scene, args.lightmaps, args.out, args.estimator, args.uv_layer, _log)
    return {"command": "export-gltf", **done}


def run_frames(args, settings, bl_scene=None, cancel=None, warn=output.log) -> dict:
    """--frames: every frame of the range (frames.py); a cancel keeps the frames finished."""
    if args.frames is None:
        raise BakeError("--moving and --static need --frames")
    frame_range = frames.parse_frames(args.frames)
    if args.apply and frame_range.step != 1:
        raise BakeError("--apply with --frames needs every frame (a step of 1): an image sequence has no gaps")
    blender, bl_scene, admission = _check_and_open(args, settings, bl_scene, warn)
    out_dir = admission.out_dir
    created = []
    scene_at = blender.frame_exporter(bl_scene, args.objects, args.uv_layer, settings.resolution, _log, created,
                                      max_bytes=geometry_budget(settings.memory_budget_mb) or None, atlas=settings)
    # The same job engine as every bake (one at a time, events, one progress bar over the range);
    # each frame is exported here, on the main thread, when the worker asks for it.
    main = job_mod.MainThread()
    job = job_mod.FramesJob(lambda frame: main.call(scene_at, frame), frame_range, settings, out_dir,
                            moving=args.moving, static=args.static, force=args.force, log=_log,
                            cluster=getattr(args, "cluster", None))
    try:
        with blender.frame_kept(bl_scene):
            result = _run_job(job, cancel, warn, main).frames
    finally:
        _warn_created(args, created, warn)
    # The finished frames are in place: from here on a signal no longer undoes them.
    first = result.frames[0]
    last = max(f for i, f in enumerate(result.frames) if f == first + i)  # a cancel keeps a shorter sequence
    if args.apply:
        blender.apply_all(bl_scene, result.files[first], args.uv_layer, settings.estimator, frames=(first, last))
        _log(f"applied the lightmaps as image sequences, frames {first}-{last}")
    saved = None
    if args.save:
        saved = Path(args.save).resolve()
        blender.save_blend(saved, {f"{name}@{frame}": paths for frame, files in result.files.items()
                                   for name, paths in files.items()})
        _log(f"saved {saved}")
    if result.cancelled:
        _log(f"cancelled: kept the {len(result.frames)} finished frames of {len(frame_range.frames())}")
    return {"command": "bake", "files": {f"{name}@{frame}": paths for frame in result.frames
                                         for name, paths in result.files[frame].items()},
            "report": str(result.report_path), "saved": str(saved) if saved else None,
            "estimator": settings.estimator, "frames": result.frames, "kept": result.skipped,
            "moving": result.motion.moving, "cancelled": result.cancelled, "warnings": list(warn)}


def cluster_for(args):
    """The Dask cluster to trace on (--scheduler, --workers), connected once the settings have passed
    the door and before the scene is opened (`_check_and_open`); without either, a bake runs here and
    imports no Dask."""
    if not (getattr(args, "scheduler", "") or getattr(args, "workers", 0)):  # export-gltf has neither
        return contextlib.nullcontext()
    if args.scheduler and args.workers:
        raise BakeError("--scheduler and --workers: choose one (a cluster of your own, or workers on this machine)")
    if args.workers < 0:
        raise BakeError(f"setting 'workers' = {args.workers}: must be 1 or more")
    cluster = Cluster(args.scheduler, args.workers, timeout=args.connect_timeout)
    cluster.connect()
    info = cluster.describe()
    _log(f"tracing on {info['workers']} Dask workers ({info['cores']} threads) at {info['address']}")
    return cluster
