"""Photon tracing with Embree: batches of photons from the lights, diffuse bounces, and the two
records density estimators use — path segments (DETP family) and surface hits (photon map).

A bounce is one diffuse reflection. `bounces` caps the reflections a photon may have made before it
lands (0 = direct light only), exactly as Cycles' Light Paths › Diffuse bounces does for its bake.
A photon that brings indirect light alone always reflects from its first landing, and otherwise by
Russian roulette with survival probability max(albedo) (scattering.py), so the expected flux is
exact and a path ends on its own in closed scenes. Each photon draws its random numbers from its own stream, started from (seed, photon
id) (`sampling.py`), and records are laid out in an order fixed by the batch size alone, so a bake
is deterministic for a seed whatever the thread count.
"""
from __future__ import annotations

import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Callable, Iterator, Optional

import numba
import numpy as np

from ..errors import BakeCancelled
from ..rays import RayCaster
from .lights import build_emitters
from .schedule import BatchSchedule
from .textures import surfaces
from .scattering import MAX_PASSES, RAY_FAR, bounce, flights_per_photon, material_table, pass_through, survival
from ..scene import Scene


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
    embree_seconds: float = 0.0  # time in Embree calls, summed over the threads
    photons_hit: int = 0  # photons whose first flight landed on a surface (the rest missed the scene)
    alpha_passes: int = 0  # flights continued through a cut-out surface
    alpha_cut: int = 0  # flights stopped because they passed MAX_PASSES cut-outs

    def add(self, other: "TraceStats") -> None:
        """Add another run's counts and flux (bake.Totals: runs of batches, added in batch order)."""
        for name, value in vars(other).items():
            setattr(self, name, getattr(self, name) + value)


class _Stream:
    """Photons traced together by one thread: the log of their rays (every bounce in order; they
    become the segments) and their hits, laid out as the batch's records, in buffers that grow as
    needed and are reused from stream to stream (and from bake to bake: see `_FREE`)."""

    def __init__(self):
        self.rays = self.hits = self.kept = 0
        self.skip_rays = self.skip_hits = self.skip_kept = 0  # the first bounce's records, when left out
        self.sums = np.zeros((3, 3))
        self.embree_seconds = 0.0
        self.passes = self.cut = self.first_hits = 0
        self._alloc(0, 0)

    def _alloc(self, rays: int, hits: int):
        vec = lambda n: np.empty((n, 3), np.float32)
        self.o, self.d, self.f = vec(rays), vec(rays), vec(rays)
        self.length = np.empty(rays, np.float32)
        self.rng = np.empty(rays, np.uint64)
        # What Embree found for each ray: triangle (−1: none), geometric normal, barycentrics; and
        # whether the ray went on through a cut-out.
        self.prim = np.empty(rays, np.int32)
        self.ng = vec(rays)
        self.bu = np.empty(rays, np.float32)
        self.bv = np.empty(rays, np.float32)
        self.through = np.zeros(rays, np.bool_)
        self.hit_pos, self.hit_dir, self.hit_flux, self.hit_nrm = vec(hits), vec(hits), vec(hits), vec(hits)
        self.hit_tri = np.empty(hits, np.int32)

    RAY_ARRAYS = 10  # the first ten of _arrays() have a row per ray

    def _arrays(self):
        return (self.o, self.d, self.f, self.length, self.rng, self.prim, self.ng, self.bu, self.bv, self.through,
                self.hit_pos, self.hit_dir, self.hit_flux, self.hit_nrm, self.hit_tri)

    def reserve(self, rays: int, hits: int):
        """Room for `rays` rays and `hits` hits, keeping what is logged so far."""
        if rays <= len(self.length) and hits <= len(self.hit_tri):
            return
        old = self._arrays()
        self._alloc(max(rays, len(self.length) * 3 // 2), max(hits, len(self.hit_tri) * 3 // 2))
        for a, b, n in zip(old, self._arrays(), [self.rays] * self.RAY_ARRAYS + [self.hits] * 5):
            b[:n] = a[:n]

    @property
    def segment_count(self) -> int:
        """Segments this stream hands to the batch."""
        return self.kept - self.skip_kept

    @property
    def hit_count(self) -> int:
        return self.hits - self.skip_hits

    def copy_to(self, seg: Optional[list], seg_at: int, hit: list[np.ndarray], hit_at: int) -> None:
        """This stream's segments of positive length into rows `seg_at` … of a batch's segment
        arrays (origin, direction, length, flux; None: not recorded), its hits into rows `hit_at` …
        of its hit arrays. numpy's block copies (memcpy) beat compiled loops several times here."""
        a, n, h, nh = self.skip_rays, self.rays, self.skip_hits, self.hits
        if seg is not None:
            src = self.o[a:n], self.d[a:n], self.length[a:n], self.f[a:n]
            count = self.segment_count
            if count < n - a:  # some segment of zero length: none in a closed scene
                keep = self.length[a:n] > 0.0
                src = tuple(x[keep] for x in src)
            for dst, x in zip(seg, src):
                dst[seg_at:seg_at + count] = x
        for dst, x in zip(hit, (self.hit_pos, self.hit_dir, self.hit_flux, self.hit_nrm, self.hit_tri)):
            dst[hit_at:hit_at + nh - h] = x[h:nh]


# Stream buffers not in use, shared by all tracers (list.pop and append are atomic): a few
# megabytes each, kept from bake to bake, as many as a tracer's threads use at once
# (release_memory() frees them).
_FREE: list[_Stream] = []


class _ArrayPool:
    """Record arrays for batches, handed out as views and reused once no view of them is left.

    A view holds a reference to the array it views, as does every array derived from one without
    a copy, so an array whose reference count is back at its count when idle has no users and its
    memory can take a later batch's records. Fresh memory is slow to touch (page faults: several
    milliseconds per batch); this memory is not. The pools are shared by all tracers and keep at
    most KEEP sets: the batch being filled, the one its consumer still holds, and one spare."""

    KEEP = 3

    def __init__(self, *spec):
        self.spec = spec  # (shape of a row, dtype) per array
        self.sets: list[list[np.ndarray]] = []
        self._idle = None
        self.lock = threading.Lock()

    @staticmethod
    def _refs(arrays) -> list[int]:
        return [sys.getrefcount(a) for a in arrays]

    def take(self, rows: int) -> list[np.ndarray]:
        """A set of arrays of at least `rows` rows that nothing else uses."""
        with self.lock:
            return self._take(rows)

    def _take(self, rows: int) -> list[np.ndarray]:
        idle = [arrays for arrays in self.sets if self._refs(arrays) == self._idle]
        for arrays in idle:
            if len(arrays[0]) >= rows:
                return arrays
        self.sets = [arrays for arrays in self.sets if not any(arrays is a for a in idle)]  # all too small
        arrays = [np.empty((rows * 9 // 8,) + row, dtype) for row, dtype in self.spec]
        self._idle = self._refs(arrays)
        self.sets.append(arrays)
        if len(self.sets) > self.KEEP:
            self.sets.pop(0)  # in use: it is freed when its last view goes
        return arrays

    def clear(self) -> None:
        """Forget every set (in-use ones are freed when their last view goes)."""
        with self.lock:
            self.sets = []

    def grow(self, arrays: list[np.ndarray], rows: int, used: int) -> None:
        """Replace a set's arrays by larger ones (keeping the first `used` rows), in place."""
        for k, (a, (row, dtype)) in enumerate(zip(list(arrays), self.spec)):
            arrays[k] = np.empty((rows,) + row, dtype)
            arrays[k][:used] = a[:used]


_VEC, _ROW = ((3,), np.float32), ((), np.float32)
_SEGMENT_ARRAYS = _ArrayPool(_VEC, _VEC, _ROW, _VEC)  # origin, direction, length, flux
_HIT_ARRAYS = _ArrayPool(_VEC, _VEC, _VEC, _VEC, ((), np.int32))  # position, direction, flux, normal, triangle


# A batch's segment arrays where the tracer records none (PhotonTracer(segments=False)).
_NO_SEGMENTS = [np.empty((0, 3), np.float32), np.empty((0, 3), np.float32), np.empty(0, np.float32),
                np.empty((0, 3), np.float32)]


def release_memory() -> None:
    """Let go of the buffers kept for later bakes (stream buffers and idle record arrays)."""
    _FREE.clear()
    _SEGMENT_ARRAYS.clear()
    _HIT_ARRAYS.clear()


class _Records:
    """A batch's record arrays, taken from the tracer's pools for an estimate of their size.

    Streams are placed in stream order: when a stream is traced, the thread that traced it copies
    it in — while it is still in that core's cache — if every earlier stream is placed, and then
    any later streams that were waiting for it. Streams that do not fit wait for `close`, which
    grows the arrays once no thread is copying."""

    def __init__(self, seg_pool: Optional[_ArrayPool], hit_pool: _ArrayPool, segments: int, hits: int,
                 streams: int, keep: int):
        self.pools = seg_pool, hit_pool
        self.keep = keep  # stream buffers to keep once copied
        # No segment pool: the batch's segment arrays are empty, and its segments only counted.
        self.seg = seg_pool.take(segments) if seg_pool is not None else _NO_SEGMENTS
        self.hit = hit_pool.take(hits)
        self.segments = self.hits = 0  # rows placed
        self.segment_total = 0  # segments of the streams added, placed or not
        self.waiting: list[Optional[_Stream]] = [None] * streams
        self.placed = 0  # streams placed
        self.full = False
        self.stats: list = [None] * streams
        self._lock = threading.Lock()

    def _copy(self, st: _Stream, seg_at: int, hit_at: int):
        st.copy_to(self.seg if self.pools[0] is not None else None, seg_at, self.hit, hit_at)
        if len(_FREE) < self.keep:
            _FREE.append(st)

    def add(self, index: int, st: _Stream):
        """Stream `index` is traced (called from the thread that traced it)."""
        self.stats[index] = (st.rays, st.sums.copy(), st.embree_seconds, st.passes, st.cut, st.first_hits,
                             st.segment_count)
        recorded = self.pools[0] is not None
        jobs = []
        with self._lock:
            self.waiting[index] = st
            self.segment_total += st.segment_count
            while not self.full and self.placed < len(self.waiting) and self.waiting[self.placed] is not None:
                nxt = self.waiting[self.placed]
                if (recorded and self.segments + nxt.segment_count > len(self.seg[0])) or \
                        self.hits + nxt.hit_count > len(self.hit[0]):
                    self.full = True
                    break
                jobs.append((nxt, self.segments, self.hits))
                self.segments += nxt.segment_count if recorded else 0
                self.hits += nxt.hit_count
                self.waiting[self.placed] = None
                self.placed += 1
        for job in jobs:
            self._copy(*job)

    def close(self, photons: int) -> PhotonBatch:
        """Every stream added and copied: place what did not fit, and hand out the batch."""
        rest = [st for st in self.waiting[self.placed:] if st is not None]
        recorded = self.pools[0] is not None
        for pool, arrays, used, more in zip(self.pools, (self.seg, self.hit), (self.segments, self.hits),
                                            (sum(st.segment_count for st in rest), sum(st.hit_count for st in rest))):
            if pool is not None and used + more > len(arrays[0]):
                pool.grow(arrays, used + more, used)
        for st in rest:
            self._copy(st, self.segments, self.hits)
            self.segments += st.segment_count if recorded else 0
            self.hits += st.hit_count
        return PhotonBatch(photons, *(a[:self.segments] for a in self.seg), *(a[:self.hits] for a in self.hit))


class PhotonTracer:
    """Traces `photons` photons in batches; iterate `batches()` to stream the records.

    A batch is cut into streams of photons (sizes fixed by the batch size alone), which worker
    threads trace through all their bounces independently: emission, then per bounce Embree on
    the stream's current rays and one compiled pass for their records and reflections. Finished
    streams are copied into the batch's record arrays in stream order (`_Records`)."""

    MAX_STREAM = 16384
    MIN_STREAM = 1024

    def __init__(self, scene: Scene, photons: int, bounces: int, seed: int = 0,
                 batch_size: int = 200_000, threads: int = 0, indirect_only: bool = False,
                 caster: Optional[RayCaster] = None, margin: float = 0.0, segments: bool = True):
        self.scene = scene
        self.bounces = int(bounces)
        # Whether batches carry their path segments (the DETP family reads them; the texel histogram
        # and the photon map read the hits alone): without, a batch's segments are counted, not copied.
        self.segments = bool(segments)
        # Leave out each photon's first flight (light to first surface) and where it lands: the
        # direct light, when it is sampled with shadow rays instead (direct.py).
        self.indirect_only = bool(indirect_only)
        self._shared_caster = caster
        self.batch_size = int(batch_size)
        # margin: how far past the geometry's footprint sun photons must start (lights.sun_emitter)
        self.schedule = BatchSchedule(build_emitters(scene, margin), int(photons), int(seed), self.batch_size)
        self.threads = threads or numba.config.NUMBA_NUM_THREADS
        self.centre, radius = scene.bounds()
        self.escape_radius = 1.1 * radius
        self.eps = max(1e-5 * radius, 1e-6)
        self.material_of, self.materials = material_table(scene.albedo)
        self.surfaces = surfaces(scene)
        self.stats = TraceStats()
        self.batches_done = 0
        self._caster: Optional[RayCaster] = None
        self._pool: Optional[ThreadPoolExecutor] = None
        # Records per photon, for the first batch's arrays: paths in a closed scene of the mean
        # survival probability; later batches go by what earlier ones made. (A batch that makes
        # more grows its arrays at the end.)
        q = survival(scene.albedo, scene.positions)
        self._per_photon = flights_per_photon(min(q, 0.95), min(self.bounces, 200), certain=self.indirect_only)
        self._per_photon_hits = self._per_photon

    @property
    def photons(self) -> int:
        return self.schedule.total

    @property
    def batch_count(self) -> int:
        return self.schedule.count

    @property
    def share(self) -> float:
        """The share of the bake traced so far: estimates of the batches so far, divided by it,
        are unbiased estimates of the whole."""
        return self.schedule.share(self.batches_done)

    @classmethod
    def stream_bounds(cls, n: int) -> list[tuple[int, int]]:
        """Streams of a batch of n photons: MAX_STREAM photons, then a quarter of what is left
        (at least MIN_STREAM), so the last streams are short and the threads finish together."""
        out, a = [], 0
        while a < n:
            size = min(n - a, max(cls.MIN_STREAM, min(cls.MAX_STREAM, (n - a) // 4)))
            out.append((a, a + size))
            a += size
        return out

    def batches(self, cancel: Optional[Callable[[], bool]] = None,
                indices: Optional[range] = None) -> Iterator[PhotonBatch]:
        """The batches in order, or batches `indices` (a range of batch numbers) only."""
        if self._caster is None:
            self._caster = self._shared_caster or RayCaster(self.scene.positions)
        if self.threads > 1:
            self._pool = ThreadPoolExecutor(self.threads)
        try:
            for index in range(self.batch_count) if indices is None else indices:
                if cancel is not None and cancel():
                    raise BakeCancelled()
                t0 = time.perf_counter()
                batch = self._trace_batch(index)
                self.stats.seconds += time.perf_counter() - t0
                self.batches_done = index + 1
                yield batch
        finally:
            if self._pool is not None:
                self._pool.shutdown(cancel_futures=True)
                self._pool = None
            self._caster = None

    def _trace_stream(self, records: _Records, index: int, batch: int, start: int, stop: int) -> None:
        """Photons [start, stop) of batch `batch` through all their bounces, in a free stream
        buffer, then into the batch's records as stream `index`."""
        try:
            st = _FREE.pop()
        except IndexError:
            st = _Stream()
        n = stop - start
        st.rays = st.hits = st.kept = 0
        st.skip_rays = st.skip_hits = st.skip_kept = 0
        st.passes = st.cut = st.first_hits = 0
        st.sums[:] = 0.0
        st.embree_seconds = 0.0
        st.reserve((3 if self.indirect_only else 2) * n, n)  # the first reflection is certain there
        self.schedule.emit(batch, start, stop, st.o, st.d, st.f, st.rng)
        st.length[:n] = RAY_FAR
        s, e, level = 0, n, 0
        st.rays = n
        srf = self.surfaces
        while e > s:
            st.reserve(e + (e - s), st.hits + (e - s))
            self._intersect(st, s, e)
            if srf.cutout:
                e = self._pass_cutouts(st, s, e)
                st.rays = e
                st.reserve(e + (e - s), st.hits + (e - s))
            w, st.hits, kept = bounce(s, e, st.prim, st.ng, st.bu, st.bv, st.through, st.o, st.d, st.f, st.length,
                                      st.rng, st.hit_pos, st.hit_dir, st.hit_flux, st.hit_nrm, st.hit_tri, st.hits,
                                      self.material_of, self.materials, srf.albedo_tex, srf.tex_uvs, srf.pixels,
                                      srf.info, level, self.bounces, self.centre, self.escape_radius, self.eps,
                                      st.sums, self.indirect_only)
            st.kept += kept
            if level == 0:
                st.first_hits = st.hits
                if self.indirect_only:
                    st.skip_rays, st.skip_hits, st.skip_kept = e, st.hits, st.kept
            s, e, st.rays = e, w, w
            level += 1
        records.add(index, st)

    def _intersect(self, st: _Stream, a: int, b: int) -> None:
        """Embree on log rays a … b−1: hit distances into `length`, the rest into the log."""
        t0 = time.perf_counter()
        r = self._caster.hits(st.o[a:b], st.d[a:b], st.length[a:b])
        st.embree_seconds += time.perf_counter() - t0
        st.prim[a:b] = r["primID"]
        st.ng[a:b] = r["Ng"]
        if self.surfaces.textured or self.surfaces.cutout:  # barycentrics are read for textures only
            st.bu[a:b] = r["u"]
            st.bv[a:b] = r["v"]
        st.through[a:b] = False

    def _pass_cutouts(self, st: _Stream, s: int, e: int) -> int:
        """Rays s … e−1 through cut-out surfaces, layer by layer (each pass traces only the rays
        that went through): returns the end of this flight's rays in the log."""
        srf = self.surfaces
        a, b = s, e
        for _ in range(MAX_PASSES):
            st.rays = b
            st.reserve(b + (b - a) + (e - s), st.hits + (e - s))
            w = pass_through(a, b, st.prim, st.bu, st.bv, st.through, st.o, st.d, st.f, st.length, st.rng,
                             srf.opacity, srf.opacity_tex, srf.tex_uvs, srf.pixels, srf.info, self.eps)
            if w == b:
                return b
            st.passes += w - b
            self._intersect(st, b, w)
            a, b = b, w
        st.cut += b - a  # the last ones stay where they landed, as if the surface were opaque
        return b

    def _trace_batch(self, index: int) -> PhotonBatch:
        start, stop = self.schedule.ids(index)
        n = stop - start
        bounds = self.stream_bounds(n)
        records = _Records(_SEGMENT_ARRAYS if self.segments else None, _HIT_ARRAYS, int(n * self._per_photon) + 1024,
                           int(n * self._per_photon_hits) + 1024, len(bounds), self.threads + 2)
        jobs = [(records, k, index, start + a, start + b) for k, (a, b) in enumerate(bounds)]
        if self._pool is None:
            for job in jobs:
                self._trace_stream(*job)
        else:
            for j in [self._pool.submit(self._trace_stream, *job) for job in jobs]:
                j.result()
        batch = records.close(n)
        tr = self.stats
        for rays, sums, embree, passes, cut, first, kept in records.stats:  # in stream order: no timing in the sums
            tr.rays += rays
            tr.segments += kept
            tr.photons_hit += first
            tr.alpha_passes += passes
            tr.alpha_cut += cut
            tr.absorbed += sums[0]
            tr.escaped += sums[1]
            tr.truncated += sums[2]
            tr.embree_seconds += embree
        tr.photons += n
        tr.emitted += self.schedule.emitted_flux * self.schedule.weight(index)
        tr.hits += batch.hit_count
        self._per_photon = 1.05 * records.segment_total / n + 0.01
        self._per_photon_hits = 1.05 * batch.hit_count / n + 0.01
        return batch
