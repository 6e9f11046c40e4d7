"""DETP by disc indexing (García et al. 2005): index the discs, then walk every segment through the
index from its origin to its end, adding its flux to each disc it crosses.

The index is a balanced BVH over the bounds of the discs' cylinders (see discs.py), built once;
photons then stream through it batch by batch, so memory does not grow with the photon count.
Each thread splats its share of a batch into its own accumulator; they are summed at the end.
Measured against Embree scenes of disc quads in non-overlapping layers (benchmarks/
disc_index_embree.py: one trace per layer and per hit, since Embree reports only the nearest hit),
this compiled index is 2.0-2.5x faster on 2 cores, so it is the one in the product.
"""
from __future__ import annotations

import time

import numba
import numpy as np

from . import Estimate, Estimator, register
from .bvh import build
from .discs import crossing_weight, make_discs
from .morton import morton_order


@numba.njit(cache=True, parallel=True)
def _splat(o, w, length, flux, eps, nlo, nhi, left, right, start, count, order,
           cen, nrm, rad, slab, kernel, acc, stats):
    threads = acc.shape[0]
    n = o.shape[0]
    for tid in numba.prange(threads):
        a = tid * n // threads
        b = (tid + 1) * n // threads
        stack = np.empty(128, np.int64)
        node_tests = 0
        disc_tests = 0
        crossings = 0
        for i in range(a, b):
            ox, oy, oz = o[i, 0], o[i, 1], o[i, 2]
            wx, wy, wz = w[i, 0], w[i, 1], w[i, 2]
            ix = 1.0 / wx if wx != 0.0 else 1e30
            iy = 1.0 / wy if wy != 0.0 else 1e30
            iz = 1.0 / wz if wz != 0.0 else 1e30
            tmax = length[i] + eps
            stack[0] = 0
            sp = 1
            while sp > 0:
                sp -= 1
                node = stack[sp]
                node_tests += 1
                t0x, t1x = (nlo[node, 0] - ox) * ix, (nhi[node, 0] - ox) * ix
                t0y, t1y = (nlo[node, 1] - oy) * iy, (nhi[node, 1] - oy) * iy
                t0z, t1z = (nlo[node, 2] - oz) * iz, (nhi[node, 2] - oz) * iz
                tn = max(max(min(t0x, t1x), min(t0y, t1y)), max(min(t0z, t1z), 0.0))
                tf = min(min(max(t0x, t1x), max(t0y, t1y)), min(max(t0z, t1z), tmax))
                if tn > tf:
                    continue
                if left[node] < 0:
                    for p in range(start[node], start[node] + count[node]):
                        j = order[p]
                        disc_tests += 1
                        k = crossing_weight(ox, oy, oz, wx, wy, wz, length[i], cen[j, 0], cen[j, 1], cen[j, 2],
                                            nrm[j, 0], nrm[j, 1], nrm[j, 2], rad[j], slab[j], eps, kernel)
                        if k > 0.0:
                            crossings += 1
                            acc[tid, j, 0] += k * flux[i, 0]
                            acc[tid, j, 1] += k * flux[i, 1]
                            acc[tid, j, 2] += k * flux[i, 2]
                else:
                    stack[sp] = left[node]
                    stack[sp + 1] = right[node]
                    sp += 2
        stats[tid, 0] += node_tests
        stats[tid, 1] += disc_tests
        stats[tid, 2] += crossings


@register
class DiscIndex(Estimator):
    name = "disc_index"
    streaming = True

    def __init__(self, texels, settings, progress=None, context=None):
        super().__init__(texels, settings, progress, context)
        t0 = time.perf_counter()
        self.discs = make_discs(texels, settings, self.context.scene_radius, self.context.clearance)
        self.bvh = build(*self.discs.bounds())
        self.seconds_build = time.perf_counter() - t0
        self.threads = numba.get_num_threads()
        self.acc = np.zeros((self.threads, len(texels), 3))
        self.stats = np.zeros((self.threads, 3), np.int64)
        self.segments = 0
        self.seconds_query = 0.0

    def add(self, batch):
        t0 = time.perf_counter()
        d, t = self.discs, self.bvh
        # Walk segments in Z-order of their midpoints: consecutive walks visit the same nodes and
        # discs, so they stay in cache (about 2x faster than photon order, measured).
        mid = batch.seg_origin + batch.seg_dir * (0.5 * batch.seg_length)[:, None]
        order = morton_order(mid) if len(mid) else np.zeros(0, np.int64)
        o, w, length, flux = (np.ascontiguousarray(a[order]) for a in
                              (batch.seg_origin, batch.seg_dir, batch.seg_length, batch.seg_flux))
        _splat(o, w, length, flux, d.eps, t.lo, t.hi,
               t.left, t.right, t.start, t.count, t.order, d.centre, d.normal, d.radius, d.slab, d.kernel,
               self.acc, self.stats)
        self.segments += batch.segment_count
        self.seconds_query += time.perf_counter() - t0

    def finish(self):
        s = self.stats.sum(axis=0)
        return Estimate(self.acc.sum(axis=0), {
            "segments": self.segments, "discs": len(self.texels), "bvh_nodes": self.bvh.nodes,
            "bvh_depth": self.bvh.depth, "ray_node_tests": int(s[0]), "ray_disc_tests": int(s[1]),
            "crossings": int(s[2]), "seconds_build": self.seconds_build,
            "seconds_query": self.seconds_query})
