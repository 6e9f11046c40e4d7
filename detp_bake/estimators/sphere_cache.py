"""DETP accelerated by Lastra's sphere cache.

A hierarchy of bounding spheres over the segments: level 0 is the whole scene and holds every
segment; level k has radius r₀·Q^k and holds its parent's segments that pass through it; the last
level a texel uses is the smallest that still contains its disc's cylinder (radius ≈ r). Texels are
visited in Morton order of their positions, so consecutive discs are close: for each one we keep the
deepest cached level whose sphere still contains the disc and rebuild only the levels below it,
centred on the disc. The optimal Q is about 0.6–0.7 (the paper's analysis; benchmarks sweep it).

Texel chunks of the Morton order run in parallel, each with its own cache. Segments are processed in
blocks of STREAM_SEGMENTS as batches arrive, so memory stays bounded whatever the photon count.
"""
from __future__ import annotations

import time

import numba
import numpy as np

from .base import Estimate, Estimator, register
from .discs import add_l1, crossing_weight, l1_sums, make_discs
from ..morton import morton_order

STREAM_SEGMENTS = 2_000_000
CHUNK_TEXELS = 4096


@numba.njit(cache=True)
def _grow(buf, need):
    if need <= buf.shape[0]:
        return buf
    out = np.empty(max(need, 2 * buf.shape[0]), np.int64)
    out[:buf.shape[0]] = buf
    return out


@numba.njit(cache=True, parallel=True)
def _run(o, w, length, flux, eps, visit, edges, sc, sr, levels, radii,
         cen, nrm, rad, slab, kernel, acc, acc_l1, stats):
    n = o.shape[0]
    kmax = radii.shape[0] - 1
    for ci in numba.prange(edges.shape[0] - 1):
        lc = np.zeros((kmax + 1, 3))
        lstart = np.zeros(kmax + 2, np.int64)
        buf = np.empty(max(1024, n // 4), np.int64)
        deepest = 0
        sphere_tests = 0
        disc_tests = 0
        crossings = 0
        rebuilds = 0
        for p in range(edges[ci], edges[ci + 1]):
            j = visit[p]
            top = levels[j]
            x0, x1, x2 = sc[j, 0], sc[j, 1], sc[j, 2]
            # The deepest level such that it and every level above it contain the disc: levels
            # are built from their parents, so a disc outside any ancestor may miss segments.
            d = 0
            while d < min(deepest, top):
                c = d + 1
                dist = np.sqrt((x0 - lc[c, 0]) ** 2 + (x1 - lc[c, 1]) ** 2 + (x2 - lc[c, 2]) ** 2)
                if dist + sr[j] > radii[c]:
                    break
                d = c
            for k in range(d + 1, top + 1):
                rebuilds += 1
                lc[k, 0], lc[k, 1], lc[k, 2] = x0, x1, x2
                r2 = radii[k] * radii[k]
                parent = n if k == 1 else lstart[k] - lstart[k - 1]
                buf = _grow(buf, lstart[k] + parent)
                pos = lstart[k]
                for m in range(parent):
                    i = m if k == 1 else buf[lstart[k - 1] + m]
                    sphere_tests += 1
                    t = (x0 - o[i, 0]) * w[i, 0] + (x1 - o[i, 1]) * w[i, 1] + (x2 - o[i, 2]) * w[i, 2]
                    t = min(max(t, 0.0), length[i] + eps)
                    q0 = o[i, 0] + t * w[i, 0] - x0
                    q1 = o[i, 1] + t * w[i, 1] - x1
                    q2 = o[i, 2] + t * w[i, 2] - x2
                    if q0 * q0 + q1 * q1 + q2 * q2 <= r2:
                        buf[pos] = i
                        pos += 1
                lstart[k + 1] = pos
            if d < top:
                deepest = top
            members = n if top == 0 else lstart[top + 1] - lstart[top]
            s0 = 0.0
            s1 = 0.0
            s2 = 0.0
            for m in range(members):
                i = m if top == 0 else buf[lstart[top] + m]
                disc_tests += 1
                kw = crossing_weight(o[i, 0], o[i, 1], o[i, 2], w[i, 0], w[i, 1], w[i, 2], length[i],
                                     cen[j, 0], cen[j, 1], cen[j, 2], nrm[j, 0], nrm[j, 1], nrm[j, 2],
                                     rad[j], slab[j], eps, kernel)
                if kw > 0.0:
                    crossings += 1
                    s0 += kw * flux[i, 0]
                    s1 += kw * flux[i, 1]
                    s2 += kw * flux[i, 2]
                    add_l1(acc_l1, j, kw, flux, w, i)
            acc[j, 0] += s0
            acc[j, 1] += s1
            acc[j, 2] += s2
        stats[ci, 0] += sphere_tests
        stats[ci, 1] += disc_tests
        stats[ci, 2] += crossings
        stats[ci, 3] += rebuilds


@register
class SphereCache(Estimator):
    name = "sphere_cache"
    # Discs' radius and slab, their spheres, levels and Morton order, sums (24); clearance and rise,
    # noise sums, the sums in flight: measured, benchmarks/memory.py
    bytes_per_texel = 160
    streaming = True
    discs = True
    directional = True
    group_segments = STREAM_SEGMENTS

    def __init__(self, texels, settings, progress=None, context=None):
        super().__init__(texels, settings, progress, context)
        t0 = time.perf_counter()
        self.discs = make_discs(texels, settings, self.context.scene_radius, self.context.clearance, self.context.rise,
                                self.context.extent)
        self.sphere_centre, self.sphere_radius = self.discs.bounding_spheres()
        q = float(settings.q)
        r0 = 2.0 * self.context.scene_radius  # contains the scene wherever its centre is
        self.levels = np.maximum(0, np.floor(np.log(self.sphere_radius / r0) / np.log(q))).astype(np.int64)
        self.radii = r0 * q ** np.arange(int(self.levels.max()) + 1)
        self.visit = morton_order(self.discs.centre)
        # Chunks of the Morton order, run `threads` at a time so progress and cancel are checked
        # between groups; each chunk starts its cache afresh from level 0.
        self.threads = numba.get_num_threads()
        chunks = min(len(texels), max(4 * self.threads, -(-len(texels) // CHUNK_TEXELS)))
        self.edges = np.linspace(0, len(texels), chunks + 1).astype(np.int64)
        self.acc = np.zeros((len(texels), 3))
        self.acc_l1 = l1_sums(len(texels), self.context.directional)
        self.stats = np.zeros((chunks, 4), np.int64)
        self.pending = []
        self.pending_count = 0
        self.segments = 0
        self.seconds_build = time.perf_counter() - t0
        self.seconds_query = 0.0

    def add(self, batch):
        self.pending.append(batch)
        self.pending_count += batch.segment_count
        if self.pending_count >= STREAM_SEGMENTS:
            self._flush()

    def _flush(self):
        if not self.pending:
            return
        t0 = time.perf_counter()
        cat = lambda attr: np.ascontiguousarray(np.concatenate([getattr(b, attr) for b in self.pending]))
        o, w, length, flux = cat("seg_origin"), cat("seg_dir"), cat("seg_length"), cat("seg_flux")
        self.pending, self.pending_count = [], 0
        d = self.discs
        chunks = len(self.edges) - 1
        for a in range(0, chunks, self.threads):
            b = min(chunks, a + self.threads)
            _run(o, w, length, flux, d.eps, self.visit, self.edges[a:b + 1], self.sphere_centre,
                 self.sphere_radius, self.levels, self.radii, d.centre, d.normal, d.radius, d.slab, d.kernel,
                 self.acc, self.acc_l1, self.stats[a:b])
            self.progress(b / chunks)
        self.segments += len(length)
        self.seconds_query += time.perf_counter() - t0

    def take(self):
        self._flush()
        sums = {"irradiance": self.acc, "stats": self.stats.sum(axis=0), "segments": self.segments,
                "seconds_query": self.seconds_query}
        self.acc = np.zeros_like(self.acc)
        if len(self.acc_l1):
            sums["l1"], self.acc_l1 = self.acc_l1, np.zeros_like(self.acc_l1)
        self.stats[:] = 0
        self.segments, self.seconds_query = 0, 0.0
        return sums

    def absorb(self, sums):
        self._flush()
        self.acc += sums["irradiance"]
        if len(self.acc_l1):
            self.acc_l1 += sums["l1"]
        self.stats[0] += sums["stats"]  # finish reads the column sums only
        self.segments += sums["segments"]
        self.seconds_query += sums["seconds_query"]

    def finish(self):
        self._flush()
        s = self.stats.sum(axis=0)
        return Estimate(self.acc, {
            "segments": self.segments, "discs": len(self.texels), "levels": len(self.radii),
            "q": float(self.settings.q), "ray_sphere_tests": int(s[0]), "ray_disc_tests": int(s[1]),
            "crossings": int(s[2]), "sphere_rebuilds": int(s[3]), "seconds_build": self.seconds_build,
            "seconds_query": self.seconds_query}, self.acc_l1 if len(self.acc_l1) else None)
