"""DETP by disc indexing (García et al. 2005): index the discs, then walk every segment through the
index from its origin to its end, adding its flux to each disc it crosses.

The index is a BVH (bvh.py: Morton-order radix splits, float32 boxes, normal cones) over items:
loose discs, and lattice patches (patches.py), the 32x32 blocks of a flat chart's texels, where a
segment's crossings are found a lattice row at a time instead of disc by disc. It is built once;
photons then stream through it batch by batch, so memory does not grow with the photon count.
A batch goes in three steps:
  1. segments are sorted in Z-order of their ends, where most crossings are, so consecutive walks
     share nodes and discs;
  2. binning: each segment walks the top of the tree and is listed under every cluster (a subtree,
     one of some 16 per thread) whose box it enters, in segment order;
  3. splatting: threads take clusters, largest list first, and walk each listed segment through
     the cluster's subtree.
Every disc belongs to one cluster and sums its segments in batch order, so the estimate is the
same, bit for bit, on any number of threads and with or without patches, and one accumulator
serves all threads. benchmarks/estimators.py --profile has the counters and seconds per step.

The kernels inline crossing_weight (discs.py) and patch_splat (patches.py). numba's cache checks
only this file's date: after editing those, touch this file (or clear NUMBA_CACHE_DIR).
"""
from __future__ import annotations

import time

import numba
import numpy as np

from .base import Estimate, Estimator, register
from . import patches
from ..bvh import AXIS, CONE, HI, LO, STACK_DEPTH, build
from .discs import add_l1, crossing_weight, l1_sums, make_discs
from ..morton import segment_order
from .patches import SIDE, form_patches, group_keys, mark_cut, patch_splat

LEAF = 4  # discs per leaf
PATCHES = True  # flat charts' texels as lattice patches (patches.py)
CLUSTERS_PER_THREAD = 4  # units of parallel work: more means more binning, fewer means worse balance
MIN_CLUSTER = 4096  # discs
BIN_CHUNK = 1 << 12  # segments per binning task
ORDER_AT = 1.0  # segments are walked in Z-order of this point along them (0.5: midpoint, 1: end)


@numba.njit(cache=True, inline="always")
def _enters(node, k, ox, oy, oz, wx, wy, wz, ix, iy, iz, tmax):
    """Whether the segment, for t in [0, tmax], enters node k's box and arrives from the front of
    at least one disc below it (the normal cone)."""
    if wx * node[k, AXIS] + wy * node[k, AXIS + 1] + wz * node[k, AXIS + 2] >= node[k, CONE]:
        return False
    t0x, t1x = (node[k, LO] - ox) * ix, (node[k, HI] - ox) * ix
    t0y, t1y = (node[k, LO + 1] - oy) * iy, (node[k, HI + 1] - oy) * iy
    t0z, t1z = (node[k, LO + 2] - oz) * iz, (node[k, HI + 2] - oz) * iz
    tn = max(max(min(t0x, t1x), min(t0y, t1y)), max(min(t0z, t1z), 0.0))
    tf = min(min(max(t0x, t1x), max(t0y, t1y)), min(max(t0z, t1z), tmax))
    return tn <= tf


@numba.njit(cache=True, inline="always")
def _ray(o, w, length, i, eps):
    ox, oy, oz = np.float64(o[i, 0]), np.float64(o[i, 1]), np.float64(o[i, 2])
    wx, wy, wz = np.float64(w[i, 0]), np.float64(w[i, 1]), np.float64(w[i, 2])
    ix = 1.0 / wx if wx != 0.0 else 1e30
    iy = 1.0 / wy if wy != 0.0 else 1e30
    iz = 1.0 / wz if wz != 0.0 else 1e30
    return ox, oy, oz, wx, wy, wz, ix, iy, iz, length[i] + eps


@numba.njit(cache=True, parallel=True)
def _gather(order, o, w, length, flux):
    n = order.shape[0]
    o2, w2, f2 = np.empty((n, 3), o.dtype), np.empty((n, 3), w.dtype), np.empty((n, 3), flux.dtype)
    l2 = np.empty(n, length.dtype)
    for i in numba.prange(n):
        j = order[i]
        for c in range(3):
            o2[i, c], w2[i, c], f2[i, c] = o[j, c], w[j, c], flux[j, c]
        l2[i] = length[j]
    return o2, w2, l2, f2


@numba.njit(cache=True, parallel=True)
def _bin(o, w, length, eps, node, left, cluster_of, chunk, cap, seg, clu, used, tests):
    """Step 2: per chunk of segments, the (segment, cluster) pairs whose box the segment enters,
    in segment order. A chunk that fills its `cap` slots reports used = -1."""
    n = o.shape[0]
    for ch in numba.prange(used.shape[0]):
        stack = np.empty(STACK_DEPTH, np.int32)
        k = 0
        t = 0
        for i in range(ch * chunk, min(n, (ch + 1) * chunk)):
            ox, oy, oz, wx, wy, wz, ix, iy, iz, tmax = _ray(o, w, length, i, eps)
            t += 1
            if not _enters(node, 0, ox, oy, oz, wx, wy, wz, ix, iy, iz, tmax):
                continue  # it reaches no disc at all
            stack[0] = 0
            sp = 1
            while sp > 0 and k >= 0:
                sp -= 1
                nd = stack[sp]
                if cluster_of[nd] >= 0:
                    if k == cap:
                        k = -1
                        break
                    seg[ch, k] = i
                    clu[ch, k] = cluster_of[nd]
                    k += 1
                    continue
                for q in range(left[nd], left[nd] + 2):
                    t += 1
                    if _enters(node, q, ox, oy, oz, wx, wy, wz, ix, iy, iz, tmax):
                        stack[sp] = q
                        sp += 1
            if k < 0:
                break
        used[ch] = k
        tests[ch] = t


@numba.njit(cache=True)
def _lists(seg, clu, used, clusters):
    """Per cluster, its segments in segment order (CSR: start, list)."""
    count = np.zeros(clusters + 1, np.int64)
    for ch in range(used.shape[0]):
        for k in range(used[ch]):
            count[clu[ch, k] + 1] += 1
    start = np.cumsum(count)
    fill = start[:-1].copy()
    out = np.empty(start[-1], np.int32)
    for ch in range(used.shape[0]):
        for k in range(used[ch]):
            c = clu[ch, k]
            out[fill[c]] = seg[ch, k]
            fill[c] += 1
    return start, out


@numba.njit(cache=True, parallel=True)
def _splat(o, w, length, flux, eps, kernel, node, left, item_first, item_count, item_disc, item_patch, patch_geo,
           patch_site, roots, disc, start, lists, schedule, acc, acc_l1, stats):
    """Step 3: each cluster walks its segments through its subtree; its discs are its own."""
    for s in numba.prange(schedule.shape[0]):
        c = schedule[s]
        stack = np.empty(STACK_DEPTH, np.int32)
        node_tests = 0
        disc_tests = 0
        crossings = 0
        patch_visits = 0
        for e in range(start[c], start[c + 1]):
            i = lists[e]
            ox, oy, oz, wx, wy, wz, ix, iy, iz, tmax = _ray(o, w, length, i, eps)
            stack[0] = roots[c]  # binning found that the segment enters it
            sp = 1
            while sp > 0:
                sp -= 1
                nd = stack[sp]
                if left[nd] < 0:
                    for it in range(item_first[nd], item_first[nd] + item_count[nd]):
                        p = item_patch[it]
                        if p >= 0:
                            patch_visits += 1
                            tests, hits = patch_splat(p, patch_geo, patch_site, disc, o, w, length, flux, i, eps,
                                                      kernel, acc, acc_l1)
                            disc_tests += tests
                            crossings += hits
                            continue
                        j = item_disc[it]
                        disc_tests += 1
                        k = crossing_weight(o[i, 0], o[i, 1], o[i, 2], w[i, 0], w[i, 1], w[i, 2], length[i],
                                            disc[0, j], disc[1, j], disc[2, j], disc[3, j], disc[4, j], disc[5, j],
                                            disc[6, j], disc[7, j], eps, kernel)
                        if k > 0.0:
                            crossings += 1
                            acc[j, 0] += k * flux[i, 0]
                            acc[j, 1] += k * flux[i, 1]
                            acc[j, 2] += k * flux[i, 2]
                            add_l1(acc_l1, j, k, flux, w, i)
                    continue
                for q in range(left[nd], left[nd] + 2):
                    node_tests += 1
                    if _enters(node, q, ox, oy, oz, wx, wy, wz, ix, iy, iz, tmax):
                        stack[sp] = q
                        sp += 1
        stats[c, 0] += node_tests
        stats[c, 1] += disc_tests
        stats[c, 2] += crossings
        stats[c, 4] += patch_visits


@register
class DiscIndex(Estimator):
    name = "disc_index"
    # Discs (72), sums (24), tree order and patch sites; the discs' radius, clearance and rise (24),
    # noise sums (16), the sums in flight, what the build leaves: measured, benchmarks/memory.py
    # (200 until the sites' blend tables, 56 bytes a texel, were no longer made for every texel a site)
    bytes_per_texel = 155
    streaming = True
    discs = True
    directional = True

    def __init__(self, texels, settings, progress=None, context=None):
        super().__init__(texels, settings, progress, context)
        t0 = time.perf_counter()
        d = make_discs(texels, settings, self.context.scene_radius, self.context.clearance, self.context.rise,
                       self.context.extent)
        self.eps, self.kernel = d.eps, d.kernel
        patch_of = site_of = geo = None
        t1 = time.perf_counter()
        if PATCHES and len(d):
            lm = np.repeat(np.arange(len(texels.lightmaps)), [m.count for m in texels.lightmaps])
            width = np.array([m.width for m in texels.lightmaps], np.int64)[lm]
            i, j = texels.pixel % width, texels.pixel // width
            keys = group_keys(lm, i, j)
            by_key = np.argsort(keys, kind="stable")
            patch_of, site_of, geo = form_patches(keys[by_key], by_key, (i % SIDE).astype(np.float64),
                                                  (j % SIDE).astype(np.float64), d.centre, d.normal, d.radius, d.slab,
                                                  patches.LATTICE_TOL, patches.NORMAL_TOL)
        t2 = time.perf_counter()
        cluster = max(MIN_CLUSTER, len(d) // (CLUSTERS_PER_THREAD * numba.get_num_threads()))
        self.tree, self.disc, steps = build(d.centre, d.normal, d.radius, d.slab, d.eps, LEAF, cluster, patch_of,
                                            site_of, geo, SIDE)
        mark_cut(self.tree.patch_site, self.disc, self.tree.patch_geo)
        steps["patches"] = t2 - t1
        self.cluster_of = np.full(self.tree.nodes, -1, np.int32)
        self.cluster_of[self.tree.clusters] = np.arange(len(self.tree.clusters), dtype=np.int32)
        self.acc = np.zeros((len(texels), 3))
        self.acc_l1 = l1_sums(len(texels), self.context.directional)
        self.stats = np.zeros((len(self.tree.clusters), 5), np.int64)  # node, disc tests, crossings, entries, patches
        self.bin_tests = 0
        self.bin_slots = 4  # pairs kept per segment of a chunk; doubled when a chunk overflows
        self.segments = 0
        self.seconds = {"build": time.perf_counter() - t0, "build_patches": steps["patches"],
                        "build_sort": steps["sort"], "build_tree": steps["tree"], "query": 0.0, "query_order": 0.0,
                        "query_bin": 0.0,
                        "query_splat": 0.0}

    def add(self, batch):
        t0 = time.perf_counter()
        n = batch.segment_count
        if n == 0:
            return
        # Z-order of midpoints: consecutive walks visit the same nodes and discs (about 2x faster
        # than photon order, measured), and every cluster's list stays in that order.
        order = segment_order(batch.seg_origin, batch.seg_dir, batch.seg_length, ORDER_AT)
        o, w, length, flux = _gather(order, batch.seg_origin, batch.seg_dir, batch.seg_length, batch.seg_flux)
        t1 = time.perf_counter()
        t, chunks = self.tree, -(-n // BIN_CHUNK)
        while True:
            cap = self.bin_slots * BIN_CHUNK
            seg = np.empty((chunks, cap), np.int32)
            clu = np.empty((chunks, cap), np.int32)
            used = np.zeros(chunks, np.int64)
            tests = np.zeros(chunks, np.int64)
            _bin(o, w, length, self.eps, t.node, t.left, self.cluster_of, BIN_CHUNK, cap, seg, clu, used, tests)
            if used.min() >= 0:
                break
            self.bin_slots *= 2
        start, lists = _lists(seg, clu, used, len(t.clusters))
        del seg, clu
        sizes = np.diff(start)
        schedule = np.argsort(-sizes, kind="stable").astype(np.int32)
        t2 = time.perf_counter()
        with numba.parallel_chunksize(1):
            _splat(o, w, length, flux, self.eps, self.kernel, t.node, t.left, t.item_first, t.item_count, t.item_disc,
                   t.item_patch, t.patch_geo, t.patch_site, t.clusters, self.disc, start, lists, schedule, self.acc,
                   self.acc_l1, self.stats)
        t3 = time.perf_counter()
        self.stats[:, 3] += sizes
        self.bin_tests += int(tests.sum())
        self.segments += n
        s = self.seconds
        s["query_order"] += t1 - t0
        s["query_bin"] += t2 - t1
        s["query_splat"] += t3 - t2
        s["query"] += t3 - t0

    QUERY_SECONDS = ("query", "query_order", "query_bin", "query_splat")

    def take(self):
        irradiance = np.empty_like(self.acc)
        irradiance[self.tree.order] = self.acc  # texel order: another machine's tree may differ
        sums = {"irradiance": irradiance, "stats": self.stats.sum(axis=0), "bin_tests": self.bin_tests,
                "segments": self.segments, **{f"seconds_{k}": self.seconds[k] for k in self.QUERY_SECONDS}}
        self.acc[:] = 0.0
        if len(self.acc_l1):
            sums["l1"] = np.empty_like(self.acc_l1)
            sums["l1"][self.tree.order] = self.acc_l1
            self.acc_l1[:] = 0.0
        self.stats[:] = 0
        self.bin_tests = self.segments = 0
        for k in self.QUERY_SECONDS:
            self.seconds[k] = 0.0
        return sums

    def absorb(self, sums):
        self.acc += sums["irradiance"][self.tree.order]
        if len(self.acc_l1):
            self.acc_l1 += sums["l1"][self.tree.order]
        self.stats[0] += sums["stats"]  # finish reads the column sums only
        self.bin_tests += sums["bin_tests"]
        self.segments += sums["segments"]
        for k in self.QUERY_SECONDS:
            self.seconds[k] += sums[f"seconds_{k}"]

    def reset(self) -> None:
        """Forget the photons added so far and keep the index: the hybrid estimator splats every
        frame of a range through one index over the static discs."""
        self.take()

    def finish(self):
        t0 = time.perf_counter()
        out = np.empty_like(self.acc)
        out[self.tree.order] = self.acc
        st = self.stats.sum(axis=0)
        self.seconds["finish"] = time.perf_counter() - t0
        counters = {
            "segments": self.segments, "discs": len(self.texels), "bvh_nodes": self.tree.nodes,
            "bvh_depth": self.tree.depth, "clusters": len(self.tree.clusters),
            "patches": len(self.tree.patch_geo),
            "patch_discs": len(self.texels) - int((self.tree.item_patch < 0).sum()),
            "ray_node_tests": int(st[0]) + self.bin_tests, "bin_node_tests": self.bin_tests,
            "cluster_entries": int(st[3]), "patch_visits": int(st[4]), "ray_disc_tests": int(st[1]),
            "crossings": int(st[2])}
        counters.update({f"seconds_{k}": v for k, v in self.seconds.items()})
        l1 = None
        if len(self.acc_l1):
            l1 = np.empty_like(self.acc_l1)
            l1[self.tree.order] = self.acc_l1
        return Estimate(out, counters, l1)
