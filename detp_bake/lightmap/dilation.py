"""The gutter grown from the covered texels, ring by ring, as Blender's bake margin (extend) does:
every lightmap image is dilated before it is written, and the denoiser fills its input's gutter
the same way (denoise.fill_gutter), so that filtering across a chart's border reads its own light."""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, inline="always")
def _dilate_row(img, filled, grown, y, acc) -> int:
    """Row y of one ring of `_dilate`: each empty texel next to filled ones takes their mean
    (float32 sums in neighbour order, as numpy's shifted sums gave) and is marked in `grown`;
    returns how many did."""
    h, w, channels = img.shape
    changed = 0
    for x in range(w):
        if filled[y, x]:
            continue
        acc[:] = 0.0
        cnt = np.float32(0.0)
        for dy in range(-1, 2):
            for dx in range(-1, 2):
                yy, xx = y + dy, x + dx
                if (dy == 0 and dx == 0) or yy < 0 or yy >= h or xx < 0 or xx >= w or not filled[yy, xx]:
                    continue
                for c in range(channels):
                    acc[c] += img[yy, xx, c]
                cnt += np.float32(1.0)
        if cnt > 0:
            for c in range(channels):
                img[y, x, c] = acc[c] / cnt
            grown[y, x] = True
            changed += 1
    return changed


@numba.njit(cache=True)
def _dilate(img, filled, margin):
    """In place: `margin` rings of `_dilate_row`; a ring reads only the texels filled before it,
    so one image and two masks are all it needs."""
    grown = filled.copy()
    acc = np.zeros(img.shape[2], np.float32)
    for _ in range(margin):
        changed = 0
        for y in range(img.shape[0]):
            changed += _dilate_row(img, filled, grown, y, acc)
        if changed == 0:
            break
        filled[:] = grown


@numba.njit(cache=True, parallel=True)
def _dilate_wide(img, filled, margin):
    """`_dilate` with a ring's rows on every core (they are independent): the same image, for
    images big enough to repay starting the threads (WIDE). Each row's count goes to its own
    slot (no reduction across threads)."""
    grown = filled.copy()
    rows = np.zeros(img.shape[0], np.int64)
    for _ in range(margin):
        for y in numba.prange(img.shape[0]):
            acc = np.zeros(img.shape[2], np.float32)
            rows[y] = _dilate_row(img, filled, grown, y, acc)
        if rows.sum() == 0:
            break
        filled[:] = grown


WIDE_SIDE = 256
WIDE = WIDE_SIDE * WIDE_SIDE  # texels from which a dilation runs on every core


def dilate(image: np.ndarray, mask: np.ndarray, margin: int, in_place: bool = False) -> np.ndarray:
    """Grow covered texels outwards by `margin` pixels: each empty texel next to covered ones
    takes their mean, ring by ring, as Blender's bake margin (extend) does. `in_place`: grow
    `image` itself when it is float32 (no copy), else a copy."""
    img = image if in_place and image.dtype == np.float32 else image.astype(np.float32, copy=True)
    if img.shape[0] and img.shape[1] and not mask.all():
        (_dilate_wide if img.shape[0] * img.shape[1] >= WIDE else _dilate)(img, np.array(mask, np.bool_), int(margin))
    return img
