"""A bake: scene → texels → photons → estimators → images (the stages: pipeline.py). The front ends
run it through a job (job.py); tests and benchmarks call `compute` and `write` directly.

`compute` does the long work and reports through `progress(Progress)`; it checks `cancel()` between
photon batches and between estimator chunks, so a cancel lands within a batch's time (well under
a second at the default batch size on two cores). `write` puts files in place only once all of them
exist, so an interrupted bake never leaves half a set of lightmaps.
"""
from __future__ import annotations

import os
from typing import Callable, Optional

from .. import estimators
from . import pipeline
from ..scene import Scene
from .batches import Partial, Totals, TraceJob, blocks, trace_batches, worker_bytes  # noqa: F401 (the API)
from .results import BakeResult, Progress, RawImages, Snapshot, cancel_fn, preview_images, si  # noqa: F401 (the API)
from .settings import BakeSettings  # noqa: F401 (the API)
from .writing import warn_stale, write, write_many  # noqa: F401 (the API)
from .door import Admission, admit, auto_photons, with_photons  # noqa: F401 (the API)
from .pipeline import RAYS_PER_SECOND, indirect_spacing  # noqa: F401 (the API)


def compute(scene: Scene, settings: BakeSettings | Admission, progress: Optional[Callable[[Progress], None]] = None,
            cancel=None, cluster=None, frame_state: Optional[estimators.FrameState] = None,
            reach_of=None) -> BakeResult:
    """Trace, estimate and dilate; nothing touches the disk. Raises BakeError or BakeCancelled.
    `settings`: the bake's settings, checked here (door.admit), or an Admission that passed the door.
    `cluster` (a distributed.Cluster) traces the photons on its workers instead of here.
    `frame_state`: one frame of a range (frames.py), shared by the range's frames. `reach_of`:
    objects whose discs also set how far out sun and sky photons start (`disc_reach`), as if they
    were baked too (incremental.py: a bake that reuses their lightmaps)."""
    name = (settings.names[0] if isinstance(settings, Admission) else settings.estimator)
    return compute_many(scene, settings, [name], progress, cancel, cluster, frame_state, reach_of=reach_of)[name]


def compute_many(scene: Scene, settings: BakeSettings | Admission, names=None,
                 progress: Optional[Callable[[Progress], None]] = None, cancel=None, cluster=None, frame_state: Optional[estimators.FrameState] = None, stop=None,
                 preview: Optional[Callable[[Snapshot], None]] = None, reach_of=None) -> dict:
    """Like `compute`, for several estimators fed the very same photons: every batch goes to each
    of them as it is traced. Returns {estimator name: BakeResult}. `settings.threads` (0: all
    cores) holds for tracing, shadow rays and the compiled estimators alike. `stop()` true ends
    tracing after the batch, keeping what there is as a finished bake (stopped_by "user");
    `preview` sees the bake after every block of batches (Snapshot), whatever the estimator. An
    Admission's own estimators are baked (`names` is for plain settings, which are checked here)."""
    import numba
    before = numba.get_num_threads()
    threads = (settings.settings if isinstance(settings, Admission) else settings).threads
    if threads:
        numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))
    try:
        run = pipeline.Pipeline(scene, settings, names, progress, cancel, cluster, frame_state, stop, preview)
        return run.run(reach_of)
    finally:
        numba.set_num_threads(before)


def disc_reach(scene: Scene, settings: BakeSettings, names) -> float:
    """How far beyond the geometry a bake of objects `names` with a disc estimator starts sun and
    sky photons: its widest disc (0 without discs)."""
    if not estimators.get(settings.estimator).discs:
        return 0.0
    settings = pipeline.wide(settings)
    return pipeline.disc_reach_of(scene.recentred()[0], settings.estimator_settings, names, settings.resolution)


def bake(scene: Scene, settings: BakeSettings, out_dir: str | os.PathLike,
         progress: Optional[Callable[[Progress], None]] = None, cancel=None,
         export_seconds: float = 0.0, cluster=None) -> BakeResult:
    """Check the settings and the output folder first (door.admit), then compute and write."""
    result = compute(scene, admit(settings, out_dir=out_dir), progress, cancel, cluster)
    result.seconds["export"] = export_seconds
    write(result, out_dir, progress, cancel)
    return result


