"""Helpers for tests/test_battery.py: scenes built with bpy and saved, the real command line run
as a subprocess, folder snapshots, and a test hook the bake's own interpreter loads to stop in a
chosen phase (the product has no hook of its own for it)."""
import hashlib
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from conftest import ROOT

# Loaded by the bake's interpreter (site imports `sitecustomize` from PYTHONPATH). DETP_TEST_HOLD
# names a phase: on entering it the bake says "detp_bake: test: holding in PHASE" on stderr and
# sleeps, so the test can kill it there. DETP_TEST_COMMIT_GO: before its first rename into the
# folder the bake says "holding before commit" and waits for that file to exist, then waits
# DETP_TEST_COMMIT_AFTER seconds more; DETP_TEST_RENAME_DELAY seconds after each rename;
# DETP_TEST_COPY: a copy of every file it renames into the folder goes to COPY/<pid>/<name>.
HOOK = r'''
import os, shutil, sys, time

_env = os.environ.get


def _say(what):
    print(f"detp_bake: test: {what}", file=sys.stderr, flush=True)


def _hold(phase):
    _say(f"holding in {phase}")
    time.sleep(3600)


def _patch():
    phase = _env("DETP_TEST_HOLD", "")
    from detp_bake.lightmap import denoise, staging, texels
    from detp_bake.run import bake
    if phase == "rasterise":
        rasterise = texels.rasterise
        texels.rasterise = lambda *a, **k: (_hold(phase), rasterise(*a, **k))[1]
    if phase == "trace":
        trace = bake.trace_batches

        def traced(*a, **k):  # a run of batches traced, then held before it is summed
            part = trace(*a, **k)
            _hold(phase)
            return part
        bake.trace_batches = traced
    if phase == "denoise":
        one = denoise.denoise_lightmap
        denoise.denoise_lightmap = lambda *a, **k: (_hold(phase), one(*a, **k))[1]
    if phase == "write":
        stage = staging.FileSet.stage

        def staged(self, *a, **k):
            out = stage(self, *a, **k)
            _hold(phase)
            return out
        staging.FileSet.stage = staged
    go, copy, delay = _env("DETP_TEST_COMMIT_GO"), _env("DETP_TEST_COPY"), float(_env("DETP_TEST_RENAME_DELAY", "0"))
    if go:
        commit = staging.FileSet.commit

        def held(self):
            _say("holding before commit")
            while not os.path.exists(go):
                time.sleep(0.02)
            time.sleep(float(_env("DETP_TEST_COMMIT_AFTER", "0")))
            return commit(self)
        staging.FileSet.commit = held
    if copy or delay:
        replace = os.replace

        def renamed(src, dst, *a, **k):
            if ".partial" in str(src) and copy:
                os.makedirs(os.path.join(copy, str(os.getpid())), exist_ok=True)
                shutil.copyfile(src, os.path.join(copy, str(os.getpid()), os.path.basename(dst)))
            out = replace(src, dst, *a, **k)
            if ".partial" in str(src):
                time.sleep(delay)
            return out
        os.replace = renamed

if _env("DETP_TEST_HOLD") or _env("DETP_TEST_COMMIT_GO") or _env("DETP_TEST_COPY"):
    _patch()
'''

BAKE = ["--photons", "20000", "--resolution", "8", "--no-denoise"]


def start(args, cwd, hook=None, **env):
    """`python -m detp_bake ARGS` in its own process; `hook`: a folder for the test hook."""
    path = str(ROOT)
    if hook is not None:
        hook.mkdir(exist_ok=True)
        (hook / "sitecustomize.py").write_text(HOOK)
        path = f"{hook}{os.pathsep}{ROOT}"
    environ = dict(os.environ, PYTHONPATH=path, **env)
    if "NUMBA_CACHE_DIR" in environ:  # the subprocess runs elsewhere: keep the compiled cache
        environ["NUMBA_CACHE_DIR"] = os.path.abspath(environ["NUMBA_CACHE_DIR"])
    return subprocess.Popen([sys.executable, "-m", "detp_bake", *args], cwd=cwd, env=environ,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def run(args, cwd, timeout=300, **env):
    """Run to the end: (exit code, stdout, stderr)."""
    proc = start(args, cwd, **env)
    out, err = proc.communicate(timeout=timeout)
    return proc.returncode, out, err


def run_measured(args, cwd, timeout=300):
    """Run to the end and read that one process's peak resident memory (wait4's rusage, Linux:
    kilobytes): (exit code, stdout, stderr, peak bytes)."""
    import tempfile
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        environ = dict(os.environ, PYTHONPATH=str(ROOT))
        if "NUMBA_CACHE_DIR" in environ:
            environ["NUMBA_CACHE_DIR"] = os.path.abspath(environ["NUMBA_CACHE_DIR"])
        proc = subprocess.Popen([sys.executable, "-m", "detp_bake", *args], cwd=cwd, env=environ,
                                stdout=out, stderr=err)
        end = time.monotonic() + timeout
        while True:
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            if time.monotonic() > end:
                proc.kill()
                raise AssertionError("the bake ran past its time")
            time.sleep(0.1)
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        return proc.returncode, out.read(), err.read(), usage.ru_maxrss * 1024


def wait_for(proc, text, seconds=120.0):
    """Read the process's stderr until a line holds `text`; the lines read so far."""
    lines = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        line = proc.stderr.readline()
        if not line:
            break
        lines.append(line)
        if text in line:
            return lines
    proc.kill()
    raise AssertionError(f"never saw {text!r}: {''.join(lines)}")


def snapshot(folder):
    """Every file in `folder`, hidden ones included: {name: (mtime_ns, sha256)}."""
    folder = Path(folder)
    if not folder.exists():
        return {}
    return {p.name: (p.stat().st_mtime_ns, hashlib.sha256(p.read_bytes()).hexdigest())
            for p in sorted(folder.iterdir()) if p.is_file()}


def room(bpy, path, size=2.0):
    """A floor and a wall with Lightmap UVs, lit by a point light, saved as `path`."""
    from blender_helpers import plane_object
    from detp_bake import blender
    bpy.ops.wm.read_factory_settings(use_empty=True)
    floor = plane_object(bpy, "Floor", size, (0, 0, 0))
    wall = plane_object(bpy, "Wall", size, (0, 1, 1), rotation=(np.pi / 2, 0, 0))
    bpy.ops.object.light_add(type="POINT", location=(0.3, 0, 1.5))
    bpy.context.active_object.data.energy = 100.0
    for obj in (floor, wall):
        blender.ensure_lightmap_uv(obj, blender.DEFAULT_UV)
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


def grid_mesh(bpy, name, nx, ny, size=2.0, uv_name="Lightmap"):
    """A flat nx × ny grid of quads (2·nx·ny triangles) made with foreach_set (no loop per face),
    its `uv_name` layer the grid itself over 0..1."""
    xs, ys = np.meshgrid(np.linspace(-size / 2, size / 2, nx + 1), np.linspace(-size / 2, size / 2, ny + 1))
    co = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], axis=1)
    i = np.arange(ny)[:, None] * (nx + 1) + np.arange(nx)[None, :]
    quads = np.stack([i, i + 1, i + nx + 2, i + nx + 1], axis=-1).reshape(-1, 4)
    return mesh_object(bpy, name, co, quads, uv=(co[:, :2] + size / 2) / size, uv_name=uv_name)


def mesh_object(bpy, name, co, quads, uv=None, uv_name="Lightmap"):
    """A mesh object of quads from arrays; `uv`: per vertex (spread to the corners)."""
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(co))
    mesh.vertices.foreach_set("co", np.asarray(co, np.float32).ravel())
    mesh.loops.add(quads.size)
    mesh.loops.foreach_set("vertex_index", quads.astype(np.int32).ravel())
    mesh.polygons.add(len(quads))
    mesh.polygons.foreach_set("loop_start", np.arange(0, quads.size, 4, dtype=np.int32))
    mesh.polygons.foreach_set("loop_total", np.full(len(quads), 4, np.int32))
    if uv is not None:
        layer = mesh.uv_layers.new(name=uv_name)
        layer.data.foreach_set("uv", np.asarray(uv, np.float32)[quads.ravel()].ravel())
    mesh.update(calc_edges=True)
    mesh.validate(clean_customdata=False)
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj
