"""Z-order (Morton) sorting of 3D points: neighbours in space become neighbours in memory, which
is what the sphere cache's texel walk, the disc index's segment walk and its tree build rely on."""
from __future__ import annotations

import numba
import numpy as np


def morton_order(points: np.ndarray) -> np.ndarray:
    """Indices sorting points along a 3D Z-order curve (10 bits per axis)."""
    lo = points.min(axis=0)
    span = max(float((points.max(axis=0) - lo).max()), 1e-30)
    q = np.clip(((points - lo) / span * 1023.0).astype(np.int64), 0, 1023)

    def spread(v):
        v = (v | (v << 16)) & 0x030000FF
        v = (v | (v << 8)) & 0x0300F00F
        v = (v | (v << 4)) & 0x030C30C3
        return (v | (v << 2)) & 0x09249249

    code = spread(q[:, 0]) | (spread(q[:, 1]) << 1) | (spread(q[:, 2]) << 2)
    return np.argsort(code, kind="stable")


@numba.njit(cache=True, inline="always")
def _spread21(v):
    """The 21 low bits of v moved to every third bit of a 63-bit integer."""
    v &= 0x1FFFFF
    v = (v | (v << 32)) & 0x1F00000000FFFF
    v = (v | (v << 16)) & 0x1F0000FF0000FF
    v = (v | (v << 8)) & 0x100F00F00F00F00F
    v = (v | (v << 4)) & 0x10C30C30C30C30C3
    return (v | (v << 2)) & 0x1249249249249249


@numba.njit(cache=True, parallel=True)
def morton_codes(points):
    """63-bit Z-order codes (21 bits per axis) over the points' bounding cube: fine enough to keep
    texels of a 2048² lightmap in a scene a hundred times its size apart. Two parallel loops, no
    more: each one waits for every thread, which costs on a busy machine."""
    n = points.shape[0]
    parts = 64
    box = np.empty((parts, 6))
    for p in numba.prange(parts):
        for c in range(3):
            box[p, c], box[p, 3 + c] = np.inf, -np.inf
        for i in range(p * n // parts, (p + 1) * n // parts):
            for c in range(3):
                box[p, c] = min(box[p, c], points[i, c])
                box[p, 3 + c] = max(box[p, 3 + c], points[i, c])
    lo = np.full(3, np.inf)
    span = 1e-300
    for c in range(3):
        hi = -np.inf
        for p in range(parts):
            lo[c], hi = min(lo[c], box[p, c]), max(hi, box[p, 3 + c])
        span = max(span, hi - lo[c])
    scale = 2097151.0 / span
    codes = np.empty(n, np.int64)
    for i in numba.prange(n):
        code = 0
        for c in range(3):
            q = min(max(int((points[i, c] - lo[c]) * scale), 0), 2097151)
            code |= _spread21(q) << c
        codes[i] = code
    return codes


@numba.njit(cache=True)
def segment_order(o, w, length, at):
    """Indices sorting segments along a 48-bit Z-order curve of the point at fraction `at` of their
    length. A stable LSD radix sort: ties keep their batch order, so the order is the same on every
    machine and thread count (the sums along it depend on it in the last bits)."""
    n = o.shape[0]
    key = np.empty(n, np.int64)
    if n == 0:
        return key
    p = np.empty((n, 3))
    for i in range(n):
        for c in range(3):
            p[i, c] = o[i, c] + w[i, c] * (at * length[i])
    lo = np.empty(3)
    span = 1e-300
    for c in range(3):
        lo[c] = p[:, c].min()
        span = max(span, p[:, c].max() - lo[c])
    scale = 65535.0 / span
    for i in range(n):
        code = 0
        for c in range(3):
            code |= _spread21(min(max(int((p[i, c] - lo[c]) * scale), 0), 65535)) << c
        key[i] = code
    idx = np.arange(n)
    tmp = np.empty(n, np.int64)
    count = np.empty(4097, np.int64)
    for shift in range(0, 48, 12):
        count[:] = 0
        for i in range(n):
            count[((key[idx[i]] >> shift) & 4095) + 1] += 1
        for d in range(4096):
            count[d + 1] += count[d]
        for i in range(n):
            d = (key[idx[i]] >> shift) & 4095
            tmp[count[d]] = idx[i]
            count[d] += 1
        idx, tmp = tmp, idx
    return idx
