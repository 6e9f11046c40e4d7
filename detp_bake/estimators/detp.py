"""DETP by brute force: every segment against every disc, O(n_R · n_P).

Too slow for production, and that is its job: it is the oracle the sphere cache and the disc
index are tested against, crossing for crossing. It refuses work beyond WORK_LIMIT (segment–disc
tests) before tracing starts, so nobody waits hours by accident.
"""
from __future__ import annotations

import time

import numba
import numpy as np

from ..errors import BakeError
from .base import Estimate, Estimator, register
from .discs import add_l1, crossing_weight, l1_sums, make_discs

WORK_LIMIT = 4e10  # segment–disc tests: about a minute on two cores


@numba.njit(cache=True, parallel=True)
def _splat_all(o, w, length, flux, cen, nrm, rad, slab, eps, kernel, acc, acc_l1, hits):
    for j in numba.prange(cen.shape[0]):
        cx, cy, cz = cen[j, 0], cen[j, 1], cen[j, 2]
        nx, ny, nz = nrm[j, 0], nrm[j, 1], nrm[j, 2]
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        count = 0
        for i in range(o.shape[0]):
            k = crossing_weight(o[i, 0], o[i, 1], o[i, 2], w[i, 0], w[i, 1], w[i, 2], length[i],
                                cx, cy, cz, nx, ny, nz, rad[j], slab[j], eps, kernel)
            if k > 0.0:
                s0 += k * flux[i, 0]
                s1 += k * flux[i, 1]
                s2 += k * flux[i, 2]
                add_l1(acc_l1, j, k, flux, w, i)
                count += 1
        acc[j, 0] += s0
        acc[j, 1] += s1
        acc[j, 2] += s2
        hits[j] += count


@register
class BruteForceDETP(Estimator):
    name = "detp"
    # Discs' radius and slab, sums (24) and crossing counts; clearance, rise, noise sums, the sums
    # in flight: measured, benchmarks/memory.py
    bytes_per_texel = 120
    streaming = True
    discs = True
    directional = True
    compared = False  # far too slow beyond small scenes

    def __init__(self, texels, settings, progress=None, context=None):
        super().__init__(texels, settings, progress, context)
        work = float(self.context.expected_segments) * len(texels)
        if work > WORK_LIMIT:
            raise BakeError(f"estimator 'detp' (brute force) would test about {work:.2g} segment–disc pairs "
                            f"(limit {WORK_LIMIT:.0e}): use sphere_cache or disc_index, or fewer photons/texels")
        self.discs = make_discs(texels, settings, self.context.scene_radius, self.context.clearance, self.context.rise,
                                self.context.extent)
        self.acc = np.zeros((len(texels), 3))
        self.acc_l1 = l1_sums(len(texels), self.context.directional)
        self.crossings = np.zeros(len(texels), np.int64)
        self.segments = 0
        self.seconds = 0.0

    def add(self, batch):
        t0 = time.perf_counter()
        d = self.discs
        _splat_all(batch.seg_origin, batch.seg_dir, batch.seg_length, batch.seg_flux, d.centre, d.normal,
                   d.radius, d.slab, d.eps, d.kernel, self.acc, self.acc_l1, self.crossings)
        self.segments += batch.segment_count
        self.seconds += time.perf_counter() - t0

    def take(self):
        sums = {"irradiance": self.acc, "crossings": int(self.crossings.sum()), "segments": self.segments,
                "seconds": self.seconds}
        self.acc = np.zeros_like(self.acc)
        if len(self.acc_l1):
            sums["l1"], self.acc_l1 = self.acc_l1, np.zeros_like(self.acc_l1)
        self.crossings[:] = 0
        self.segments, self.seconds = 0, 0.0
        return sums

    def absorb(self, sums):
        self.acc += sums["irradiance"]
        if len(self.acc_l1):
            self.acc_l1 += sums["l1"]
        self.crossings[0] += sums["crossings"]  # finish reads the total only
        self.segments += sums["segments"]
        self.seconds += sums["seconds"]

    def finish(self):
        n = len(self.texels)
        return Estimate(self.acc, {"segments": self.segments, "discs": n,
                                   "ray_disc_tests": self.segments * n,
                                   "crossings": int(self.crossings.sum()),
                                   "seconds_build": 0.0, "seconds_query": self.seconds},
                        self.acc_l1 if len(self.acc_l1) else None)
