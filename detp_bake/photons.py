"""Photon tracing with Embree: batches of photons from the lights, diffuse bounces, and the two
records density estimators use — path segments (DETP family) and surface hits (photon map).

A bounce is one diffuse reflection. `bounces` caps the reflections a photon may have made before it
lands (0 = direct light only), exactly as Cycles' Light Paths › Diffuse bounces does for its bake.
Reflection uses Russian roulette with survival probability max(albedo), so the expected flux is
exact and a path ends on its own in closed scenes. Batches are independent and seeded by
(seed, batch index), so a bake is deterministic for a seed whatever the thread count.
"""
from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Callable, Iterator, Optional

import numba
import numpy as np

from .errors import BakeCancelled
from .lights import PhotonSchedule, build_emitters
from .scene import Scene


@dataclass
class PhotonBatch:
    """One batch's records. Segments run from `seg_origin` along unit `seg_dir` for `seg_length`;
    hits are where a segment landed on a surface, `hit_normal` facing the arriving photon."""
    photons: int
    seg_origin: np.ndarray
    seg_dir: np.ndarray
    seg_length: np.ndarray
    seg_flux: np.ndarray
    hit_position: np.ndarray
    hit_dir: np.ndarray
    hit_flux: np.ndarray
    hit_normal: np.ndarray
    hit_triangle: np.ndarray

    @property
    def segment_count(self) -> int:
        return len(self.seg_length)

    @property
    def hit_count(self) -> int:
        return len(self.hit_triangle)


@dataclass
class TraceStats:
    """Flux bookkeeping (RGB watts) and counts; emitted = absorbed + escaped + truncated, in
    expectation, where truncated is what the bounce limit cut off."""
    photons: int = 0
    segments: int = 0
    hits: int = 0
    rays: int = 0
    emitted: np.ndarray = field(default_factory=lambda: np.zeros(3))
    absorbed: np.ndarray = field(default_factory=lambda: np.zeros(3))
    escaped: np.ndarray = field(default_factory=lambda: np.zeros(3))
    truncated: np.ndarray = field(default_factory=lambda: np.zeros(3))
    seconds: float = 0.0
    embree_seconds: float = 0.0


class RayCaster:
    """An Embree scene of all triangles; `intersect` splits a batch across threads, since one
    embreex `run` call uses one core (it releases the GIL)."""

    MIN_CHUNK = 2048

    def __init__(self, positions: np.ndarray, threads: int):
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        self.scene = rtcore_scene.EmbreeScene()
        self._mesh = TriangleMesh(self.scene, np.ascontiguousarray(positions, np.float32))
        self.threads = max(1, int(threads))
        self._pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None

    def _run(self, origins, dirs):
        r = self.scene.run(origins, dirs, output=True)
        return r["tfar"], r["primID"], r["Ng"]

    def intersect(self, origins: np.ndarray, dirs: np.ndarray):
        """Closest hit per ray: (tfar, primID (-1 = miss), unnormalised geometric normal)."""
        origins = np.ascontiguousarray(origins, np.float32)
        dirs = np.ascontiguousarray(dirs, np.float32)
        n = len(origins)
        parts = min(self.threads, max(1, n // self.MIN_CHUNK))
        if parts == 1 or self._pool is None:
            return self._run(origins, dirs)
        bounds = np.linspace(0, n, parts + 1).astype(np.int64)
        jobs = [self._pool.submit(self._run, origins[a:b], dirs[a:b]) for a, b in zip(bounds[:-1], bounds[1:])]
        out = [j.result() for j in jobs]
        return tuple(np.concatenate(x) for x in zip(*out))

    def close(self):
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None


@numba.njit(cache=True, parallel=True)
def _scatter(origins, dirs, flux, tfar, prim, ng, albedo, bounce, max_bounces, u,
             centre, escape_radius, eps, seg_length, hit_pos, hit_normal, next_origin,
             next_dir, next_flux, survive, absorbed, escaped, truncated):
    """Per ray: segment length, hit record, and the Russian-roulette diffuse reflection."""
    n = origins.shape[0]
    for i in numba.prange(n):
        survive[i] = False
        for c in range(3):
            absorbed[i, c] = 0.0
            escaped[i, c] = 0.0
            truncated[i, c] = 0.0
        if prim[i] < 0:
            # Escapes: the segment runs to the far side of a sphere around the scene.
            b = 0.0
            cc = 0.0
            for c in range(3):
                d = origins[i, c] - centre[c]
                b += dirs[i, c] * d
                cc += d * d
            disc = b * b - (cc - escape_radius * escape_radius)
            t = -b + np.sqrt(disc) if disc > 0.0 else 0.0
            seg_length[i] = t if t > 0.0 else 0.0
            for c in range(3):
                escaped[i, c] = flux[i, c]
            continue
        seg_length[i] = tfar[i]
        nx, ny, nz = ng[i, 0], ng[i, 1], ng[i, 2]
        ln = np.sqrt(nx * nx + ny * ny + nz * nz)
        if ln > 0.0:
            nx, ny, nz = nx / ln, ny / ln, nz / ln
        if nx * dirs[i, 0] + ny * dirs[i, 1] + nz * dirs[i, 2] > 0.0:
            nx, ny, nz = -nx, -ny, -nz
        hit_normal[i, 0], hit_normal[i, 1], hit_normal[i, 2] = nx, ny, nz
        for c in range(3):
            hit_pos[i, c] = origins[i, c] + tfar[i] * dirs[i, c]
        t = prim[i]
        a0, a1, a2 = albedo[t, 0], albedo[t, 1], albedo[t, 2]
        for c in range(3):
            absorbed[i, c] = flux[i, c] * (1.0 - albedo[t, c])
        if bounce >= max_bounces:
            for c in range(3):
                truncated[i, c] = flux[i, c] * albedo[t, c]
            continue
        q = max(a0, max(a1, a2))
        if q > 1.0:
            q = 1.0
        if q <= 0.0 or u[i, 0] >= q:
            continue
        survive[i] = True
        for c in range(3):
            next_flux[i, c] = flux[i, c] * albedo[t, c] / q
        # Cosine-weighted direction about the face normal on the side the photon arrived.
        r = np.sqrt(u[i, 1])
        phi = 2.0 * np.pi * u[i, 2]
        lx, ly, lz = r * np.cos(phi), r * np.sin(phi), np.sqrt(max(0.0, 1.0 - u[i, 1]))
        sign = 1.0 if nz >= 0.0 else -1.0
        aa = -1.0 / (sign + nz)
        bb = nx * ny * aa
        tx, ty, tz = 1.0 + sign * nx * nx * aa, sign * bb, -sign * nx
        sx, sy, sz = bb, sign + ny * ny * aa, -ny
        next_dir[i, 0] = lx * tx + ly * sx + lz * nx
        next_dir[i, 1] = lx * ty + ly * sy + lz * ny
        next_dir[i, 2] = lx * tz + ly * sz + lz * nz
        next_origin[i, 0] = hit_pos[i, 0] + eps * nx
        next_origin[i, 1] = hit_pos[i, 1] + eps * ny
        next_origin[i, 2] = hit_pos[i, 2] + eps * nz


class PhotonTracer:
    """Traces `photons` photons in batches; iterate `batches()` to stream the records."""

    def __init__(self, scene: Scene, photons: int, bounces: int, seed: int = 0,
                 batch_size: int = 200_000, threads: int = 0):
        self.scene = scene
        self.bounces = int(bounces)
        self.schedule = PhotonSchedule(build_emitters(scene), int(photons), int(seed))
        self.batch_size = int(batch_size)
        self.threads = threads or numba.config.NUMBA_NUM_THREADS
        self.centre, radius = scene.bounds()
        self.escape_radius = 1.1 * radius
        self.eps = max(1e-5 * radius, 1e-6)
        self.albedo = np.clip(np.asarray(scene.albedo, np.float64), 0.0, 1.0)
        self.stats = TraceStats(emitted=self.schedule.emitted_flux.copy())
        self._caster: Optional[RayCaster] = None

    @property
    def photons(self) -> int:
        return self.schedule.total

    @property
    def batch_count(self) -> int:
        return -(-self.photons // self.batch_size)

    def batches(self, cancel: Optional[Callable[[], bool]] = None) -> Iterator[PhotonBatch]:
        if self._caster is None:
            self._caster = RayCaster(self.scene.positions, self.threads)
        try:
            for index in range(self.batch_count):
                if cancel is not None and cancel():
                    raise BakeCancelled()
                t0 = time.perf_counter()
                a = index * self.batch_size
                b = min(self.photons, a + self.batch_size)
                batch = self._trace_batch(index, a, b)
                self.stats.seconds += time.perf_counter() - t0
                yield batch
        finally:
            self._caster.close()
            self._caster = None

    def _trace_batch(self, index: int, start: int, stop: int) -> PhotonBatch:
        origins, dirs, flux = self.schedule.batch(index, start, stop)
        rng = np.random.default_rng([self.schedule.seed, index, 1])
        segs, hits = [], []
        st = self.stats
        st.photons += stop - start
        bounce = 0
        while len(origins):
            t0 = time.perf_counter()
            tfar, prim, ng = self._caster.intersect(origins, dirs)
            st.embree_seconds += time.perf_counter() - t0
            st.rays += len(origins)
            n = len(origins)
            u = rng.random((n, 3))
            seg_length = np.empty(n, np.float64)
            hit_pos = np.empty((n, 3), np.float64)
            hit_normal = np.empty((n, 3), np.float64)
            next_origin = np.empty((n, 3), np.float64)
            next_dir = np.empty((n, 3), np.float64)
            next_flux = np.empty((n, 3), np.float64)
            survive = np.empty(n, np.bool_)
            absorbed = np.empty((n, 3), np.float64)
            escaped = np.empty((n, 3), np.float64)
            truncated = np.empty((n, 3), np.float64)
            origins64 = np.asarray(origins, np.float64)
            dirs64 = np.asarray(dirs, np.float64)
            flux64 = np.asarray(flux, np.float64)
            _scatter(origins64, dirs64, flux64, tfar, prim, ng, self.albedo, bounce, self.bounces, u,
                     self.centre, self.escape_radius, self.eps, seg_length, hit_pos, hit_normal,
                     next_origin, next_dir, next_flux, survive, absorbed, escaped, truncated)
            st.absorbed += absorbed.sum(axis=0)
            st.escaped += escaped.sum(axis=0)
            st.truncated += truncated.sum(axis=0)
            keep = seg_length > 0.0
            segs.append((origins64[keep], dirs64[keep], seg_length[keep], flux64[keep]))
            hit = prim >= 0
            hits.append((hit_pos[hit], dirs64[hit], flux64[hit], hit_normal[hit], prim[hit]))
            origins, dirs, flux = next_origin[survive], next_dir[survive], next_flux[survive]
            bounce += 1
        f32 = lambda parts, k: np.ascontiguousarray(np.concatenate([p[k] for p in parts]), np.float32)
        batch = PhotonBatch(
            photons=stop - start,
            seg_origin=f32(segs, 0), seg_dir=f32(segs, 1), seg_length=f32(segs, 2), seg_flux=f32(segs, 3),
            hit_position=f32(hits, 0), hit_dir=f32(hits, 1), hit_flux=f32(hits, 2),
            hit_normal=f32(hits, 3),
            hit_triangle=np.concatenate([h[4] for h in hits]).astype(np.int32),
        )
        st.segments += batch.segment_count
        st.hits += batch.hit_count
        return batch
