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

import numpy as np

from .charts import chart_widths
from ..sampling import jit
from ..bvh import discs_meet_triangles
from ..kdtree import KDTree
from .texels import TexelSet, geometric_normals, lightmap_triangles
from .validity import blocked_between

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


def fragment_texels(texels: TexelSet, lm, scene, narrower: float = FRAGMENT) -> np.ndarray:
    """Indices (within lightmap `lm`'s texels) of those whose triangle's chart is narrower than
    `narrower` texels."""
    sl = lightmap_triangles(scene, lm)
    chart, width = chart_widths(scene.uvs[sl], scene.positions[sl], lm.width)
    own = np.searchsorted(sl, texels.triangle[lm.texels])
    return np.flatnonzero(width[chart[own]] < narrower)


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
    local = fragment_texels(texels, lm, scene, STARVED_WIDTH if starved else FRAGMENT)
    if local.size == 0:
        return None
    sl = lm.texels
    pos = texels.position[sl]
    size = lm.texel_size
    k = min(NEIGHBOURS, lm.count)
    dist, near = KDTree(pos).query(pos[local], k, distance_upper_bound=3 * SIGMA * size)
    dist, near = dist.reshape(len(local), k), near.reshape(len(local), k)
    found = near < lm.count
    near = np.where(found, near, local[:, None])
    nrm = texels.normal[sl]
    found &= np.einsum("fc,fkc->fk", nrm[local], nrm[near]) >= COS
    # A ray from a texel to a neighbour can be blocked only where some triangle crosses the disc of
    # its reach lifted off the surface: most texels of an open floor need no rays.
    tri = texels.triangle[sl]
    g = geometric_normals(scene, tri[local], nrm[local])
    lifted = pos[local] + LIFT * size * g
    crossed = discs_meet_triangles(scene.positions, lifted, g, np.full(len(local), 3 * SIGMA * size))
    other = found & (near != local[:, None]) & crossed[:, None]
    f, j = np.nonzero(other)
    if f.size:
        blocked, _ = blocked_between(texels, local[f] + lm.offset, near[f, j] + lm.offset, LIFT * size, caster,
                                     scene, threads)
        found[f, j] = ~blocked
    area = texels.area[sl]
    weight = np.where(found, area[near] * np.exp(-0.5 * (np.where(found, dist, 0.0) / (SIGMA * size)) ** 2), 0.0)
    alone = ~(weight.sum(axis=1) > 0)  # a texel of no area with every neighbour hidden keeps its own value
    near[alone, 0], weight[alone, 0] = local[alone], 1.0
    pixel = texels.pixel[sl].astype(np.int64)
    return Fragments(pixel[local], pixel[near].astype(np.int32), weight.astype(np.float32))
