"""What the command line says, and where: stdout holds only the files a run wrote (one path a line,
or one JSON summary with `--json`), so that scripts can read it; progress, notes and warnings go to
stderr. Blender prints from C to the process's stdout ("Read blend: …", Lightmap Pack's chatter),
so around Blender calls file descriptor 1 itself is pointed at stderr (or discarded).
"""
from __future__ import annotations

import json
import os
import sys
from contextlib import contextmanager, redirect_stdout
from pathlib import Path


def _flush_c_stdio() -> None:
    """Push out what C code left in its stdout buffer, before descriptor 1 changes again."""
    try:
        import ctypes
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError, TypeError):
        pass  # no C library to reach (Windows): Blender flushes its own lines there


@contextmanager
def quiet_stdout(to: str = "stderr"):
    """Within the block, everything written to stdout, from Python or from C, goes to stderr
    (`to="stderr"`) or nowhere (`to="null"`)."""
    sys.stdout.flush()
    _flush_c_stdio()
    saved = os.dup(1)
    target = os.open(os.devnull, os.O_WRONLY) if to == "null" else os.dup(2)
    python_out = open(os.devnull, "w") if to == "null" else sys.stderr
    try:
        os.dup2(target, 1)
        with redirect_stdout(python_out):  # Python's prints too, wherever sys.stdout points
            yield
    finally:
        sys.stdout.flush()
        _flush_c_stdio()
        os.dup2(saved, 1)
        os.close(target)
        os.close(saved)
        if to == "null":
            python_out.close()


def log(msg: str) -> None:
    print(f"detp_bake: {msg}", file=sys.stderr, flush=True)


class Warnings(list):
    """Warnings said on stderr as they come, and kept for report.json and `--json`."""

    def __call__(self, msg: str) -> None:
        self.append(msg)
        log(f"warning: {msg}")


def percent(fraction: float) -> str:
    """A fraction as per cent in plain digits: 0.031 → '3.1', 2.5 → '250' (never '2.5e+02')."""
    p = 100.0 * fraction
    return f"{p:.0f}" if abs(p) >= 10.0 else f"{p:.2g}"


def noise_line(noise: dict, unmeasured: str, fixed: bool = False) -> str:
    """The bake's noise in one line: the worst lightmaps first, what the figure is relative to and
    what lowers it; or why it was not measured ('' when there is nothing to say)."""
    if unmeasured:
        return f"noise not measured: {unmeasured}"
    if not noise:
        return ""
    worst = sorted(noise.items(), key=lambda kv: -kv[1])
    listed = ", ".join(f"{name} {percent(v)} %" for name, v in worst[:8]) + \
        (f" (+{len(worst) - 8} more in report.json)" if len(worst) > 8 else "")
    if fixed:
        return f"noise: {listed} of each texel's value (the photon map's is fixed by --k: a larger k lowers it)"
    return (f"noise: {listed} of the scene's mean irradiance (RMS over each lightmap's texels); more photons "
            "(--photons) or a noise target (--target-noise PERCENT) lower it")


def written(summary: dict, as_json: bool = False) -> None:
    """The run's result on stdout: every file written, one a line, or the summary as JSON."""
    if as_json:
        print(json.dumps(summary, indent=2, default=str, allow_nan=False), flush=True)
        return
    for path in _paths(summary.get("files", {})):
        print(path)
    for path in summary.get("extra", []):
        print(path)
    print(summary["report"])
    if summary.get("saved"):
        print(summary["saved"])
    sys.stdout.flush()


def _paths(files):
    """The paths in {object: [paths]}, or {estimator: {object: [paths]}}, in order."""
    for value in files.values():
        if isinstance(value, dict):
            yield from _paths(value)
        else:
            yield from value



def exit_hangs() -> bool:
    """Whether this process would hang in Blender's own exit handlers: the bpy 4.5 module, once
    a bake's compiled kernels have run threads and Blender's glTF exporter has been loaded, waits
    forever in a static destructor (its sound state's delayed-close thread is never woken; seen
    with gdb, not with bpy 5.2). The callers leave with os._exit once everything is written."""
    bpy = sys.modules.get("bpy")
    return bpy is not None and tuple(bpy.app.version) < (5, 0, 0) and \
        any(name.startswith("io_scene_gltf2.blender.exp") for name in sys.modules)


def leave(code) -> None:
    """Exit with `code` (None: 0), past Blender's exit handlers where they would hang."""
    code = 0 if code is None else code
    if exit_hangs() and isinstance(code, int):
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)
