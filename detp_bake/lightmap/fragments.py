"""Texels of charts too narrow for the denoiser, smoothed over their neighbours on the surface.

OIDN sees a lightmap as an image. A UV chart a few texels wide (Smart UV Project on a detailed mesh
makes thousands) is a scrap of an image to it: its neighbours in the image are other surfaces, and
its own surface goes on in other charts elsewhere in the atlas. Measured on a plane cut into 16 × 16
charts of 4 × 4 texels shuffled over the lightmap (tests/test_seams.py: a point light, every photon
through the texel histogram, 2M photons at 64²): OIDN left 10.6 % error per texel of the raw 11 % and
raised the mean by 1.4 %, where the same plane as one chart denoised to 2.2 %.

So the texels of a chart narrower than FRAGMENT texels (charts.chart_widths) are left out of OIDN's
runs and take instead a weighted mean of the values of the NEIGHBOURS texels nearest them in space,
of any chart of the same lightmap: those facing the same way (shading normals within COS) and seen
along the surface (a ray between the two, lifted LIFT texels off it, meets nothing: no wall stands
between; rays are cast only from texels whose lifted disc of reach some triangle crosses), weighted by their area and a Gaussian of SIGMA texels. For the texel histogram this is the
count of landings over a patch of surface about three texels wide, across the charts' seams. On the
plane above: 2.8 % error per texel, the mean within 0.3 %.

Where photons are few a texel (a small object at a fixed resolution: a chair's label, a sofa's legs),
one such mean is still noisy, and so is OIDN's image. So the mean is taken again over the last
pass's means (`passes_for`: as many passes as the lightmap's measured noise asks, noise.py), which
widens the kernel along the surface through the same neighbours and rays (no new ones, so no
wall is crossed), and a lightmap that can expect under STARVED_PHOTONS photons a texel has its
charts narrower than STARVED_WIDTH smoothed here instead of by OIDN (which still cleans a wide
chart best). On the
downloaded living room (benchmarks/race.py, 128² per object, 1M photons, against Cycles at 512
samples): 11.2 % error per texel with one pass and OIDN on every chart wide enough,
6.2 % so (the label 221 → 44 %, the legs 115 → 50 %, walls and floor unchanged).
"""
from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from ..sampling import jit
from ..bvh import TriangleTree
from ..kdtree import query_groups
from .texels import TexelSet, geometric_normals, lightmap_triangles
from .validity import blocked_between, whole_batches

FRAGMENT = 8.0  # texels: charts narrower than this (charts.py's width) are not denoised as an image
NEIGHBOURS = 24  # texels in each fragment texel's mean, itself included
SIGMA = 1.5  # the Gaussian's width, texel sizes; neighbours beyond 3 SIGMA are left out
COS = 0.9  # shading normals at least this aligned count as one surface
PASS_NOISE = 0.33  # relative noise (noise.py) up to which fragments take one weighted mean (passes_for)
MAX_PASSES = 32  # the most weighted means taken in turn: each widens the kernel along the surface
STARVED_PHOTONS = 8.0  # photons a texel (by area) under which a lightmap's charts up to STARVED_WIDTH skip OIDN
STARVED_WIDTH = 32.0  # texels: a starved lightmap's charts narrower than this skip OIDN (wider ones it still
# cleans best: a 64-texel plane at 10 photons a texel, 7.9 % per texel by OIDN, 10.5 % smoothed)
LIFT = 0.25  # texel sizes: rays between neighbours pass this far above the surface (over a convex curve's chord)
BATCH = 1 << 15  # fragment texels (of whole lightmaps) found at once: 6 MB an (F, K) float64 array


@dataclass
class Fragments:
    """For one lightmap: its fragment texels (`pixel`, flat indices into its image) and each one's
    neighbours (`neighbour`, flat pixel indices) with their weights (`weight`, 0 for none)."""
    pixel: np.ndarray  # (F,) int64
    neighbour: np.ndarray  # (F, K) int32
    weight: np.ndarray  # (F, K) float32
    passes: int = 1  # weighted means taken in turn (smooth)

    def __len__(self) -> int:
        return len(self.pixel)

    def smooth(self, image: np.ndarray, passes: int | None = None) -> np.ndarray:
        """(F, 3) float32: each fragment texel's weighted mean of its neighbours in `image` (H, W, 3),
        taken `passes` times (the lightmap's, passes_for, by default), each pass over the last one's means where the
        neighbour is itself a fragment texel (module docstring)."""
        flat = np.ascontiguousarray(image.reshape(-1, image.shape[-1]), np.float32)
        row = np.full(len(flat), -1, np.int32)
        row[self.pixel] = np.arange(len(self.pixel), dtype=np.int32)
        out = np.empty((len(self.pixel), flat.shape[1]), np.float32)
        _passes(flat, self.neighbour, self.weight, row[self.neighbour], self.passes if passes is None else passes, out)
        return out


@jit
def _passes(flat, neighbour, weight, row, passes, out):
    """`passes` weighted means of each fragment texel's neighbours (`neighbour`, flat pixel
    indices into `flat`; `row`, their rows among the fragment texels, −1 for a texel that is
    not one and keeps its value in `flat`), the last into `out`. Sums in float64."""
    f_count, k_count, c_count = neighbour.shape[0], neighbour.shape[1], flat.shape[1]
    now = np.empty((f_count, c_count))
    last = np.empty((f_count, c_count))
    for p in range(passes):
        for f in range(f_count):
            total = 0.0
            for c in range(c_count):
                now[f, c] = 0.0
            for k in range(k_count):
                w = np.float64(weight[f, k])
                if w == 0.0:
                    continue
                total += w
                r = row[f, k]
                for c in range(c_count):
                    now[f, c] += w * (last[r, c] if p > 0 and r >= 0 else np.float64(flat[neighbour[f, k], c]))
            for c in range(c_count):
                now[f, c] = now[f, c] / total if total > 0.0 else 0.0
        now, last = last, now
    for f in range(f_count):
        for c in range(c_count):
            out[f, c] = np.float32(last[f, c])


def chart_widths_of(texels: TexelSet, scene, lightmaps) -> np.ndarray:
    """(T,) float64: the width in texels (charts.py) of each scene triangle's chart in its lightmap,
    for the triangles of `lightmaps` (inf elsewhere), as the rasteriser found them
    (Lightmap.triangle_widths)."""
    width = np.full(len(scene.positions), np.inf)
    for lm in lightmaps:
        width[lightmap_triangles(scene, lm)] = lm.triangle_widths
    return width


def passes_for(noise) -> int:
    """How many weighted means a lightmap's fragments take in turn (Fragments.smooth), from its
    measured relative noise (noise.py; None when unmeasured): one at PASS_NOISE or less, then as
    the variance grows, up to MAX_PASSES."""
    if noise is None or not noise > PASS_NOISE:
        return 1
    return int(min(MAX_PASSES, round((noise / PASS_NOISE) ** 2)))


def starved_lightmaps(texels: TexelSet, scene, photons: int) -> frozenset:
    """Names of the lightmaps that can expect fewer than STARVED_PHOTONS photons a texel, the bake's
    `photons` dealt out by surface area (their texels' area over all the scene's triangles'),
    known before tracing: small objects at a fixed resolution."""
    p = np.asarray(scene.positions, np.float64)
    total = 0.5 * float(np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum())
    if not (photons > 0 and total > 0.0):
        return frozenset()
    return frozenset(lm.name for lm in texels.lightmaps
                     if lm.count and photons * float(texels.area[lm.texels].sum()) / total / lm.count < STARVED_PHOTONS)


def set_passes(found: dict, noise: dict) -> None:
    """Each lightmap's fragments (`found`: {name: Fragments or None}) take passes_for its measured
    noise (`noise`: {name: noise.py's figure}, as far as measured), once the photons are traced."""
    for name, fragments in found.items():
        if fragments is not None:
            fragments.passes = passes_for(noise.get(name))


def find(texels: TexelSet, lm, scene, caster, threads: int = 1, starved: bool = False) -> Fragments | None:
    """The fragments of lightmap `lm` and their neighbours (module docstring), or None when it has
    none: the texels of its charts narrower than FRAGMENT texels, or than STARVED_WIDTH for a
    `starved` lightmap (starved_lightmaps)."""
    return find_all(texels, scene, caster, threads, {lm.name} if starved else (), [lm])[lm.name]


def find_all(texels: TexelSet, scene, caster, threads: int = 1, starved=(), lightmaps=None) -> dict:
    """{name: `find` of each lightmap of `lightmaps` (all by default)}, `starved` the names of the
    starved ones, found in one pass over every lightmap: one chart pass, one tree walk for the
    neighbours, one for the discs and one call for the rays, then sliced by lightmap (1,500 small
    objects, one pass each, took seconds)."""
    lightmaps = texels.lightmaps if lightmaps is None else lightmaps
    at = {lm.name: i for i, lm in enumerate(texels.lightmaps)}
    narrower = np.zeros(len(texels.lightmaps))
    for lm in lightmaps:
        narrower[at[lm.name]] = STARVED_WIDTH if lm.name in starved else FRAGMENT
    frag = np.flatnonzero(chart_widths_of(texels, scene, lightmaps)[texels.triangle] < texels.per_texel(narrower))
    out = {lm.name: None for lm in lightmaps}
    if frag.size == 0:
        return out
    start = np.array([lm.offset for lm in texels.lightmaps], np.int64)
    count = np.array([lm.count for lm in texels.lightmaps], np.int64)
    size = np.array([lm.texel_size for lm in texels.lightmaps], np.float64)
    group = np.searchsorted(start + count, frag, side="right")  # each fragment texel's lightmap
    ends = np.searchsorted(group, np.arange(len(start) + 1))  # each lightmap's rows of `frag`
    near, weight = np.zeros((len(frag), NEIGHBOURS), np.int32), np.zeros((len(frag), NEIGHBOURS), np.float32)
    # Whole lightmaps at a time, about BATCH fragment texels: their (F, K) float64 arrays stay small.
    bounds = np.unique(ends[whole_batches(ends, BATCH)])  # lightmaps without fragments make no empty batch
    triangles = TriangleTree(scene.positions)
    for a, b in zip(bounds[:-1], bounds[1:]):
        n, w = _neighbours(texels, scene, caster, threads, frag[a:b], group[a:b], start, count, size, triangles)
        near[a:b, :n.shape[1]], weight[a:b, :n.shape[1]] = texels.pixel[n], w
    frag_pixel = texels.pixel[frag].astype(np.int64)
    for lm in lightmaps:
        g = at[lm.name]
        a, b, k = ends[g], ends[g + 1], min(NEIGHBOURS, lm.count)
        if b > a:
            out[lm.name] = Fragments(frag_pixel[a:b], np.ascontiguousarray(near[a:b, :k]),
                                     np.ascontiguousarray(weight[a:b, :k]))
    return out


def _neighbours(texels, scene, caster, threads, frag, group, start, count, size, triangles) -> tuple:
    """((F, K) texels, (F, K) float32 weights) of the fragment texels `frag` (in lightmaps `group`,
    whose texels run from `start`, `count` of them, `size` metres wide; K the most any of them
    takes): the nearest of their own lightmap within 3 SIGMA, facing the same way and seen along
    the surface (`triangles`: the scene's TriangleTree), each texel itself with weight 1 where it
    has no other (a row past its lightmap's count ends in weights 0)."""
    pos, nrm = texels.position, texels.normal
    own = size[group]
    dist, near = query_groups(pos, start, count, pos[frag], group, np.minimum(NEIGHBOURS, count),
                              3 * SIGMA * size)
    found = np.empty(near.shape, np.bool_)
    _facing(nrm, frag, near, found)
    # A ray from a texel to a neighbour can be blocked only where some triangle crosses the disc of
    # its reach lifted off the surface: most texels of an open floor need no rays.
    g = geometric_normals(scene, texels.triangle[frag], nrm[frag])
    lifted = pos[frag] + (LIFT * own)[:, None] * g
    crossed = triangles.discs_meet(lifted, g, 3 * SIGMA * own)
    other = found & (near != frag[:, None]) & crossed[:, None]
    f, j = np.nonzero(other)
    if f.size:
        blocked, _ = blocked_between(texels, frag[f], near[f, j], LIFT * own[f], caster, scene, threads)
        found[f, j] = ~blocked
    weight = np.empty(near.shape, np.float32)
    _weights(found, near, dist, texels.area, SIGMA * own, frag, weight)
    return near, weight


@numba.njit(cache=True, parallel=True)
def _facing(nrm, frag, near, found):
    """Per fragment texel and neighbour found (`near` < the texel count; the others become the
    texel itself), whether their shading normals lie within COS: `found`, in place of two (F, K)
    gathers (a million fragment texels' (F, K, 3) normals were 2 GB)."""
    n = nrm.shape[0]
    for f in numba.prange(near.shape[0]):
        a = frag[f]
        for k in range(near.shape[1]):
            b = near[f, k]
            if b >= n:
                near[f, k] = a
                found[f, k] = False
                continue
            d = nrm[a, 0] * nrm[b, 0] + nrm[a, 1] * nrm[b, 1] + nrm[a, 2] * nrm[b, 2]
            found[f, k] = d >= COS


@numba.njit(cache=True, parallel=True)
def _weights(found, near, dist, area, sigma, frag, weight):
    """Each neighbour's weight: its texel's area times a Gaussian of its distance (`sigma` metres
    per fragment texel), 0 where not found; a texel whose weights sum to nothing (no area, every
    neighbour hidden) keeps its own value (weight 1 on itself)."""
    for f in numba.prange(near.shape[0]):
        total = 0.0
        for k in range(near.shape[1]):
            w = 0.0
            if found[f, k]:
                x = dist[f, k] / sigma[f]
                w = np.float64(area[near[f, k]]) * np.exp(-0.5 * x * x)
            total += w
            weight[f, k] = np.float32(w)
        if not total > 0.0:
            near[f, 0] = frag[f]
            weight[f, 0] = np.float32(1.0)
