"""Rays against the scene's triangles, through Embree (embreex): every stage that casts rays (texel
validity, the discs' clearance, shadow rays, the photons) shares one RayCaster per bake."""
from __future__ import annotations

from typing import Optional

import numpy as np


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
