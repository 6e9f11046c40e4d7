"""How noisy a lightmap is, read off the bake itself: the spread between independent batches.

Every batch of photons is an unbiased estimate of its share of the bake (schedule.py), so a streaming
estimator's sums after each group of batches, differenced, give independent estimates x_g of the
indirect irradiance, each from a share w_g of the photons. Their variance falls as 1/w, so with
W = Σ w_g and X = Σ w_g·x_g / W (the bake's own estimate), the variance of X at a texel is
Σ w_g (x_g − X)² / ((G − 1)·W): no extra tracing, two running sums per texel. A lightmap's relative
noise is the RMS of that standard deviation over its texels, over the mean irradiance of the whole
bake (direct light included: that is what the user sees). Over the lightmap's own mean, a dim lamp
shade or one of a thousand small crates read hundreds of per cent, which says nothing the user can
act on; over the scene's light, it says how visible the noise is beside the rest. Sampled direct light has its own, much smaller, noise, which
this leaves out.
"""
from __future__ import annotations

import numba
import numpy as np

from ..sampling import jit

MIN_GROUPS = 4  # groups needed before the estimate is trusted for stopping a bake


@numba.njit(cache=True)
def _add_wx2(cumulative, previous, w, sum_wx2):
    """Per texel, lum = the mean of `cumulative`'s channels (float64, summed in order as numpy's
    mean over a row of three), sum_wx2 += w·x·x with x = (lum − previous)/w, and previous = lum:
    in place, no array the size of the bake."""
    for i in range(cumulative.shape[0]):
        lum = np.float64(cumulative[i, 0])
        for c in range(1, cumulative.shape[1]):
            lum += np.float64(cumulative[i, c])
        lum /= cumulative.shape[1]
        x = (lum - np.float64(previous[i])) / w
        sum_wx2[i] = np.float64(sum_wx2[i]) + w * x * x
        previous[i] = lum


@jit
def _lightmap_sums(first, end, previous, sum_wx2, weight, groups, level, level_scale, indirect_scale, spread,
                   luminance):
    """Per lightmap m (texels first[m] … end[m] − 1): the sum of the texels' variances (as
    BatchNoise.variance) into spread[m] and of their luminance (BatchNoise.relative) into
    luminance[m], in float64."""
    channels = level.shape[1]
    for m in range(first.shape[0]):
        s = 0.0
        total = 0.0
        for i in range(first[m], end[m]):
            p = np.float64(previous[i])
            mean = p / weight
            s += max(np.float64(sum_wx2[i]) - weight * mean * mean, 0.0) / ((groups - 1) * weight)
            x = indirect_scale * p
            if level.shape[0] > 0:
                c_sum = 0.0
                for c in range(channels):
                    c_sum += np.float64(level[i, c])
                x += level_scale * (c_sum / channels)
            total += x
        spread[m] = s
        luminance[m] = total


class BatchNoise:
    """Running per-texel sums of the group estimates of one estimator."""

    def __init__(self, texel_count: int):
        # float32 (the sums are float64 in the kernel): a noise estimate needs no more, and at
        # 2048² the two arrays are 8 bytes a texel less.
        self.previous = np.zeros(texel_count, np.float32)
        self.weight = 0.0
        self.sum_wx2 = np.zeros(texel_count, np.float32)
        self.groups = 0

    def update(self, cumulative: np.ndarray, share: float) -> None:
        """`cumulative`: the estimator's irradiance sums so far (N, 3); `share`: the share of the
        bake traced so far (schedule.share)."""
        w = share - self.weight
        if w <= 0.0:
            return
        _add_wx2(np.ascontiguousarray(cumulative), self.previous, float(w), self.sum_wx2)
        self.weight = share
        self.groups += 1

    def variance(self, start: int = 0, stop=None) -> np.ndarray:
        """Per texel of start:stop, the variance of the bake's estimate X (luminance); NaN before
        two groups."""
        previous = self.previous[start:stop]
        if self.groups < 2:
            return np.full(len(previous), np.nan)
        mean = previous.astype(np.float64) / self.weight
        spread = np.maximum(self.sum_wx2[start:stop].astype(np.float64) - self.weight * mean * mean, 0.0)
        return spread / ((self.groups - 1) * self.weight)

    def relative(self, lightmaps, level: np.ndarray, level_scale: float = 1.0, indirect_scale: float = 0.0) -> dict:
        """{object name: relative noise} of each lightmap: the RMS over its texels of the standard
        deviation, over the mean irradiance of every texel of the bake (the scene's light), so that
        a dim object's noise is not magnified by its own darkness, nor a small object's by its
        few texels. Empty when it cannot be measured (`unmeasured` says why). The luminance at a
        texel is `level_scale` × the mean of `level`'s channels there ((N, C), or no rows for
        none) plus `indirect_scale` × the indirect sums so far (`previous`). One compiled pass,
        no temporaries the size of the bake: it is read after every block of batches."""
        if self.groups < 2:
            return {}
        first = np.array([lm.offset for lm in lightmaps], np.int64)
        end = first + np.array([lm.count for lm in lightmaps], np.int64)
        spread, luminance = np.zeros(len(lightmaps)), np.zeros(len(lightmaps))
        level = np.asarray(level)
        _lightmap_sums(first, end, self.previous, self.sum_wx2, float(self.weight), self.groups,
                       level[:, None] if level.ndim == 1 else level, float(level_scale), float(indirect_scale),
                       spread, luminance)
        count = int((end - first).sum())
        mean = float(luminance.sum()) / count if count else 0.0
        if not mean > 0.0:
            return {}
        return {lm.name: float(np.sqrt(max(v, 0.0) / lm.count) / mean) if lm.count else 0.0
                for lm, v in zip(lightmaps, spread)}

    def unmeasured(self, photons: int) -> str:
        """Why `relative` is empty after a bake of `photons` photons."""
        if self.groups < 2:
            return (f"the {photons:,} photons were traced in one block, and the noise is read from the spread "
                    "between blocks: trace more photons to have it measured")
        return "the scene's mean irradiance is zero: there is no light to measure the noise against"
