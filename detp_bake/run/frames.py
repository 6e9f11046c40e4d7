"""Baking a frame range: every frame of an animation, lightmaps numbered by frame.

`bake_frames` takes the scene of each frame from a callable (the Blender adapter sets the frame and
exports it: blender/frames.py; tests build scenes by hand). It first evaluates every frame and
hashes each object's evaluated arrays (`object_signatures`: world-space geometry, UVs, materials),
so the objects that move over the range are found whatever moves them (keyframes, drivers,
modifiers, shape keys, armatures, geometry nodes); `--moving` / `--static` override that. Then it
bakes frame after frame, sharing a `FrameState` between them (the hybrid estimator keeps its index
over the static objects' discs there) and writing `<object>.<estimator>.<frame:04d>.<format>`.

No flicker: a photon's random numbers depend on the bake seed and its id alone (schedule.py), so
every frame traces the same photons and a path that meets no moving object is the same path in
every frame; a texel that no changed path reaches gets the same sums, in the same order, so the
same bits (with denoising off: OIDN looks at the whole image).

report.json is rewritten after every finished frame, so a cancel leaves the frames done so far as a
valid, shorter sequence with a report that lists them.
"""
from __future__ import annotations

import json
import os
import re
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Optional

import numpy as np

from .. import __version__
from . import bake as bake_mod, door
from ..lightmap import staging
from .incremental import digest as _digest, lights_signature, object_signatures  # noqa: F401  (frames' keys)
from ..errors import BakeCancelled, BakeError
from ..estimators import FrameState
from ..scene import Scene

MAX_FRAMES = 100_000
SCENE_CACHE_BYTES = 256e6  # evaluated scenes kept from the motion pass for the bake pass


@dataclass(frozen=True)
class FrameRange:
    start: int
    end: int
    step: int = 1

    def frames(self) -> list[int]:
        return list(range(self.start, self.end + 1, self.step))

    def __str__(self) -> str:
        return f"{self.start}-{self.end}" + (f":{self.step}" if self.step != 1 else "")


_RANGE = re.compile(r"^\s*(-?\d+)\s*(?:-\s*(-?\d+))?\s*(?::\s*(\d+))?\s*$")


def parse_frames(text: str) -> FrameRange:
    """'A', 'A-B' or 'A-B:STEP' (frames may be negative, as in Blender: '-5--1')."""
    m = _RANGE.match(str(text))
    if not m:
        raise BakeError(f"frames '{text}': write A-B or A-B:STEP (for example 1-24 or 1-24:2)")
    start = int(m.group(1))
    end = int(m.group(2)) if m.group(2) is not None else start
    step = int(m.group(3)) if m.group(3) is not None else 1
    if end < start:
        raise BakeError(f"frames '{text}': the last frame {end} comes before the first {start}")
    if step < 1:
        raise BakeError(f"frames '{text}': the step must be 1 or more")
    if (end - start) // step + 1 > MAX_FRAMES:
        raise BakeError(f"frames '{text}': more than {MAX_FRAMES:,} frames")
    return FrameRange(start, end, step)


def object_boxes(scene: Scene) -> dict[str, np.ndarray]:
    """Each object's world-space bounding box, (2, 3): lo, hi."""
    out = {}
    for obj in scene.objects:
        p = scene.positions[obj.triangles].reshape(-1, 3)
        if len(p):
            out[obj.name] = np.array([p.min(axis=0), p.max(axis=0)], np.float64)
    return out


@dataclass
class Motion:
    """Which objects move over the range, and why each is said to."""
    objects: list[str]  # every object seen in any frame, in first-seen order
    found: list[str]  # found moving by evaluating the frames
    forced_moving: list[str]
    forced_static: list[str]
    lights_change: bool

    @property
    def moving(self) -> list[str]:
        return [n for n in self.objects if (n in self.found or n in self.forced_moving) and n not in self.forced_static]

    @property
    def static(self) -> list[str]:
        moving = set(self.moving)
        return [n for n in self.objects if n not in moving]

    def describe(self) -> str:
        found = ", ".join(self.found) if self.found else "none"
        text = f"found moving over the range: {found}"
        if self.forced_moving:
            text += f"; moving by --moving: {', '.join(self.forced_moving)}"
        if self.forced_static:
            text += f"; static by --static: {', '.join(self.forced_static)}"
        if self.lights_change:
            text += "; the lights or the world change between frames"
        return text

    def report(self) -> dict:
        return {"moving": self.moving, "static": self.static, "found_moving": self.found,
                "forced_moving": self.forced_moving, "forced_static": self.forced_static,
                "lights_change": self.lights_change}


def find_motion(signatures: list[dict], lights: list[str], moving: Iterable[str] = (),
                static: Iterable[str] = ()) -> Motion:
    """Objects whose signature differs between any two frames (or that are missing from some) move.
    `moving` / `static` force objects either way; a name in neither frame is a BakeError."""
    objects = list(dict.fromkeys(n for sig in signatures for n in sig))
    found = [n for n in objects if len({sig.get(n) for sig in signatures}) > 1]
    moving, static = list(dict.fromkeys(moving)), list(dict.fromkeys(static))
    both = sorted(set(moving) & set(static))
    if both:
        raise BakeError(f"object '{both[0]}' is given as both moving and static")
    unknown = [n for n in moving + static if n not in objects]
    if unknown:
        raise BakeError(f"object '{unknown[0]}' (--moving/--static) is not in the exported scene")
    return Motion(objects, found, moving, static, len(set(lights)) > 1)


@dataclass
class FramesResult:
    frames: list[int]  # finished frames, in order
    files: dict  # frame -> {object name: [paths]}
    motion: Motion
    cancelled: bool
    report_path: Path
    sections: list = field(default_factory=list)  # report.json's per-frame sections
    skipped: list = field(default_factory=list)  # frames kept from the last bake, unchanged


def _frame_label(k: int, n: int, frame: int) -> str:
    return f"Frame {k + 1}/{n}" + ("" if frame == k + 1 else f" (#{frame})")


def bake_frames(scene_at: Callable[[int], Scene], frames: FrameRange,
                settings: bake_mod.BakeSettings | door.Admission, out_dir, progress: Optional[Callable[[bake_mod.Progress], None]] = None, cancel=None,
                moving: Iterable[str] = (), static: Iterable[str] = (),
                log: Callable[[str], None] = lambda message: None, force: bool = False, cluster=None) -> FramesResult:
    """Bake every frame of `frames` into `out_dir`. `scene_at(frame)` returns the scene at a frame.
    A cancel stops between frames' batches: the finished frames stay, with their report.

    A frame whose inputs (its evaluation's hashes, the lights, the settings, where the movers go
    over the range) are those of the last bake into `out_dir`, and whose files are all there, is
    not baked again but kept as it is (said, and marked in report.json); `force` bakes it anyway;
    `cluster` (a connected distributed.Cluster): every frame's photons are traced there."""
    admission = door.admitted(settings, out_dir=out_dir, frame_state=FrameState())  # checked once (door.py)
    settings, out = admission.settings, admission.out_dir
    report, cancelled = progress or (lambda p: None), bake_mod.cancel_fn(cancel)
    numbers, t_start = frames.frames(), time.perf_counter()
    n = len(numbers)
    if settings.target_noise or settings.time_limit:
        log("frames may stop at different photon counts (--target-noise/--time-limit): static regions then "
            "differ between frames")
    # 1. Evaluate every frame: what moves.
    signatures, lights, kept, export_seconds, boxes = _evaluate(scene_at, numbers, report, cancelled)
    motion = find_motion(signatures, lights, moving, static)
    log(motion.describe())
    evaluate_seconds = time.perf_counter() - t_start
    # 2. Bake frame after frame.
    # Shadows follow what really moves, whatever --static says: found and forced moving alike.
    shadowing = [n for n in motion.objects if n in motion.found or n in motion.moving]
    moving_boxes = [b[name] for b in boxes for name in shadowing if name in b]
    state = FrameState(moving=frozenset(motion.moving), lights_change=motion.lights_change,
                       moving_boxes=np.array(moving_boxes, np.float64).reshape(-1, 2, 3))
    result = FramesResult([], {}, motion, False, out / "report.json")
    previous, settings_report = ({}, None) if force else _previous(result.report_path)
    # What a frame's numbers depend on beyond its own scene: where the movers go over the range
    # (the hybrid's split, frame_direct's re-sampled texels) and whether the lights change.
    range_key = _digest([state.moving_boxes, np.frombuffer(" ".join(sorted(state.moving)).encode(), np.uint8),
                         np.array([state.lights_change])])
    settings_key = json.dumps(asdict(settings), sort_keys=True, default=list)
    skipped = []
    try:
        for k, frame in enumerate(numbers):
            label = _frame_label(k, n, frame)
            inputs = _digest([np.frombuffer(f"{__version__}|{settings_key}|{range_key}|{lights[k]}|".encode() +
                                            json.dumps(sorted(signatures[k].items())).encode(), np.uint8)])
            if _unchanged(previous.get(frame), inputs):
                report(bake_mod.Progress("write", 1.0, f"{label} · unchanged since the last bake: kept", part=(k, n)))
                old = previous[frame]
                _add(result, frame, {**old, "kept": True}, {o["name"]: o["files"] for o in old["objects"]})
                skipped.append(frame)
                _write_report(result, frames, settings_report, evaluate_seconds, time.perf_counter() - t_start)
                continue

            def framed(p, label=label, k=k):
                report(bake_mod.Progress(p.phase, p.fraction, f"{label} · {p.message}", part=(k, n)))

            t0 = time.perf_counter()
            scene = kept.pop(frame, None)
            if scene is None:
                scene = scene_at(frame)
                export_seconds[frame] += time.perf_counter() - t0
            baked = bake_mod.compute(scene, admission, framed, cancel, cluster, frame_state=state)
            baked.seconds["export"] = export_seconds[frame]
            baked.export = dict(getattr(scene, "export_stats", None) or {})
            bake_mod.write(baked, out, framed, cancel, frame=frame)
            section = baked.report()
            section.pop("version")
            settings_report = section.pop("settings")
            _add(result, frame, {"frame": frame, "inputs": inputs, "kept": False, **section}, baked.files)
            _write_report(result, frames, settings_report, evaluate_seconds, time.perf_counter() - t_start)
            report(bake_mod.Progress("write", 1.0, f"{label} · written", part=(k, n)))
            del baked, scene
    except BakeCancelled:
        result.cancelled = True
        if result.frames:
            _write_report(result, frames, settings_report, evaluate_seconds, time.perf_counter() - t_start)
    if skipped:
        log(f"kept {len(skipped)} unchanged frame{'s' if len(skipped) > 1 else ''} from the last bake "
            f"({_ranges(skipped)}); --force bakes them again")
    result.skipped = skipped
    return result


def _unchanged(old: Optional[dict], inputs: str) -> bool:
    """Whether a frame's earlier report section has these inputs and all its files (lightmaps, and
    its probes when it had some) are still there."""
    return old is not None and old.get("inputs") == inputs and all(
        os.path.isfile(f) for o in old["objects"] for f in o["files"]) and \
        os.path.isfile(old.get("probes", {}).get("file", __file__))


def _evaluate(scene_at, numbers, report, cancelled):
    """Every frame evaluated once: (its objects' signatures, its lights' signature, the scenes kept
    for the bake (up to SCENE_CACHE_BYTES), the seconds each export took, its objects' boxes)."""
    signatures, lights, kept, export_seconds, boxes = [], [], {}, {}, []
    held, n = 0, len(numbers)
    for k, frame in enumerate(numbers):
        if cancelled():
            raise BakeCancelled()
        report(bake_mod.Progress("evaluate", k / n, f"{_frame_label(k, n, frame)} · Evaluating"))
        t0 = time.perf_counter()
        scene = scene_at(frame)
        export_seconds[frame] = time.perf_counter() - t0
        signatures.append(object_signatures(scene))
        boxes.append(object_boxes(scene))
        lights.append(lights_signature(scene) + f":{scene.default_bounces}")
        size = scene.positions.nbytes * 3
        if held + size <= SCENE_CACHE_BYTES:
            kept[frame] = scene
            held += size
    return signatures, lights, kept, export_seconds, boxes


def _add(result: "FramesResult", frame: int, section: dict, files: dict) -> None:
    result.sections.append(section)
    result.frames.append(frame)
    result.files[frame] = files


def _previous(path: Path) -> tuple[dict, Optional[dict]]:
    """The frame sections of the report.json of an earlier bake into the same folder (and its
    settings), when this version of detp_bake wrote it."""
    try:
        doc = json.loads(path.read_text())
        if doc.get("version") != __version__:
            return {}, None
        return {int(s["frame"]): s for s in doc["per_frame"] if "inputs" in s}, doc["settings"]
    except (OSError, ValueError, KeyError, TypeError):
        return {}, None


def _ranges(numbers: list[int]) -> str:
    parts, start = [], None
    for i, f in enumerate(numbers):
        if start is None:
            start = f
        if i + 1 == len(numbers) or numbers[i + 1] != f + 1:
            parts.append(str(start) if start == f else f"{start}-{f}")
            start = None
    return ", ".join(parts)


def _write_report(result: FramesResult, frames: FrameRange, settings: dict, evaluate_seconds: float,
                  total_seconds: float) -> None:
    """report.json for the frames finished so far, replaced whole (never half-written)."""
    estimator = settings["estimator"]
    stems = {}
    for files in result.files.values():
        for name, paths in files.items():
            stems.setdefault(name, [re.sub(r"\.\d+(\.\w+)$", r".####\1", os.path.basename(p)) for p in paths])
    doc = {"version": __version__, "settings": settings,
           "frames": {"range": str(frames), "requested": frames.frames(), "done": list(result.frames),
                      "kept": [s["frame"] for s in result.sections if s.get("kept")],
                      "cancelled": result.cancelled, "sequences": stems, **result.motion.report()},
           "estimator": estimator,
           "seconds": {"evaluate": evaluate_seconds, "total": total_seconds},
           "per_frame": result.sections}
    tmp = staging.temporary(result.report_path)
    tmp.write_text(json.dumps(doc, indent=2, allow_nan=False))
    os.replace(tmp, result.report_path)
