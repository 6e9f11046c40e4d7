"""Rays against the scene's triangles, through Embree (embreex): every stage that casts rays (texel
validity, the discs' clearance, shadow rays, the photons) shares one RayCaster per bake."""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from typing import Optional

import numpy as np

CHUNK = 1 << 16  # rays per work item of `blocked`


class RayCaster:
    """An Embree scene of all triangles, its BVH built at construction. One `intersect` call is
    one embreex `run`, which uses one core and releases the GIL: the tracer calls it from several
    threads at once."""

    def __init__(self, positions: np.ndarray):
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        self.scene = rtcore_scene.EmbreeScene()
        self._mesh = TriangleMesh(self.scene, np.ascontiguousarray(positions, np.float32))
        # embreex builds the BVH on the first run: do it now, not in the first batch.
        self.scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), output=True)

    def hits(self, origins: np.ndarray, dirs: np.ndarray, tfar: np.ndarray) -> dict:
        """Closest hits with everything Embree reports (tfar, primID, Ng, u, v); `tfar` (float32)
        holds the far limits and receives the hit distances in place."""
        return self.scene.run(origins, dirs, dists=tfar, output=True)

    def intersect(self, origins: np.ndarray, dirs: np.ndarray, tfar: Optional[np.ndarray] = None):
        """Closest hit per ray of float32 (N, 3) arrays: (tfar, primID (-1 = miss), unnormalised
        geometric normal). A given float32 `tfar` holds each ray's far limit (1e37: none) and
        receives the hit distances in place."""
        r = self.scene.run(origins, dirs, dists=tfar, output=True)
        return r["tfar"], r["primID"], r["Ng"]

    def occluded(self, origins: np.ndarray, dirs: np.ndarray, tfar: np.ndarray) -> np.ndarray:
        """Shadow rays: −1 where nothing lies within each ray's `tfar` (float32, overwritten)."""
        return self.scene.run(origins, dirs, dists=tfar, query="OCCLUDED")

    def blocked(self, origins: np.ndarray, dirs: np.ndarray, far: np.ndarray, threads: int = 1) -> np.ndarray:
        """Whether each ray meets anything before `far` (any float arrays), the rays split over
        `threads` (one `occluded` call uses one core)."""
        out = np.empty(len(origins), bool)

        def run(a):
            b = min(a + CHUNK, len(origins))
            out[a:b] = self.occluded(np.ascontiguousarray(origins[a:b], np.float32),
                                     np.ascontiguousarray(dirs[a:b], np.float32),
                                     np.ascontiguousarray(far[a:b], np.float32)) >= 0

        if threads <= 1 or len(origins) <= CHUNK:  # no pool (a thread started for each of 1,500 small lightmaps)
            for a in range(0, len(origins), CHUNK):
                run(a)
            return out
        with ThreadPoolExecutor(int(threads)) as pool:
            list(pool.map(run, range(0, len(origins), CHUNK)))
        return out
