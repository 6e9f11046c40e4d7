"""Sites: the texels where the indirect light is estimated, every `spacing`-th of each lightmap.

Indirect light is smooth, and the DETP disc already averages it over a few texels, so estimating
it at every texel buys nothing the disc has not blurred away. What an estimate costs grows with the
discs a segment crosses, that is with the disc density: estimating on every second texel in each
direction, with the same disc radius in metres, crosses a quarter of the discs for the same noise
per site. The texels between sites take the bilinear blend of their four lattice corners
(texel (i, j) of lattice cell (i0, j0) … (i0 + s, j0 + s)) when every corner it needs lies inside
a chart (it and its four neighbours covered) and on the same surface: facing within NORMAL_COS of
the texel's normal, and within REACH lattice steps in metres (a UV neighbour from another chart is
usually neither). Otherwise, along chart borders, the texel becomes a site itself: every texel's
value comes from its own surface, blended only inside the lattice (which reproduces linear light
exactly), never extrapolated. Border texels are never corners: light bends there within a texel
(a concave corner, a cut disc), and blending them into the row beside them took the L-shaped
room's blended texels 1.3 % low at 32² (measured).

The sites form a TexelSet of their own: lattice sites keep their lattice (pixel (i/s, j/s) of a
lightmap s times smaller, so lattice patches still find them), the extra sites follow below it,
one per row, and every lightmap keeps its texel size, so disc radii stay the same in metres.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numba
import numpy as np

from ..options import AUTO_FROM, AUTO_SPACING
from .texels import TexelSet

NORMAL_COS = 0.9  # corners facing further away than about 25° are another surface
REACH = 2.0  # a corner further than REACH × spacing × texel size is another surface
# Spacing 0 (automatic): AUTO_SPACING on lightmaps of AUTO_FROM² pixels and more, every texel below.
# The estimate's cost is set by the segments, not the discs (a segment's walk through the disc
# index is about as long over half the discs), so sites save the passes per texel: disc clearance
# and rise, which grow with the texels. L-shaped room, against a 16M-photon bake, 2 cores: at 256²
# 20 % less time and 0.4-1.6 % lower RMSE; at 128² 5-10 % less time and 2 % higher RMSE; at 64²
# the same time and 3 % higher RMSE. (Declared in options.py, with the setting.)


@dataclass
class Sites:
    texels: TexelSet  # the sites, as a TexelSet for the estimators
    index: np.ndarray  # (M,) each site's texel in the full set (empty when every texel is a site)
    source: np.ndarray  # (N, 4) int32: the sites each texel blends (0 where unused; empty likewise)
    weight: np.ndarray  # (N, 4) float64: their weights (sum 1 per texel; empty likewise)
    spacing: int  # the largest of the lightmaps' spacings (1: every texel is a site)

    def expand(self, values: np.ndarray) -> np.ndarray:
        """(M, C) per site → (N, C) per texel (the same array when every texel is a site)."""
        if self.spacing <= 1:
            return values
        return _blend(np.ascontiguousarray(values, np.float64), self.source, self.weight)

    def of_sites(self, per_texel: np.ndarray) -> np.ndarray:
        """(N, …) per texel → (M, …) the sites' own rows (no copy when every texel is a site)."""
        return per_texel if self.spacing <= 1 else per_texel[self.index]


def every_texel(texels: TexelSet) -> Sites:
    """Every texel its own site: `expand` and `of_sites` pass arrays through, so the blend tables
    stay empty (at 2048² they would hold 56 bytes a texel for nothing)."""
    return Sites(texels, np.empty(0, np.int64), np.empty((0, 4), np.int32), np.empty((0, 4)), 1)


def spacings(texels: TexelSet, spacing: int) -> list:
    """Each lightmap's spacing: `spacing`, or for 0 the automatic one by the lightmap's size."""
    if spacing:
        return [int(spacing)] * len(texels.lightmaps)
    return [AUTO_SPACING if lm.width * lm.height >= AUTO_FROM ** 2 else 1 for lm in texels.lightmaps]


def choose(texels: TexelSet, spacing: int) -> Sites:
    """Sites every `spacing` texels (1: every texel is a site; 0: by each lightmap's size)."""
    each = spacings(texels, spacing)
    if max(each, default=1) <= 1 or len(texels) == 0:
        return every_texel(texels)
    n = len(texels)
    is_site = np.zeros(n, np.bool_)
    corner = np.full((n, 4), -1, np.int64)  # corner texels, in the full set
    weight = np.zeros((n, 4))
    for lm, s in zip(texels.lightmaps, each):
        sl = lm.texels
        grid = np.full(lm.width * lm.height, -1, np.int64)
        grid[texels.pixel[sl]] = np.arange(lm.offset, lm.offset + lm.count)
        _corners(texels.pixel[sl], lm.width, lm.height, s, grid, texels.position, texels.normal,
                 texels.centre_inside, REACH * s * lm.texel_size, NORMAL_COS, corner[sl], weight[sl], is_site[sl])
    index = np.flatnonzero(is_site)
    site_of = np.full(n, -1, np.int64)
    site_of[index] = np.arange(len(index))
    source = np.where(corner >= 0, site_of[np.maximum(corner, 0)], 0).astype(np.int32)
    weight[corner < 0] = 0.0
    weight /= weight.sum(axis=1, keepdims=True)
    return Sites(_site_texels(texels, index, each), index, source, weight, max(each))


@numba.njit(cache=True)
def _same(position, normal, a, b, reach2, cos_min):
    """Texels a and b lie on one surface: facing alike and close in metres."""
    d2 = 0.0
    dot = 0.0
    for c in range(3):
        d2 += (position[a, c] - position[b, c]) ** 2
        dot += normal[a, c] * normal[b, c]
    return d2 <= reach2 and dot >= cos_min


@numba.njit(cache=True)
def _inner(grid, i, j, width, height, position, normal, centre_inside, step2, cos_min):
    """Texel (i, j) lies inside its chart: its centre on the surface, and its four neighbours covered
    and on its surface (within `step2`, a squared texel step in metres)."""
    if i == 0 or j == 0 or i + 1 >= width or j + 1 >= height:
        return False
    q = grid[j * width + i]
    if not centre_inside[q]:
        return False
    for n in (grid[j * width + i - 1], grid[j * width + i + 1], grid[(j - 1) * width + i], grid[(j + 1) * width + i]):
        if n < 0 or not _same(position, normal, q, n, step2, cos_min):
            return False
    return True


@numba.njit(cache=True)
def _corners(pixel, width, height, s, grid, position, normal, centre_inside, reach, cos_min, corner, weight, is_site):
    """Per texel of one lightmap: its lattice corners on the same surface, their bilinear weights,
    and whether it must be a site itself (a lattice point, or no corner on its surface)."""
    reach2 = reach * reach
    step2 = reach2 / (s * s)
    for k in range(pixel.shape[0]):
        t = grid[pixel[k]]
        i, j = pixel[k] % width, pixel[k] // width
        i0, j0 = (i // s) * s, (j // s) * s
        fx, fy = (i - i0) / s, (j - j0) / s
        whole = True
        for c in range(4):
            ci, cj = i0 + s * (c & 1), j0 + s * (c >> 1)
            w = (fx if c & 1 else 1.0 - fx) * (fy if c >> 1 else 1.0 - fy)
            if w <= 0.0:
                continue
            q = grid[cj * width + ci] if ci < width and cj < height else -1
            if q >= 0 and q != t:
                if not _same(position, normal, q, t, reach2, cos_min) or \
                        not _inner(grid, ci, cj, width, height, position, normal, centre_inside, step2, cos_min):
                    q = -1  # another surface, or a border texel, whose light bends within the texel
            if q < 0:
                whole = False
                break
            corner[k, c] = q
            weight[k, c] = w
        if i == i0 and j == j0:
            is_site[k] = True  # its own corner, weight 1
        elif not whole:  # blending fewer corners would extrapolate: estimate it here instead
            is_site[k] = True
            for c in range(4):
                corner[k, c] = -1
                weight[k, c] = 0.0
            corner[k, 0] = t
            weight[k, 0] = 1.0


def _site_texels(texels: TexelSet, index: np.ndarray, each: list) -> TexelSet:
    """The sites as a TexelSet: lattice sites at pixel (i/s, j/s) of a lightmap s times smaller,
    extra sites below it in column 0, one per row: no two sites share a pixel, and sites in one
    column never form a lattice patch (patches.py), whatever their places."""
    pixel = np.empty(len(index), np.int64)
    lightmaps = []
    offset = 0
    for lm, s in zip(texels.lightmaps, each):
        mine = index[(index >= lm.offset) & (index < lm.offset + lm.count)]
        p = texels.pixel[mine]
        i, j = p % lm.width, p // lm.width
        width, height = -(-lm.width // s), -(-lm.height // s)
        on = (i % s == 0) & (j % s == 0)
        extra = np.cumsum(~on) - 1
        sub = np.where(on, (j // s) * width + i // s, (height + extra) * width)
        pixel[offset:offset + len(mine)] = sub
        rows = height + int((~on).sum())
        lightmaps.append(replace(lm, width=width, height=rows, offset=offset, count=len(mine)))
        offset += len(mine)
    return TexelSet(texels.position[index], texels.normal[index], texels.triangle[index], pixel,
                    texels.area[index], texels.centre_inside[index], lightmaps,
                    None if texels.cuts is None else texels.cuts.select(index))


@numba.njit(cache=True)
def _blend(values, source, weight):
    out = np.zeros((source.shape[0], values.shape[1]))
    for k in range(source.shape[0]):
        for c in range(4):
            w = weight[k, c]
            if w != 0.0:
                for a in range(values.shape[1]):
                    out[k, a] += w * values[source[k, c], a]
    return out
