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

    def relative(self, lightmaps, luminance, chunk: int = 1 << 20) -> dict:
        """{object name: relative noise} of each lightmap: the RMS over its texels of the standard
        deviation, over the mean irradiance of every texel of the bake (the scene's light), so that
        a dim object's noise is not magnified by its own darkness, nor a small object's by its
        few texels. Empty when it cannot be measured (`unmeasured` says why). `luminance(start,
        stop)`: the full estimate's (direct + indirect) mean over channels at texels start:stop,
        float64. Chunk by chunk: no temporaries the size of the bake (at 2048² the noise is read
        after every block of batches, and a whole-bake float64 RGB copy is 80 MB)."""
        if self.groups < 2:
            return {}
        first = np.array([lm.offset for lm in lightmaps], np.int64)
        end = first + np.array([lm.count for lm in lightmaps], np.int64)
        spread, level = np.zeros(len(lightmaps)), np.zeros(len(lightmaps))
        # Chunks of the bake's texels, each lightmap's share of a chunk summed from its running sums:
        # a level of 1,500 small lightmaps reads its noise in a few numpy calls, not 1,500 × 4.
        for start in range(int(first.min(initial=0)), int(end.max(initial=0)), chunk):
            stop = min(start + chunk, int(end.max()))
            lo, hi = np.clip(first - start, 0, stop - start), np.clip(end - start, 0, stop - start)
            for out, values in ((spread, self.variance(start, stop)), (level, luminance(start, stop))):
                running = np.concatenate([[0.0], np.cumsum(values, dtype=np.float64)])
                out += running[hi] - running[lo]
        count = int((end - first).sum())
        mean = float(level.sum()) / count if count else 0.0
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
