"""The hybrid estimator for quasi-static scenes (García et al. 2005, the slides' last result).

A frame range of a scene where most objects stand still and a few small ones move: the static
objects' discs do not change from frame to frame, so they are indexed once (disc_index) and every
frame's segments, traced through that frame's geometry, are splatted through the same index; the
moving objects' texels, few, are estimated with the sphere cache over the same frame's segments
(or, with `hybrid_moving` = disc_index, through a small index of their own built every frame).

The index lives in the range's `FrameState` (frames.py) and is reused while the static discs stay
what they were: a static texel whose disc is cut differently this frame (a mover came within its
clearance, texels.tangent_clearance) is estimated by the sphere cache for that frame instead, and a
change of the discs' ε or of the settings builds the index again. So every frame gives exactly the
sums of `detp` over that frame's discs. Without a frame state (a single bake) every object counts as
static, and the hybrid is the disc index.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from . import Context, Estimate, Estimator, EstimatorSettings, register
from .disc_index import DiscIndex
from .discs import Discs, make_discs
from .sphere_cache import STREAM_SEGMENTS, SphereCache
from ..errors import BakeError
from ..texels import select

MOVING = {"sphere_cache": SphereCache, "disc_index": DiscIndex}


@dataclass
class _Kept:
    """The index over the static discs, and what it was built from."""
    index: DiscIndex
    static: np.ndarray  # bool per texel of the whole set
    pixel: np.ndarray  # the static texels' pixels
    discs: Discs
    settings: EstimatorSettings

    def serves(self, static, pixel, discs, settings) -> bool:
        return (self.settings == settings and np.array_equal(self.static, static)
                and np.array_equal(self.pixel, pixel) and self.discs.eps == discs.eps
                and self.discs.kernel == discs.kernel)

    def changed(self, discs: Discs) -> np.ndarray:
        """Per static texel: its disc this frame is not the one indexed."""
        d = self.discs
        return ((d.centre != discs.centre).any(axis=1) | (d.normal != discs.normal).any(axis=1)
                | (d.radius != discs.radius) | (d.slab != discs.slab))


@register
class Hybrid(Estimator):
    name = "hybrid"
    streaming = True
    group_segments = STREAM_SEGMENTS
    bytes_per_texel = max(DiscIndex.bytes_per_texel, SphereCache.bytes_per_texel)

    def __init__(self, texels, settings, progress=None, context=None):
        super().__init__(texels, settings, progress, context)
        if settings.hybrid_moving not in MOVING:
            raise BakeError(f"setting 'hybrid_moving' = {settings.hybrid_moving!r}: choose {' or '.join(MOVING)}")
        t0 = time.perf_counter()
        state = self.context.frames
        moving = state.moving if state is not None else frozenset()
        static = np.zeros(len(texels), bool)
        for lm in texels.lightmaps:
            static[lm.texels] = lm.name not in moving
        clearance = self.context.clearance
        part = lambda mask: None if clearance is None else clearance[mask]
        scene_radius = self.context.scene_radius
        static_texels = select(texels, static)
        discs = make_discs(static_texels, settings, scene_radius, part(static))
        kept = state.keep.get(self.name) if state is not None else None
        self.reused = kept is not None and kept.serves(static, texels.pixel[static], discs, settings)
        if self.reused:
            kept.index.reset()
            kept.index.progress = self.progress
            changed = kept.changed(discs)
        else:
            index = DiscIndex(static_texels, settings, progress,
                              Context(scene_radius, self.context.expected_segments, part(static)))
            kept = _Kept(index, static.copy(), texels.pixel[static].copy(), discs, settings)
            if state is not None:
                state.keep[self.name] = kept
            changed = np.zeros(int(static.sum()), bool)
        self.index = kept.index
        self.static_rows = np.flatnonzero(static)
        cached = ~static
        cached[self.static_rows[changed]] = True
        self.cache_rows = np.flatnonzero(cached)
        self.rerouted = int(changed.sum())
        self.cache = None
        if self.cache_rows.size:
            self.cache = MOVING[settings.hybrid_moving](select(texels, cached), settings, progress,
                                                        Context(scene_radius, self.context.expected_segments,
                                                                part(cached)))
        self.seconds_build = time.perf_counter() - t0

    def add(self, batch):
        if len(self.static_rows):
            self.index.add(batch)
        if self.cache is not None:
            self.cache.add(batch)

    def finish(self):
        out = np.zeros((len(self.texels), 3))
        counters = {"static_texels": int(len(self.static_rows)), "moving_texels": int(len(self.cache_rows)) -
                    self.rerouted, "rerouted_texels": self.rerouted, "index_reused": bool(self.reused),
                    "seconds_build": self.seconds_build, "crossings": 0, "segments": 0}
        parts = [("static", self.static_rows, self.index if len(self.static_rows) else None),
                 ("moving", self.cache_rows, self.cache)]
        for label, rows, est in parts:
            if est is None:
                continue
            got = est.finish()
            out[rows] = got.irradiance
            counters["segments"] = max(counters["segments"], got.counters.get("segments", 0))
            # Crossings of rerouted texels' indexed discs are counted too (they are not used).
            counters["crossings"] += got.counters.get("crossings", 0)
            counters.update({f"{label}_{k}": v for k, v in got.counters.items()})
        return Estimate(out, counters)
