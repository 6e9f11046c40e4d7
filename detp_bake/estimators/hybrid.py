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
sums of `detp` over that frame's discs. Only the segments that enter boxes around those texels'
discs go to the sphere cache, in their order, so its sums are unchanged and it does not scan the
whole frame's segments for a small object. Without a frame state (a single bake) every object
counts as static, and the hybrid is the disc index.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numba
import numpy as np

from .base import Context, Estimate, Estimator, EstimatorSettings, register
from .disc_index import DiscIndex
from .discs import Discs, make_discs
from ..morton import morton_order
from .sphere_cache import STREAM_SEGMENTS, SphereCache
from ..errors import BakeError
from ..lightmap.texels import of_objects, select

MOVING = {"sphere_cache": SphereCache, "disc_index": DiscIndex}
BOX_DISCS = 4096  # discs per box of the segment filter, at most


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


@numba.njit(cache=True, parallel=True)
def _enter_boxes(o, w, length, eps, lo, hi, keep):
    """keep[i]: segment i, for t in [0, length + eps], enters one of the boxes (lo, hi); box 0
    holds all the others (a segment that misses it is done after one test)."""
    for i in numba.prange(o.shape[0]):
        keep[i] = False
        tmax = np.float64(length[i]) + eps
        for b in range(lo.shape[0]):
            tn, tf = 0.0, tmax
            for c in range(3):
                oc, wc = np.float64(o[i, c]), np.float64(w[i, c])
                if wc == 0.0:
                    if oc < lo[b, c] or oc > hi[b, c]:
                        tn, tf = 1.0, 0.0
                    continue
                t0, t1 = (lo[b, c] - oc) / wc, (hi[b, c] - oc) / wc
                tn, tf = max(tn, min(t0, t1)), min(tf, max(t0, t1))
            if tn > tf:
                if b == 0:
                    break
                continue
            if b > 0:
                keep[i] = True
                break


def _boxes(discs: Discs) -> tuple[np.ndarray, np.ndarray]:
    """Boxes around runs of the discs' cylinders in Morton order (tight round a mover and round the
    few static texels near it, wherever they lie), after one box round them all; padded against
    rounding."""
    lo, hi = discs.bounds()
    order = morton_order(discs.centre)
    # A box also ends where the Z-curve jumps (more than a few discs' widths between neighbours),
    # so no box spans the room between two far-apart groups of texels.
    step = np.linalg.norm(np.diff(discs.centre[order], axis=0), axis=1)
    jumps = np.flatnonzero(step > 4.0 * float(discs.radius.max())) + 1
    starts = np.union1d(np.arange(0, len(order), BOX_DISCS), jumps)
    a = np.concatenate([lo.min(axis=0)[None], np.minimum.reduceat(lo[order], starts, axis=0)])
    b = np.concatenate([hi.max(axis=0)[None], np.maximum.reduceat(hi[order], starts, axis=0)])
    pad = 1e-6 * max(float(np.abs(np.r_[a, b]).max()), 1.0) + discs.eps
    return a - pad, b + pad


@register
class Hybrid(Estimator):
    name = "hybrid"
    streaming = True
    discs = True
    directional = True
    compared = False  # one frame: disc_index's numbers at more cost
    group_segments = STREAM_SEGMENTS
    # The disc index's, and a copy of the static texels (texels.select) it is built over: measured,
    # benchmarks/memory.py
    bytes_per_texel = 290

    def __init__(self, texels, settings, progress=None, context=None):
        super().__init__(texels, settings, progress, context)
        if settings.hybrid_moving not in MOVING:
            raise BakeError(f"setting 'hybrid_moving' = {settings.hybrid_moving!r}: choose {' or '.join(MOVING)}")
        t0 = time.perf_counter()
        state = self.context.frames
        moving = state.moving if state is not None else frozenset()
        static = ~of_objects(texels, moving, self.context.scene)
        clearance, rise, extent = self.context.clearance, self.context.rise, self.context.extent
        scene_radius, expected = self.context.scene_radius, self.context.expected_segments
        self.l1 = self.context.directional

        def context(mask):  # the bake's context for the texels of `mask`
            return Context(scene_radius, expected, None if clearance is None else clearance[mask],
                           None if rise is None else rise[mask], None if extent is None else extent[mask],
                           directional=self.l1)

        static_texels = select(texels, static)
        sub = context(static)
        discs = make_discs(static_texels, settings, scene_radius, sub.clearance, sub.rise, sub.extent)
        kept = state.keep.get(self.name) if state is not None else None
        self.reused = kept is not None and kept.serves(static, texels.pixel[static], discs, settings)
        if self.reused:
            kept.index.reset()
            kept.index.progress = self.progress
            changed = kept.changed(discs)
        else:
            index = DiscIndex(static_texels, settings, progress, sub)
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
        self.kept_segments = 0
        self.segments = 0
        if self.cache_rows.size:
            cached_texels = select(texels, cached)
            sub = context(cached)
            self.cache = MOVING[settings.hybrid_moving](cached_texels, settings, progress, sub)
            cached_discs = make_discs(cached_texels, settings, scene_radius, sub.clearance, sub.rise, sub.extent)
            self.box_lo, self.box_hi = _boxes(cached_discs)
            self.eps = cached_discs.eps
        self.seconds_build = time.perf_counter() - t0

    def add(self, batch):
        self.segments += batch.segment_count
        if len(self.static_rows):
            self.index.add(batch)
        if self.cache is not None and batch.segment_count:
            keep = np.empty(batch.segment_count, np.bool_)
            _enter_boxes(batch.seg_origin, batch.seg_dir, batch.seg_length, self.eps, self.box_lo, self.box_hi, keep)
            near = replace(batch, seg_origin=batch.seg_origin[keep], seg_dir=batch.seg_dir[keep],
                           seg_length=batch.seg_length[keep], seg_flux=batch.seg_flux[keep])
            self.kept_segments += near.segment_count
            self.cache.add(near)

    def _parts(self):
        """(label, rows, estimator) of the static and the moving part, in that order: rows of a
        static texel rerouted this frame are in both, and the moving part's value is the one kept."""
        if len(self.static_rows):
            yield "static", self.static_rows, self.index
        if self.cache is not None:
            yield "moving", self.cache_rows, self.cache

    def take(self):
        irradiance = np.zeros((len(self.texels), 3))
        l1 = np.zeros((len(self.texels), 9)) if self.l1 else None
        sums = {"segments": self.segments, "near": self.kept_segments}
        self.segments = self.kept_segments = 0
        for label, rows, est in self._parts():
            part = est.take()
            irradiance[rows] = part.pop("irradiance")
            if l1 is not None:
                l1[rows] = part.pop("l1")
            sums.update({f"{label}/{k}": v for k, v in part.items()})
        sums["irradiance"] = irradiance
        if l1 is not None:
            sums["l1"] = l1
        return sums

    def absorb(self, sums):
        self.segments += sums["segments"]
        self.kept_segments += sums["near"]
        for label, rows, est in self._parts():
            part = {k.split("/", 1)[1]: v for k, v in sums.items() if k.startswith(label + "/")}
            est.absorb({**part, "irradiance": sums["irradiance"][rows],
                        **({"l1": sums["l1"][rows]} if self.l1 else {})})

    def finish(self):
        out = np.zeros((len(self.texels), 3))
        l1 = np.zeros((len(self.texels), 9)) if self.l1 else None
        counters = {"static_texels": int(len(self.static_rows)), "moving_texels": int(len(self.cache_rows)) -
                    self.rerouted, "rerouted_texels": self.rerouted, "index_reused": bool(self.reused),
                    "seconds_build": self.seconds_build, "crossings": 0, "segments": self.segments,
                    "moving_segments_near": self.kept_segments,
                    "moving_boxes": 0 if self.cache is None else len(self.box_lo) - 1}
        for label, rows, est in self._parts():
            got = est.finish()
            out[rows] = got.irradiance
            if l1 is not None:
                l1[rows] = got.l1
            # Crossings of rerouted texels' indexed discs are counted too (they are not used).
            counters["crossings"] += got.counters.get("crossings", 0)
            counters.update({f"{label}_{k}": v for k, v in got.counters.items()})
        return Estimate(out, counters, l1)
