"""Batches of photons traced into the estimators and summed in batch order, here or on a cluster's
workers (distributed.py): a run of batches gives a Partial, a bake's Totals add them in order, so
the lightmaps are the same bit for bit whoever traced them; TraceJob is what a worker needs."""
from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from .. import estimators
from ..lightmap import texels as texels_mod
from ..scene import Scene
from ..transport.photons import PhotonBatch, PhotonTracer, TraceStats
from . import memory
from .settings import BakeSettings


BLOCKS = 32  # the most blocks of batches a bake is traced in (blocks)


@dataclass
class Partial:
    """What a run of consecutive batches adds to a bake, summed from zero: tracing counts and flux,
    and per estimator its `take()` sums and the seconds it spent. Plain data (`plain`), so it
    crosses to a client that imports this package under another name (Blender's bl_ext)."""
    first: int  # first batch number
    batches: int  # batches traced
    stats: TraceStats
    sums: dict  # estimator name -> Estimator.take()
    seconds: dict  # estimator name -> seconds in add and take
    stopped: bool = False  # `stop` said to stop the bake after this run (time limit)

    def plain(self) -> dict:
        return {**vars(self), "stats": vars(self.stats)}

    @classmethod
    def from_plain(cls, d: dict) -> "Partial":
        return cls(**{**d, "stats": TraceStats(**d["stats"])})


class Totals:
    """A bake's sums, partials added in batch order: the same additions in the same order whoever
    traced the batches, so the lightmaps are identical bit for bit."""

    def __init__(self, names):
        self.stats = TraceStats()
        self.sums = {name: {} for name in names}
        self.seconds = dict.fromkeys(names, 0.0)
        self.batches = 0

    def add(self, part: Partial) -> None:
        if part.first != self.batches:
            raise ValueError(f"batch {part.first} added after {self.batches} batches")
        self.stats.add(part.stats)
        for name, sums in part.sums.items():
            total = self.sums[name]
            for key, value in sums.items():
                if key in total:
                    total[key] += value
                elif isinstance(value, np.ndarray) and value.flags.writeable and value.flags.owndata:
                    total[key] = value  # an estimator's take() let it go: adopted, not copied
                else:  # a copy: what came over the wire may be read-only
                    total[key] = value.copy() if isinstance(value, (np.ndarray, list)) else value
            self.seconds[name] += part.seconds[name]
        self.batches += part.batches


def trace_batches(tracer: PhotonTracer, runs: dict, indices: range, cancel=None,
                  stop: Optional[Callable[[float], bool]] = None,
                  on_batch: Optional[Callable[[PhotonBatch], None]] = None) -> Partial:
    """Trace batches `indices` (consecutive batch numbers) into every estimator of `runs` and hand
    over their sums. The local bake and a cluster's workers (distributed.py) both bake through this,
    a block of batches at a time (`blocks`). `stop(seconds the batch took)` ends the run early."""
    tracer.stats = TraceStats()
    seconds = dict.fromkeys(runs, 0.0)
    done, stopped = 0, False
    with contextlib.closing(tracer.batches(cancel, indices)) as batches:
        t0 = time.perf_counter()
        for batch in batches:
            for name, est in runs.items():
                t1 = time.perf_counter()
                est.add(batch)
                seconds[name] += time.perf_counter() - t1
            done += 1
            if on_batch is not None:
                on_batch(batch)
            if stop is not None and stop(time.perf_counter() - t0):
                stopped = True
                break
            t0 = time.perf_counter()
    sums = {}
    for name, est in runs.items():
        t1 = time.perf_counter()
        sums[name] = est.take()
        seconds[name] += time.perf_counter() - t1
    return Partial(indices[0], done, tracer.stats, sums, seconds, stopped)


def blocks(tracer: PhotonTracer, runs: dict, expected_segments: int) -> list[range]:
    """The bake's batches in blocks, each estimated from zero and read for noise once done: as
    many segments as a streaming estimator gathers before it works through them, and at most a
    sixteenth of the bake, but no fewer than a BLOCKS-th of it (reading the noise of a million
    texels costs about 0.07 s a block on 2 cores: a block per batch took 12 s of a 1024² bake of
    168 batches). Fixed by the settings and the scene alone, so a cluster sums exactly what a local
    bake sums."""
    count = tracer.batch_count
    gather = max((est.group_segments for est in runs.values() if est.streaming), default=0)
    per_batch = max(expected_segments / count, 1.0)
    size = max(1, int(max(min(gather, expected_segments // 16), expected_segments // BLOCKS) / per_batch))
    return [range(a, min(a + size, count)) for a in range(0, count, size)]


def worker_bytes(need: memory.Estimate, texels, runs, blocks) -> tuple[int, int]:
    """(bytes a worker keeps for a bake, bytes one block's sums add), for sizing a cluster's units."""
    fixed = need.total - need.parts.get("photon map hits", 0) - need.parts["lightmap images"] \
        - need.parts.get("denoiser", 0)
    per_block = sum(len(texels) * 3 * 8 for est in runs.values() if est.streaming)
    if blocks and any(est.stores_hits for est in runs.values()):
        per_block += need.parts.get("photon map hits", 0) // len(blocks)
    return int(fixed), int(per_block)


@dataclass
class TraceJob:
    """A bake's tracing and estimation inputs, plain data: what a cluster's worker needs to trace
    any of the bake's batches exactly as the local bake would (distributed.py)."""
    scene: Scene
    texels: texels_mod.TexelSet
    settings: BakeSettings
    names: list
    bounces: int
    batch_size: int
    margin: float  # how far past the geometry sun photons start (the discs' reach)
    context: estimators.Context

    def tracer(self, threads: int = 0) -> PhotonTracer:
        s = self.settings
        return PhotonTracer(self.scene, s.photons, self.bounces, s.seed, self.batch_size, threads or s.threads,
                            indirect_only=s.direct == "sampled", margin=self.margin,
                            segments=estimators.read_segments(self.names))

    def estimators(self) -> dict:
        return {name: estimators.create(name, self.texels, self.settings.estimator_settings, None, self.context)
                for name in self.names}
