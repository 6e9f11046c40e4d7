"""How much memory a bake will need, said before any long work, and what it really used.

The peak is the sum of what lives at once: the texels (their records, the lightmap images before
and after denoising, the direct light), the estimator's per-texel state, the denoiser's scratch
and images for the largest lightmap (beyond the estimator state let go before it), a few photon
batches (the one being filled, the one being estimated, a spare: photons.py), each thread's
stream log, and for the photon map every stored hit. Batches are bounded in segments, not
photons (`batch_photons`): in a closed white room with a thousand bounces a photon makes a
thousand segments, and a batch of 100,000 photons would need gigabytes.
"""
from __future__ import annotations

import os
import sys

try:
    import resource
except ImportError:  # Windows
    resource = None
from dataclasses import dataclass

from .. import estimators
from ..errors import BakeError
from ..lightmap import denoise as denoise_mod, texels as texels_mod
from ..transport.photons import PhotonTracer

SEGMENT_BYTES = 40  # origin, direction, length, flux (float32)
HIT_BYTES = 52  # position, direction, flux, normal (float32), triangle
STREAM_RAY_BYTES = 73  # a stream's log row: ray, flux, random state, Embree's answer, flags
BATCH_SETS = 3  # record sets alive at once (photons._ArrayPool.KEEP)
# Per texel (charged per pixel: an upper bound) whatever the estimator: the TexelSet row (float64
# position and normal, int32 triangle and pixel, float32 area, a flag: 61) and the direct light and
# E/π (float32 RGB, 24). What an estimator adds (its discs, index and sums, the discs' clearance,
# the sums in flight, the noise sums, what its build leaves behind) is its `bytes_per_texel`.
# Measured with benchmarks/memory.py (2048², a 5 % gutter): a disc_index bake needed about 500
# bytes a texel before issue 10's cuts, about 300 after; the figures here are 1.1 times the
# measured peaks, so the estimate stays above them when every pixel is a texel.
# Since texel validity (validity.py): its cut index and moved and covered flags (6), the sharp
# lights' part of the direct light (12) and the region labels (4).
TEXEL_BYTES = 61 + 2 * 12 + 6 + 12 + 4
# The dilated lightmap image (float32 RGB), its area weights for the denoiser's means and two masks;
# the image before denoising is made only when asked (results.RawImages).
PIXEL_BYTES = 12 + 4 + 2
# Denoising, one lightmap at a time: OIDN's scratch, about 560 bytes a pixel of an image it gets
# whole, and it gets at most denoise.tile_for(pixels)² at once (464² from 1024² up: at most 115 MB;
# at 2048² its tiles of up to 464² took 87 MB; 720² up to 1024²: at most 290 MB), and the float32
# images the denoiser works on beside it: the part being denoised (OIDN writes over it), the part
# denoised before it, the sharp lights' part added after.
OIDN_BYTES_PER_PIXEL = 560
OIDN_MOST = 115_000_000  # for tiles of denoise.TILE², in proportion for wider ones
# Measured (benchmarks/memory.py, 2048², 5 % gutter, 2 cores; benchmarks/measured/memory.json): the
# texel histogram at 1M photons peaks at 106 bytes a texel (348 before the tiles and the cuts that
# came with them; its positions and normals are set aside from tracing to the last image); the
# estimate (each part at its own peak, summed) says 240.
DENOISE_PIXEL_BYTES = 3 * 12 + 6
# --directional (lightmap/sh.py): nine more channels a texel: the estimator's float64 sums and the
# copy a take hands over (2 × 72), the shadow rays' L1 and its sharp part (2 × 36, float32), the
# per-texel value (36), and per pixel the raw, denoised and written images (3 × 36).
DIRECTIONAL_BYTES = 2 * 72 + 2 * 36 + 36 + 3 * 36
# --shadowmask: four float32 channels a texel (the visibility), its image and the dilated copy.
# Measured (benchmarks/memory.py --directional sh [--shadowmask], 2048², 5 % gutter, OIDN): the
# texel histogram peaks at 341 bytes a texel plain, 675 with sh, 373 with the shadowmask, 709 with
# both (estimates 504, 948, 563, 1007); disc_index with both at 741 (estimate 1007). The L1 peak is
# the clamp's float64 norms while the images are made; both figures stay as they are.
SHADOWMASK_BYTES = 3 * 16
# What a triangle costs beyond the scene's own arrays while a bake runs: the export's evaluated
# copies, Embree's tree and the triangle tree of validity, and the chart analysis of the rasteriser
# (its corners and edges, a moment). Measured on grids of 0.25M and 1M triangles at 16² (the peak of
# the bake's process less that of one that only opens the file): 873 bytes a triangle in all, 657
# beyond the arrays counted apart; 1.1 times that here.
TRIANGLE_BYTES = 720
MAX_BATCH_SEGMENTS = 4_000_000  # segments one batch may hold (160 MB of records per set)
MIN_BATCH = 1000


def batch_photons(asked: int, per_photon: float) -> int:
    """Photons per batch: as asked, but no more than MAX_BATCH_SEGMENTS segments' worth."""
    return int(max(MIN_BATCH, min(asked, MAX_BATCH_SEGMENTS / max(per_photon, 1e-9))))


@dataclass
class Estimate:
    texels: int
    parts: dict  # what -> bytes

    @property
    def total(self) -> int:
        return int(sum(self.parts.values()))

    def biggest(self) -> str:
        what, size = max(self.parts.items(), key=lambda kv: kv[1])
        return f"{what} {size / 1e6:,.0f} MB"


def estimate(pixels: int, estimator_bytes: dict, batch: int, per_photon_all: float, per_photon_kept: float,
             threads: int, stored_hits: int = 0, geometry_bytes: int = 0, denoised_pixels: int = 0,
             directional: bool = False, shadowmask: bool = False, probe_bytes: int = 0) -> Estimate:
    """pixels: the lightmaps' pixels (an upper bound on texels, and on the estimators' sites,
    sites.py, which leave them about half the texels of a large lightmap); estimator_bytes: {name:
    bytes per texel}; batch: photons per batch; per_photon_all / per_photon_kept: segments a photon
    makes / hands to the estimator; stored_hits: hits the photon map keeps; denoised_pixels: the largest
    lightmap's pixels when lightmaps are denoised (one at a time), else 0; directional: L1 is baked
    too (DIRECTIONAL_BYTES a pixel); probe_bytes: the light probes' records and their gather's
    scratch (probes/placement.cost)."""
    parts = {
        "texels": pixels * TEXEL_BYTES,
        "lightmap images": pixels * PIXEL_BYTES,
        "photon batches": int(BATCH_SETS * batch * per_photon_kept * (SEGMENT_BYTES + HIT_BYTES)),
        # A thread's stream logs every flight of its photons (growing by half when full).
        "stream logs": int(threads * min(PhotonTracer.MAX_STREAM, batch) * max(per_photon_all, 1.0) * 1.5
                           * STREAM_RAY_BYTES),
        "geometry": geometry_bytes,
    }
    for name, per_texel in estimator_bytes.items():
        parts[f"estimator {name} texels"] = int(pixels * per_texel)  # its state per texel
    if directional:
        parts["directional maps"] = pixels * DIRECTIONAL_BYTES
    if shadowmask:
        parts["shadowmask"] = pixels * SHADOWMASK_BYTES
    if probe_bytes:
        parts["light probes"] = int(probe_bytes)
    if stored_hits:
        parts["photon map hits"] = stored_hits * HIT_BYTES
    if denoised_pixels:
        # Each estimator is let go before its lightmaps are denoised (bake.py): the denoiser needs
        # only what is more than the smallest estimator's state, which it takes over.
        widest = (denoise_mod.tile_for(denoised_pixels) / denoise_mod.TILE) ** 2
        denoiser = min(denoised_pixels * OIDN_BYTES_PER_PIXEL, int(OIDN_MOST * widest)) \
            + denoised_pixels * DENOISE_PIXEL_BYTES
        freed = min((pixels * b for b in estimator_bytes.values()), default=0)
        parts["denoiser"] = int(max(0, denoiser - freed))
    return Estimate(pixels, parts)


def _proc_kib(path: str, key: str):
    """Bytes of a "Key: N kB" line of a Linux /proc file, or None where there is none."""
    try:
        with open(path) as f:
            for line in f:
                if line.startswith(key + ":"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def available_bytes() -> int:
    """Memory the system could give now (MemAvailable), or 0 when it cannot say."""
    free = _proc_kib("/proc/meminfo", "MemAvailable")
    if free is not None:
        return free
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return 0


def geometry_budget(memory_budget_mb: int = 0) -> int:
    """Bytes the flattened scene geometry may take: half the bake's budget (the setting, else
    80 % of free memory), so the texels and photons keep the rest; 0 when unknown."""
    budget = memory_budget_mb * 1e6 if memory_budget_mb else 0.8 * available_bytes()
    return int(0.5 * budget)


def peak_bytes() -> int:
    """This process's peak resident memory so far (0 where the system cannot say). Linux's
    VmHWM first: getrusage's ru_maxrss carries over from the parent through fork and exec, so a
    bake started by a large process (a test run) would report that process's peak."""
    peak = _proc_kib("/proc/self/status", "VmHWM")
    if peak is not None:
        return peak
    if resource is None:
        return 0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(peak if sys.platform == "darwin" else peak * 1024)


MMAP_THRESHOLD = 1 << 20  # bytes: blocks this large and larger are mapped apart (`return_large_blocks`)
_M_MMAP_THRESHOLD = -3  # glibc's mallopt parameter number


def return_large_blocks() -> bool:
    """Have glibc's malloc map every block of MMAP_THRESHOLD or more apart, so that an array the
    bake frees goes back to the system at once (mallopt; other C libraries: nothing). By default
    glibc raises that threshold, up to 32 MB, each time a mapped block is freed; after that the
    per-texel arrays of a 2048² lightmap (3 to 27 MB each) come from the heap, and the holes they
    leave there when freed keep the resident size up: a 2048² ground quad peaked 34 bytes a texel
    higher (205 against 171, benchmarks/memory.py). The setting stays for the process (Blender's
    own large blocks are then mapped too: a page fault or two more per block). True when set."""
    global _returning
    if _returning is None:
        _returning = False
        try:
            import ctypes
            import ctypes.util
            name = ctypes.util.find_library("c")
            libc = ctypes.CDLL(name) if name and sys.platform.startswith("linux") else None
            _returning = bool(libc is not None and hasattr(libc, "mallopt")
                              and libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD) == 1)
        except OSError:
            pass
    return _returning


_returning = None


def reset_peak() -> None:
    """Start this process's peak (`peak_bytes`) again from its present size, where Linux allows it
    (writing 5 to /proc/self/clear_refs): a bake's report then gives its own peak, not that of
    whatever the process (Blender, a test session) did before it."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        pass


def check(scene, settings, names, batch, per_photon, per_photon_kept, probe_bytes: int = 0) -> Estimate:
    """The bake's peak memory, estimated before any work; over the budget (the setting, else 80 %
    of what the system has free) it is a BakeError that says what to lower."""
    # One image per lightmap: an atlas's objects share theirs (each carries the atlas's resolution).
    sizes = [int(scene.objects[members[0]].resolution) ** 2 for _, members in texels_mod.images(scene)]
    pixels = sum(sizes)
    per_texel = {n: estimators.get(n).bytes_per_texel for n in names}
    hits = int(settings.photons * per_photon_kept) if any(estimators.get(n).stores_hits for n in names) else 0
    geometry = scene.positions.nbytes + scene.normals.nbytes + scene.uvs.nbytes + \
        (24 + TRIANGLE_BYTES) * scene.triangle_count
    denoised = max(sizes, default=0) if settings.denoise and denoise_mod.available() else 0
    need = estimate(pixels, per_texel, batch, per_photon, per_photon_kept,
                           settings.threads or os.cpu_count() or 1, hits, geometry, denoised,
                           settings.directional != "none", bool(settings.shadowmask), probe_bytes)
    budget = settings.memory_budget_mb * 1e6 if settings.memory_budget_mb else 0.8 * available_bytes()
    if budget and need.total > budget:
        advice = []
        if hits and need.parts.get("photon map hits", 0) > 0.3 * need.total:
            advice.append("a DETP estimator (they stream photons) or fewer photons")
        per_pixel = need.parts["texels"] + need.parts["lightmap images"] + need.parts.get("denoiser", 0)
        if per_pixel > 0.3 * need.total:
            advice.append("a lower resolution")
        if need.parts["photon batches"] + need.parts["stream logs"] > 0.3 * need.total:
            advice.append("fewer bounces or a smaller batch")
        raise BakeError(f"this bake would need about {need.total / 1e9:,.1f} GB of memory (the most: "
                        f"{need.biggest()}), over the budget of {budget / 1e9:,.1f} GB"
                        f"{' (the memory budget preference)' if settings.memory_budget_mb else ' (80 % of free memory)'}"
                        f": use {' or '.join(advice) or 'a smaller bake'}")
    return need
