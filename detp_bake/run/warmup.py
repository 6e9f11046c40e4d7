"""A warm first click: every kernel a bake runs, compiled (or loaded from numba's on-disk cache)
before the user asks for a bake, by baking a tiny scene nobody sees.

Numba compiles a kernel on its first call, per argument types: the first bake of a Blender
session used to wait about 22 s on two cores for disc_index, sphere_cache, the tracer and the
emitters. The extension points NUMBA_CACHE_DIR at its user folder (the root __init__.py), so a
later session only loads the compiled code; this module does even that in a background thread
when the extension is enabled, holding the job lock (job.py) so that no bake shares numba's
thread pool with it. A bake started meanwhile waits for it, saying so.
"""
from __future__ import annotations

import threading
import time
from typing import Optional

import numpy as np

from .. import estimators, options
from ..lightmap import dilation
from ..errors import BakeCancelled
from ..scene import AreaLight, BakeObject, PointLight, Scene, SpotLight, SunLight
from . import bake, job

_thread: Optional[threading.Thread] = None
_cancel = threading.Event()
seconds: Optional[float] = None  # how long the last warm-up took


def _placed(scale: float, at) -> np.ndarray:
    m = np.diag([scale, scale, scale, 1.0])
    m[:3, 3] = at
    return m


def _box() -> Scene:
    """A closed unit box seen from inside (12 triangles, each face a cell of a 3 × 2 UV atlas),
    lit by one light of every kind, an emissive triangle and a sky. The same kernels emit the
    point, spot, area and mesh photons (lights._emit): a new light type adds no emitter compile.
    The sun on its footprint and the sky have kernels of their own."""
    faces = []  # (corner order) per face, inward
    c = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
    for quad in ((0, 1, 2, 3), (4, 7, 6, 5), (0, 4, 5, 1), (1, 5, 6, 2), (2, 6, 7, 3), (3, 7, 4, 0)):
        faces.append(c[list(quad)])
    pos, nrm, uvs = [], [], []
    for i, q in enumerate(faces):
        n = np.cross(q[1] - q[0], q[2] - q[0])
        n /= np.linalg.norm(n)
        u0, v0 = (i % 3) / 3.0, (i // 3) / 2.0
        cell = np.array([[0.05, 0.05], [0.95, 0.05], [0.95, 0.95], [0.05, 0.95]]) * [1 / 3.0, 0.5] + [u0, v0]
        for a, b, d in ((0, 1, 2), (0, 2, 3)):
            pos.append(q[[a, b, d]])
            nrm.append(np.tile(n, (3, 1)))
            uvs.append(cell[[a, b, d]])
    t = len(pos)
    emission = np.zeros((t, 3))
    emission[2] = 1.0
    lights = [PointLight("point", np.array([0.5, 0.5, 0.8]), np.full(3, 10.0)),
              SpotLight("spot", np.array([0.5, 0.5, 0.9]), np.array([0.0, 0.0, -1.0]), np.full(3, 10.0), 1.0, 0.1),
              SunLight("sun", np.array([0.0, 0.0, -1.0]), np.full(3, 1.0), 0.01),
              AreaLight("area", _placed(0.2, (0.5, 0.5, 0.95)), "SQUARE", 1.0, 1.0, np.full(3, 10.0))]
    return Scene(positions=np.array(pos), normals=np.array(nrm), uvs=np.array(uvs), albedo=np.full((t, 3), 0.5),
                 emission=emission, objects=[BakeObject("box", 0, t, 8, True)], lights=lights,
                 world=np.full(3, 0.1), default_bounces=2)


def warm_up(threads: int = 0, cancel=None) -> float:
    """Bake the tiny box with every estimator, both ways of finding direct light; returns seconds.
    The caller holds the job lock (or knows nothing else runs numba)."""
    t0 = time.perf_counter()
    for direct in options.DIRECT_MODES:
        settings = bake.BakeSettings(photons=4000, resolution=8, direct=direct, direct_samples=2, denoise=False,
                                     threads=threads, batch_size=1000, probe_spacing=0.5, probe_rays=16,
                                     probes="auto" if direct == "sampled" else "off")  # the probes' kernels too
        bake.compute_many(_box(), settings, estimators.names(), cancel=cancel)
    # Kernels only big lightmaps run (the tiny box's images are too small for them).
    dilation.dilate(np.zeros((dilation.WIDE_SIDE, dilation.WIDE_SIDE, 3), np.float32),
                    np.eye(dilation.WIDE_SIDE, dtype=bool), 1)
    return time.perf_counter() - t0


def start(threads: int = 0) -> Optional[threading.Thread]:
    """Warm up on a daemon thread unless a job (or a warm-up) runs; returns the thread or None."""
    global _thread
    holder = job.hold("warm-up")
    if holder is None:
        return None
    _cancel.clear()

    def work():
        global seconds
        try:
            seconds = warm_up(threads, _cancel)
        except BakeCancelled:
            pass
        except Exception:  # a warm-up that fails costs the first bake its compile time, nothing more
            import traceback
            traceback.print_exc()
        finally:
            job.release(holder)

    _thread = threading.Thread(target=work, name="detp_bake warm-up", daemon=True)
    _thread.start()
    return _thread


def running() -> bool:
    return _thread is not None and _thread.is_alive()


def wait(timeout: Optional[float] = None) -> None:
    if _thread is not None:
        _thread.join(timeout)


def stop() -> None:
    """End the warm-up at its next cancel point (the kernel compiling now still finishes)."""
    _cancel.set()
