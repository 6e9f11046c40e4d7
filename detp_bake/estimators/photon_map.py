"""Jensen's photon map: irradiance from the k nearest surface hits.

E(x) = Σ Φ_p / (π r_k²) over the k − 1 nearest hits that arrive from the front of the texel and lie
on a surface facing the same way; r_k, the distance to the k-th hit, only sets the area (counting
the k-th photon too over-estimates: García, Ureña and Sbert 2012). Relative noise is about 1/√k
whatever the photon count; more photons only shrink r_k. It needs every hit at once, so it keeps
them all until `finish`; a live preview gathers over the hits so far (`current`).
"""
from __future__ import annotations

import time

import numpy as np
from scipy.spatial import cKDTree

from . import Estimate, Estimator, register

CHUNK = 8192  # texels per k-NN query, bounds the (chunk, k, 3) gather


@register
class PhotonMap(Estimator):
    name = "photon_map"
    bytes_per_texel = 30  # its (N, 3) result (the hits are counted apart): benchmarks/memory.py
    label = "Photon Map"
    description = "Jensen's k-nearest-neighbour photon map: noisy, darkens edges"
    stores_hits = True
    slow_preview = True
    baseline = True

    @classmethod
    def fixed_noise(cls, settings):
        """About 1/√(k − 1) whatever the photon count (DESIGN.md §2)."""
        return 1.0 / float(np.sqrt(settings.k - 1))

    def __init__(self, texels, settings, progress=None, context=None):
        super().__init__(texels, settings, progress, context)
        self._parts = []

    def add(self, batch):
        self._parts.append((batch.hit_position, batch.hit_dir, batch.hit_flux, batch.hit_normal))

    def take(self):
        sums = {"parts": self._parts}
        self._parts = []
        return sums

    def absorb(self, sums):
        self._parts.extend(sums["parts"])

    def finish(self):
        parts, self._parts = self._parts, []
        return self._gather(parts, self.progress)

    def current(self, sums, progress=None):
        """The gather over the hits so far. Their flux is the share of the bake traced, which the
        bake divides by (as a stop keeps it): fewer hits put the k-th neighbour farther away, so a
        preview is blurrier than the final lightmap, not darker."""
        return self._gather(sums.get("parts", []), progress or (lambda fraction: None)).irradiance

    def _gather(self, parts, progress):
        t0 = time.perf_counter()
        n = len(self.texels)
        irradiance = np.zeros((n, 3))
        pos, wdir, flux, hnorm = (np.concatenate([p[i] for p in parts]) if parts
                                  else np.zeros((0, 3), np.float32) for i in range(4))
        hits = len(pos)
        k = min(int(self.settings.k), hits)
        counters = {"hits": hits, "k": k}
        if k < 2:
            counters.update(seconds_build=0.0, seconds_query=0.0)
            return Estimate(irradiance, counters)
        # An unbalanced, non-compact tree builds several times faster and queries about as fast.
        tree = cKDTree(pos, balanced_tree=False, compact_nodes=False)
        t1 = time.perf_counter()
        cos_min = float(self.settings.normal_agreement)
        used = 0
        for a in range(0, n, CHUNK):
            b = min(n, a + CHUNK)
            x = self.texels.position[a:b]
            nrm = self.texels.normal[a:b]
            dist, idx = tree.query(x, k=k, workers=-1)
            dist = dist.reshape(b - a, k)
            idx = idx.reshape(b - a, k)
            near = idx[:, :k - 1]
            front = np.einsum("nkc,nc->nk", wdir[near], nrm) < 0.0
            agree = np.einsum("nkc,nc->nk", hnorm[near], nrm) >= cos_min
            ok = front & agree
            used += int(ok.sum())
            total = np.einsum("nk,nkc->nc", ok.astype(np.float64), flux[near].astype(np.float64))
            r2 = np.maximum(dist[:, k - 1], 1e-12) ** 2
            irradiance[a:b] = total / (np.pi * r2)[:, None]
            progress(b / n)
        counters.update(photons_used=used, seconds_build=t1 - t0,
                        seconds_query=time.perf_counter() - t1)
        return Estimate(irradiance, counters)
