"""Connected components of an undirected graph given as edge lists, by union-find. Labels are
numbered in the order of each component's first node, which is the order scipy's
`connected_components` gives: charts, pieces and regions keep their numbers, and bakes their bytes.
The extension ships no scipy."""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, inline="always")
def _root(parent, i):
    while parent[i] != i:
        parent[i] = parent[parent[i]]  # path halving
        i = parent[i]
    return i


@numba.njit(cache=True)
def _label(n, a, b):
    """(count, (n,) int32 labels): the root of a component is its smallest node, so one pass in node
    order numbers the components by their first node."""
    parent = np.arange(n)
    for e in range(a.shape[0]):
        x = _root(parent, a[e])
        y = _root(parent, b[e])
        if x < y:
            parent[y] = x
        elif y < x:
            parent[x] = y
    label = np.empty(n, np.int32)
    count = 0
    for i in range(n):
        r = _root(parent, i)
        if r == i:
            label[i] = count
            count += 1
        else:
            label[i] = label[r]
    return count, label


def connected_components(n: int, a, b) -> tuple[int, np.ndarray]:
    """(count, (n,) int32 label of each node) of the graph on nodes 0..n-1 whose edges join a[e] and
    b[e] (either way). Labels run from 0 in the order of each component's smallest node."""
    a = np.ascontiguousarray(a, np.int64).reshape(-1)
    b = np.ascontiguousarray(b, np.int64).reshape(-1)
    if a.shape != b.shape:
        raise ValueError(f"connected_components: {a.size} edge starts but {b.size} edge ends")
    if a.size and (min(a.min(), b.min()) < 0 or max(a.max(), b.max()) >= n):
        raise ValueError(f"connected_components: an edge names a node outside 0..{n - 1}")
    return _label(int(n), a, b)


@numba.njit(cache=True)
def _boxes(label, count):
    box = np.empty((count, 4), np.int64)  # first row, last row + 1, first column, last column + 1
    box[:, 0], box[:, 1], box[:, 2], box[:, 3] = label.shape[0], -1, label.shape[1], -1
    for r in range(label.shape[0]):
        for c in range(label.shape[1]):
            v = label[r, c]
            if v >= 0:
                box[v, 0] = min(box[v, 0], r)
                box[v, 1] = max(box[v, 1], r + 1)
                box[v, 2] = min(box[v, 2], c)
                box[v, 3] = max(box[v, 3], c + 1)
    return box


def label_boxes(label: np.ndarray) -> list:
    """For each label 0..max of a (H, W) image (negative: no label), the (row slice, column slice)
    of its bounding box, or None for a label no pixel carries."""
    label = np.ascontiguousarray(label, np.int64)
    if label.ndim != 2:
        raise ValueError(f"label_boxes: a (H, W) image, not shape {label.shape}")
    count = int(label.max()) + 1 if label.size else 0
    if count <= 0:
        return []
    return [(slice(int(r0), int(r1)), slice(int(c0), int(c1))) if r1 > 0 else None
            for r0, r1, c0, c1 in _boxes(label, count)]
