"""The exact Euclidean distance from each pixel of a 2D image to its nearest feature pixel, and which
pixel that is, in compiled code: the denoiser's gutter texels take their nearest covered texel's
region. Two passes of nearest-site sweeps (columns, then rows, each keeping the lower envelope of the
parabolas of the sites before it); where two feature pixels are equally near, the choice is the one
scipy's `distance_transform_edt` makes (the earlier along the sweep), so regions and bakes keep their
bytes. The extension ships no scipy."""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def _columns(feature, fr):
    """fr[r, c]: the row of the nearest feature pixel in column c (the upper one of two as near),
    -1 in a column with none."""
    h, w = feature.shape
    for c in range(w):
        last = -1
        for r in range(h):  # nearest above or at r
            if feature[r, c]:
                last = r
            fr[r, c] = last
        below = -1
        for r in range(h - 1, -1, -1):
            if feature[r, c]:
                below = r
            if below >= 0 and (fr[r, c] < 0 or below - r < r - fr[r, c]):
                fr[r, c] = below


@numba.njit(cache=True)
def _rows(fr, out_r, out_c):
    """Along each row, the nearest of the column sites (fr[r, j], j): sites that can be no pixel's
    nearest are dropped as the sweep meets them, then each pixel walks the kept ones in order."""
    h, w = fr.shape
    g = np.empty(w, np.int64)
    for r in range(h):
        n = -1
        for j in range(w):
            if fr[r, j] < 0:
                continue
            wr = float(fr[r, j] - r) ** 2
            while n >= 1:
                j1, j0 = g[n], g[n - 1]
                a = float(j1 - j0)
                b = float(j - j1)
                c = a + b
                u = float(fr[r, j0] - r) ** 2
                v = float(fr[r, j1] - r) ** 2
                if c * v - b * u - a * wr - a * b * c <= 0.0:
                    break
                n -= 1
            n += 1
            g[n] = j
        if n < 0:
            continue
        s = 0
        for i in range(w):
            d1 = float(fr[r, g[s]] - r) ** 2 + float(g[s] - i) ** 2
            while s < n:
                d2 = float(fr[r, g[s + 1]] - r) ** 2 + float(g[s + 1] - i) ** 2
                if d1 <= d2:
                    break
                d1 = d2
                s += 1
            out_r[r, i] = fr[r, g[s]]
            out_c[r, i] = g[s]


def distance_transform(background: np.ndarray):
    """((H, W) float64 distance, ((H, W) row, (H, W) column) of the nearest pixel where `background`
    is False) for a (H, W) boolean image. With no such pixel at all: inf and -1 everywhere."""
    background = np.asarray(background, bool)
    if background.ndim != 2:
        raise ValueError(f"distance_transform: a (H, W) image, not shape {background.shape}")
    fr = np.empty(background.shape, np.int64)
    _columns(~background, fr)
    rows = np.full(background.shape, -1, np.int64)
    cols = np.full(background.shape, -1, np.int64)
    _rows(fr, rows, cols)
    ri, ci = np.indices(background.shape)
    far = np.sqrt(((rows - ri) ** 2 + (cols - ci) ** 2).astype(np.float64))
    far[rows < 0] = np.inf
    return far, (rows, cols)
