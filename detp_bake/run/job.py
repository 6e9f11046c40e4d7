"""A job: one bake, one comparison or one frame range (FramesJob), run on a worker thread and told
as typed events.

Every front end (the Blender operators, `blender -c detp_bake`, `python -m detp_bake`) makes a Job
from settings and an exported scene and reads its events: Started, Phase, Status (with an
ETA), Notice, Preview, then exactly one of Result, Error or Cancelled. The job turns the core's
progress callback, its cancel and stop callables and its exceptions into those events, so no
front end talks to bake.py's four channels itself. A frame range's progress (`Status.part`) runs
once over the whole range. The command line exports each frame when the worker asks for it, on its
own thread (`MainThread`: bpy is not thread-safe); the panel exports every frame first.

One job runs at a time per process (a Blender session): two at once would share numba's thread
pool, which aborts the process under the workqueue layer. `start` refuses a second one with
JobBusy, and `running()` says which job holds the lock, for the operators' greyed-out buttons.
"""
from __future__ import annotations

import contextlib
import queue
import threading
import time
import traceback
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Iterator, Optional

from . import bake as bake_mod, comparison, door, frames, incremental
from ..lightmap import staging
from ..transport import photons
from ..errors import BakeCancelled, BakeError

# Share of the whole job each phase stands for (the progress bar and the ETA).
PHASES = {"export": (0.0, 0.0), "direct": (0.0, 0.1), "prepare": (0.1, 0.15), "trace": (0.15, 0.9),
          "estimate": (0.9, 0.96), "probes": (0.96, 0.98), "write": (0.98, 1.0)}
# A slow preview (the photon map's gather over every hit so far, on the worker: tracing waits for
# it) waits this many times as long as it took before the next, so previews cost at most a sixth
# of the bake.
SLOW_PREVIEW_WAIT = 5.0


class JobBusy(BakeError):
    """Another job holds the session's lock."""


@dataclass
class Event:
    pass


@dataclass
class Started(Event):
    kind: str  # bake or compare
    estimators: list
    photons: int  # the most the job traces
    objects: int


@dataclass
class Phase(Event):
    phase: str  # direct, prepare, trace, estimate, probes, write


@dataclass
class Status(Event):
    """How far the job has got (bake.py's Progress, with the whole job's share and the time left)."""
    phase: str
    fraction: float  # of the phase
    message: str
    overall: float  # of the whole job
    eta: Optional[float]  # seconds left, once there is enough to go on


@dataclass
class Notice(Event):
    """A warning the job passes on to the person (the front end shows it once)."""
    message: str


@dataclass
class Preview(Event):
    """The primary estimator's lightmaps as they stand: {object: (H, W, 3) E/π, row 0 at the bottom}."""
    estimator: str
    images: dict
    photons: int
    share: float
    noise: Optional[float]  # worst relative noise so far (None until measured)


@dataclass
class Result(Event):
    results: dict  # {estimator: BakeResult}
    out_dir: Optional[Path]
    report: Optional[Path]  # report.json (a bake) or the comparison's report
    comparison: Optional[dict] = None  # a compare's summary (comparison.report_files)
    frames: Optional[object] = None  # a frame range's frames.FramesResult (cancelled: the frames kept)
    reused: dict = field(default_factory=dict)  # object -> files of lightmaps kept from the last bake


@dataclass
class Error(Event):
    message: str
    unexpected: bool = False  # a bug, not bad input


@dataclass
class Cancelled(Event):
    phase: str


TERMINAL = (Result, Error, Cancelled)

_lock = threading.Lock()
_running: Optional["Job"] = None


def running() -> Optional["Job"]:
    """The job that holds the lock, or None."""
    return _running


def busy_message() -> Optional[str]:
    """Why a new job cannot start now, or None (also while the warm-up runs: a job waits for it)."""
    job = _running
    if job is None or isinstance(job, _Holder):
        return None
    return f"a {job.kind} is running: wait for it or press Esc"


class _Holder:
    """The lock held by something that is not a job: the kernels' warm-up (warmup.py)."""

    def __init__(self, kind: str):
        self.kind = kind


def hold(kind: str) -> Optional[_Holder]:
    """Take the lock for work that is not a job, if free; None when a job holds it."""
    global _running
    if not _lock.acquire(blocking=False):
        return None
    _running = _Holder(kind)
    return _running


def release(holder: _Holder) -> None:
    global _running
    if _running is holder:
        _running = None
        _lock.release()


def warming() -> bool:
    """The warm-up holds the lock: a job started now waits for it."""
    return isinstance(_running, _Holder)


@dataclass
class _Clock:
    start: float = field(default_factory=time.perf_counter)

    def eta(self, overall: float) -> Optional[float]:
        elapsed = time.perf_counter() - self.start
        if overall < 0.02 or elapsed < 1.0:
            return None
        return elapsed * (1.0 - overall) / overall


class Job:
    """`names` None: a bake of settings.estimator; a list: a comparison of those estimators fed
    the same photons (the first is the reference). `out_dir` None computes only. `preview`
    seconds > 0: a Preview event at most that often while tracing (the photon map's less often:
    SLOW_PREVIEW_WAIT). `warnings`: what the front end found before the job (they go into
    report.json too). `cluster`: a distributed.Cluster to trace on. `listener` sees every event
    on the worker thread as it is sent, in order with anything the worker prints (a command
    line's stderr), before the front end's own read of the queue."""

    def __init__(self, scene, settings: bake_mod.BakeSettings | door.Admission, out_dir=None, names=None, *,
                 export_seconds: float = 0.0, preview: float = 0.0, warnings=(), cluster=None, listener=None,
                 reuse: bool = False, force: bool = False):
        # An Admission (door.py) passed the door in the front end: its settings, estimators and folder
        # are not checked again. Plain settings are checked on the worker (an Error event when bad).
        self.admission = settings if isinstance(settings, door.Admission) else None
        if self.admission is not None:
            settings, out_dir = self.admission.settings, self.admission.out_dir
            names = None if len(self.admission.names) == 1 and names is None else list(self.admission.names)
        self.kind = "bake" if names is None else "compare"
        self.names = [settings.estimator] if names is None else list(dict.fromkeys(names))
        self.scene = scene
        self.settings = settings
        self.chosen = settings.photons  # the photons the job traces at most (chosen when it starts)
        self.out_dir = None if out_dir is None else Path(out_dir)
        self.export_seconds = export_seconds
        self.preview_interval = float(preview)
        self._warnings = list(warnings)
        self.listener = listener
        self.cluster = cluster
        # A bake keeps the lightmaps of the last bake into out_dir that cannot have changed
        # (incremental.py); `force` bakes them all again.
        self.reuse, self.force = reuse, force
        self._events: "queue.Queue[Event]" = queue.Queue()
        self._cancel = threading.Event()
        self._stop = threading.Event()
        self.thread: Optional[threading.Thread] = None
        self.phase = "export"
        self.last: Optional[Status] = None
        self.outcome: Optional[Event] = None  # the terminal event, once the worker has sent it
        self._next_preview = -1e9  # perf_counter time
        self._clock = _Clock()

    # The front end's side -------------------------------------------------------------------
    def start(self) -> "Job":
        """Take the session's lock (after the warm-up, if it runs) and run on a worker thread.
        Raises JobBusy when another job runs."""
        global _running
        if not _lock.acquire(blocking=False):
            if not warming():
                raise JobBusy(busy_message() or "another job is running")
            _lock.acquire()
        _running = self
        self.thread = threading.Thread(target=self._work, name=f"detp_bake {self.kind}", daemon=True)
        self.thread.start()
        return self

    def cancel(self) -> None:
        """Stop as soon as possible; nothing is written or kept."""
        self._cancel.set()

    def stop(self) -> None:
        """Stop tracing after the current batch and keep what there is as a finished bake."""
        self._stop.set()

    @property
    def cancelling(self) -> bool:
        return self._cancel.is_set()

    @property
    def stopping(self) -> bool:
        return self._stop.is_set()

    @property
    def done(self) -> bool:
        return self.thread is not None and not self.thread.is_alive() and self._events.empty()

    def poll(self) -> list:
        """The events sent since the last call, without waiting (a modal timer's read)."""
        out = []
        while True:
            try:
                out.append(self._events.get_nowait())
            except queue.Empty:
                return out

    def events(self, timeout: Optional[float] = None) -> Iterator[Event]:
        """Every event until the terminal one (starting the job if nobody has), waiting for each."""
        if self.thread is None:
            self.start()
        while True:
            event = self._events.get(timeout=timeout)
            yield event
            if isinstance(event, TERMINAL):
                return

    def run(self) -> Event:
        """Run to the end, dropping the events; the terminal one is returned."""
        for event in self.events():
            pass
        return event

    # The worker's side ----------------------------------------------------------------------
    def _send(self, event: Event) -> None:
        if self.listener is not None:
            self.listener(event)
        self._events.put(event)

    def _progress(self, p: bake_mod.Progress) -> None:
        if self._cancel.is_set():  # every report is a cancel point: it ends the phase that ran
            raise BakeCancelled()
        if p.phase != self.phase:
            self.phase = p.phase
            self._send(Phase(p.phase))
        lo, hi = PHASES.get(p.phase, (0.0, 0.0))
        overall = lo + (hi - lo) * min(1.0, max(0.0, p.fraction))
        if p.part is not None:  # a frame of a range: one bar and one ETA over the whole range
            k, n = p.part
            overall = (k + overall) / max(n, 1)
        self.last = Status(p.phase, p.fraction, p.message, overall, self._clock.eta(overall))
        self._send(self.last)

    def _preview(self, partial: bake_mod.Snapshot) -> None:
        now = time.perf_counter()
        if now < self._next_preview:
            return
        self._next_preview = now + self.preview_interval
        images = bake_mod.preview_images(partial.texels, partial.read(), self.settings.margin)
        if partial.slow:
            done = time.perf_counter()
            self._next_preview = max(self._next_preview, done + SLOW_PREVIEW_WAIT * (done - now))
        self._send(Preview(partial.estimator, images, partial.photons, partial.share, partial.noise))

    def _work(self) -> None:
        global _running
        try:
            # The photons are chosen once, for the Started event and the bake alike (door.with_photons).
            self.chosen = door.auto_photons(self.scene, self.settings) if self.scene is not None else \
                self.settings.photons
            self._send(Started(self.kind, list(self.names), self.chosen,
                               sum(o.bake for o in self.scene.objects) if self.scene is not None else 0))
            for message in self._warnings:
                self._send(Notice(message))
            self._remove_stale()
            outcome = self._compute()
        except BakeCancelled:
            outcome = Cancelled(self.phase)
        except BakeError as exc:
            outcome = Error(str(exc))
        except Exception as exc:  # a bug: say so instead of dying silently in a thread
            traceback.print_exc()
            outcome = Error(f"unexpected error: {exc!r}", unexpected=True)
        finally:
            self.scene = None  # the exported scene can be large: the job no longer needs it
            _running = None
            _lock.release()
        self.outcome = outcome
        self._send(outcome)

    def _remove_stale(self) -> None:
        """The temporaries a killed bake left in the output folder go (staging.remove_stale), said."""
        removed = staging.remove_stale(self.out_dir) if self.out_dir is not None else []
        if removed:
            message = (f"removed {len(removed)} temporary files an interrupted bake left in {self.out_dir}: "
                       f"{', '.join(removed[:4])}{' …' if len(removed) > 4 else ''}")
            self._warnings.append(message)
            self._send(Notice(message))

    def _admitted(self, scene, reduced: bool) -> door.Admission:
        """The door's admission (checked here unless the front end brought one), with the photons
        chosen once: for the whole scene, or for what is left of it when lightmaps are reused."""
        admission = self.admission or door.admit(self.settings, self.names, self.out_dir)
        if self.settings.photons or not self.chosen:
            return admission
        chosen = door.auto_photons(scene, self.settings) if reduced else self.chosen
        return replace(admission, settings=replace(admission.settings, photons=chosen), automatic=True)

    def _compute(self) -> Result:
        scene, plan = self.scene, None
        if self.reuse and self.kind == "bake" and self.out_dir is not None:
            plan = incremental.plan(scene, self.settings, self.out_dir, self.force)
            if not plan.bake:  # every lightmap is there and cannot have changed
                report = incremental.write_all_reused(plan, self.out_dir)
                return Result({}, self.out_dir, report, reused={n: e["files"] for n, e in plan.reused.items()})
            scene = incremental.without(scene, plan.reused)
        admission = self._admitted(scene, plan is not None and bool(plan.reused))
        connect = self.cluster is not None and getattr(self.cluster, "client", None) is None
        with (self.cluster if connect else contextlib.nullcontext(self.cluster)) as cluster:  # here, off the UI
            results = bake_mod.compute_many(scene, admission, None, self._progress, self._cancel,
                                            cluster=cluster, stop=self._stop.is_set,
                                            preview=self._preview if self.preview_interval > 0 else None,
                                            reach_of=list(plan.reused) if plan is not None else None)
        for result in results.values():
            if plan is not None:
                incremental.record(result, plan)
            result.seconds["export"] = self.export_seconds
            found = []
            if self.out_dir is not None:  # older files of these lightmaps that this bake leaves
                bake_mod.warn_stale(self.out_dir, result, found.append)
            for message in dict.fromkeys(found + result.warnings):
                self._send(Notice(message))
            result.warnings = list(dict.fromkeys(self._warnings + found + result.warnings))  # for report.json
        report, summary = None, None
        if self.out_dir is not None:  # every file together, or none (bake.write_many)
            if self.kind == "compare":
                summary, extra = comparison.report_files(results, self.names)
                report = bake_mod.write_many(results, self.out_dir, self._progress, self._cancel, extra=extra,
                                             summary={"comparison": dict(summary)})
                summary["report"] = str(report)
                summary["image"] = str(self.out_dir / "compare.png")
                summary["extra"] = [str(self.out_dir / name) for name in extra]
            else:
                report = bake_mod.write(results[self.names[0]], self.out_dir, self._progress, self._cancel)
        elif self.kind == "compare":
            summary, _ = comparison.report_files(results, self.names)
        return Result(results, self.out_dir, report, summary,
                      reused={n: e["files"] for n, e in plan.reused.items()} if plan is not None else {})


class FramesJob(Job):
    """A frame range as a job (frames.bake_frames on the worker, the same events): `scene_at(frame)`
    gives each frame's exported scene. A cancel keeps the frames finished: the outcome is then a
    Result whose `frames.cancelled` is set (Cancelled only when no frame was finished). The range's
    notes (which objects move, frames kept) are in `notes`."""

    def __init__(self, scene_at, frame_range, settings: bake_mod.BakeSettings, out_dir, *, moving=(), static=(),
                 force: bool = False, warnings=(), export_seconds: float = 0.0, log=None, cluster=None):
        super().__init__(None, settings, out_dir, warnings=warnings, export_seconds=export_seconds, cluster=cluster)
        self.kind = "frames"
        self.scene_at, self.frame_range = scene_at, frame_range
        self.moving, self.static, self.force = list(moving), list(static), force
        self.notes: list = []
        self.log = log  # also told each note as it comes (the command line's stderr), when given

    def _note(self, message: str) -> None:
        self.notes.append(message)
        if self.log is not None:
            self.log(message)

    def _compute(self) -> Result:
        connect = self.cluster is not None and getattr(self.cluster, "client", None) is None
        with (self.cluster if connect else contextlib.nullcontext(self.cluster)) as cluster:  # here, off the UI
            done = frames.bake_frames(self.scene_at, self.frame_range, self.admission or self.settings,
                                      self.out_dir, self._progress, self._cancel, self.moving, self.static,
                                      self._note, self.force, cluster)
        if not done.frames:
            raise BakeCancelled()
        return Result({}, self.out_dir, done.report_path, frames=done)


class MainThread:
    """Calls a job's worker must make on the front end's thread (bpy is not thread-safe: a frame
    range's export, frame by frame): the worker's `call(fn, *args)` waits until the front end's
    loop runs `serve()`, and returns what fn returned or raises what it raised."""

    def __init__(self):
        self._calls: queue.Queue = queue.Queue()
        self.closed = False

    def call(self, fn, *args):
        if self.closed:
            raise BakeCancelled()
        box, done = {}, threading.Event()
        self._calls.put((fn, args, box, done))
        done.wait()
        if "error" in box:
            raise box["error"]
        return box["value"]

    def serve(self) -> None:
        """Run the calls waiting (on the front end's thread)."""
        while True:
            try:
                fn, args, box, done = self._calls.get_nowait()
            except queue.Empty:
                return
            try:
                if self.closed:
                    raise BakeCancelled()
                box["value"] = fn(*args)
            except BaseException as exc:  # the worker raises it, as if it had called fn itself
                box["error"] = exc
            done.set()

    def close(self) -> None:
        """No more calls: the waiting ones and any later one raise BakeCancelled in the worker."""
        self.closed = True
        self.serve()


def release_memory() -> None:
    """Let go of what the core keeps between jobs (the tracer's buffer pools). Embree's scene goes
    with the job's last reference to it; embreex has no call of its own for that."""
    photons.release_memory()
