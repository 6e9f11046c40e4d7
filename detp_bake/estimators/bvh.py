"""A balanced bounding-volume hierarchy over boxes, compiled with numba.

Median splits on the longest axis of the centroids give a tree of depth ⌈log₂(n / leaf)⌉: the
balanced case of the paper's bound for disc indexing, O(n_R·∛n_P) rather than O(n_R·∛n_P·log n_P).
Nodes are flat arrays; a node with `left < 0` is a leaf holding `order[start:start + count]`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

LEAF_SIZE = 4


@dataclass
class BVH:
    lo: np.ndarray
    hi: np.ndarray
    left: np.ndarray
    right: np.ndarray
    start: np.ndarray
    count: np.ndarray
    order: np.ndarray

    @property
    def nodes(self) -> int:
        return len(self.left)

    @property
    def depth(self) -> int:
        return _depth(self.left, self.right)


@numba.njit(cache=True)
def _build(lo, hi, leaf_size):
    n = lo.shape[0]
    order = np.arange(n)
    cen = 0.5 * (lo + hi)
    cap = 2 * n + 1  # median splits can leave leaves smaller than leaf_size
    nlo = np.empty((cap, 3))
    nhi = np.empty((cap, 3))
    left = np.full(cap, -1, np.int64)
    right = np.full(cap, -1, np.int64)
    start = np.zeros(cap, np.int64)
    count = np.zeros(cap, np.int64)
    st_node = np.empty(cap, np.int64)
    st_a = np.empty(cap, np.int64)
    st_b = np.empty(cap, np.int64)
    sp = 0
    st_node[0], st_a[0], st_b[0] = 0, 0, n
    sp = 1
    used = 1
    while sp > 0:
        sp -= 1
        node, a, b = st_node[sp], st_a[sp], st_b[sp]
        for c in range(3):
            nlo[node, c] = np.inf
            nhi[node, c] = -np.inf
        clo = np.full(3, np.inf)
        chi = np.full(3, -np.inf)
        for p in range(a, b):
            q = order[p]
            for c in range(3):
                nlo[node, c] = min(nlo[node, c], lo[q, c])
                nhi[node, c] = max(nhi[node, c], hi[q, c])
                clo[c] = min(clo[c], cen[q, c])
                chi[c] = max(chi[c], cen[q, c])
        axis = 0
        for c in range(1, 3):
            if chi[c] - clo[c] > chi[axis] - clo[axis]:
                axis = c
        if b - a <= leaf_size or chi[axis] - clo[axis] <= 0.0:
            start[node] = a
            count[node] = b - a
            continue
        sub = order[a:b].copy()
        keys = np.empty(b - a)
        for p in range(b - a):
            keys[p] = cen[sub[p], axis]
        idx = np.argsort(keys)
        for p in range(b - a):
            order[a + p] = sub[idx[p]]
        mid = (a + b) // 2
        l, r = used, used + 1
        used += 2
        left[node], right[node] = l, r
        st_node[sp], st_a[sp], st_b[sp] = l, a, mid
        sp += 1
        st_node[sp], st_a[sp], st_b[sp] = r, mid, b
        sp += 1
    return nlo[:used].copy(), nhi[:used].copy(), left[:used].copy(), right[:used].copy(), \
        start[:used].copy(), count[:used].copy(), order


@numba.njit(cache=True)
def _depth(left, right):
    depth = np.zeros(len(left), np.int64)
    best = 0
    for node in range(len(left)):  # children always come after their parent
        if left[node] >= 0:
            depth[left[node]] = depth[node] + 1
            depth[right[node]] = depth[node] + 1
        best = max(best, depth[node])
    return best + 1


def build(lo: np.ndarray, hi: np.ndarray, leaf_size: int = LEAF_SIZE) -> BVH:
    return BVH(*_build(np.ascontiguousarray(lo, np.float64), np.ascontiguousarray(hi, np.float64),
                       int(leaf_size)))
