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

from ..kdtree import KDTree
from ..rays import RayCaster
from ..lightmap.validity import LIFT
from .base import Estimate, Estimator, register
from ..bvh import discs_meet_triangles

CHUNK = 8192  # texels per k-NN query, bounds the (chunk, k, 3) gather


class _Walls:
    """What a texel's gather must not reach through: a hit beyond a wall (a floor inside a sealed
    room gathers only from outside, where all its nearest hits are) is left out. Only texels whose
    gather disc some triangle may cross cast rays, one per neighbour, lifted off both surfaces."""

    def __init__(self, texels, scene):
        self.texels = texels
        self.scene = scene
        self.caster = None if scene is None or scene.triangle_count == 0 else RayCaster(scene.positions)
        self.lift = LIFT * texels.per_texel([lm.texel_size for lm in texels.lightmaps])

    def hide(self, a, b, reach, hit_pos, hit_normal, ok):
        """Clear `ok` (texels a … b−1 by neighbour) where a wall stands between texel and hit."""
        if self.caster is None:
            return
        x = self.texels.position[a:b] + self.lift[a:b, None] * self.texels.normal[a:b]
        suspect = discs_meet_triangles(self.scene.positions, x, self.texels.normal[a:b], reach)
        rows, cols = np.nonzero(ok & suspect[:, None])
        if rows.size == 0:
            return
        end = hit_pos[rows, cols].astype(np.float64) + self.lift[a + rows, None] * hit_normal[rows, cols]
        span = end - x[rows]
        length = np.linalg.norm(span, axis=1)
        way = span / np.maximum(length, 1e-300)[:, None]
        blocked = self.caster.occluded(np.ascontiguousarray(x[rows], np.float32),
                                       np.ascontiguousarray(way, np.float32), length.astype(np.float32)) >= 0
        ok[rows[blocked], cols[blocked]] = False


@register
class PhotonMap(Estimator):
    name = "photon_map"
    bytes_per_texel = 30  # its (N, 3) result (the hits are counted apart): benchmarks/memory.py
    stores_hits = True
    segments = False  # the hits alone
    slow_preview = True
    baseline = True
    directional = True

    @classmethod
    def fixed_noise(cls, settings):
        """About 1/√(k − 1) whatever the photon count (docs/design.md, Estimators)."""
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
        l1 = np.zeros((n, 9)) if self.context.directional else None
        pos, wdir, flux, hnorm = (np.concatenate([p[i] for p in parts]) if parts
                                  else np.zeros((0, 3), np.float32) for i in range(4))
        hits = len(pos)
        k = min(int(self.settings.k), hits)
        counters = {"hits": hits, "k": k}
        if k < 2:
            counters.update(seconds_build=0.0, seconds_query=0.0)
            return Estimate(irradiance, counters, l1)
        # An unbalanced, non-compact tree builds several times faster and queries about as fast.
        tree = KDTree(pos, balanced=False, compact=False)
        t1 = time.perf_counter()
        cos_min = float(self.settings.normal_agreement)
        walls = _Walls(self.texels, self.context.scene)
        used = 0
        for a in range(0, n, CHUNK):
            b = min(n, a + CHUNK)
            x = self.texels.position[a:b]
            nrm = self.texels.normal[a:b]
            dist, idx = tree.query(x, k)
            dist = dist.reshape(b - a, k)
            idx = idx.reshape(b - a, k)
            near = idx[:, :k - 1]
            front = np.einsum("nkc,nc->nk", wdir[near], nrm) < 0.0
            agree = np.einsum("nkc,nc->nk", hnorm[near], nrm) >= cos_min
            ok = front & agree
            walls.hide(a, b, dist[:, k - 1], pos[near], hnorm[near], ok)
            used += int(ok.sum())
            total = np.einsum("nk,nkc->nc", ok.astype(np.float64), flux[near].astype(np.float64))
            r2 = np.maximum(dist[:, k - 1], 1e-12) ** 2
            irradiance[a:b] = total / (np.pi * r2)[:, None]
            if l1 is not None:  # the same hits' flux times the way they came (lightmap/sh.py)
                back = np.einsum("nk,nkc,nka->nac", ok.astype(np.float64), flux[near].astype(np.float64),
                                 -wdir[near].astype(np.float64))
                l1[a:b] = back.reshape(b - a, 9) / (np.pi * r2)[:, None]
            progress(b / n)
        counters.update(photons_used=used, seconds_build=t1 - t0,
                        seconds_query=time.perf_counter() - t1)
        return Estimate(irradiance, counters, l1)
