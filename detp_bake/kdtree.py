"""The k nearest points to each query point by a k-d tree in compiled code: the photon map's
neighbours and the fragments' texels round them. The extension ships no scipy.

Texels on a flat chart lie on a grid, so many lie at exactly the same distance from a query, and
which of them is kept (and in which order they come) changes the bytes of a bake. This tree
therefore makes the choices scipy's cKDTree makes on Linux: the same splits (the median by
libstdc++'s selection and partition, or the sliding midpoint), the same visiting order, the same
distance sums and the same heap of neighbours. Bakes keep the bytes they had with scipy."""
from __future__ import annotations

import numba
import numpy as np

LEAF = 16  # points per leaf at most (cKDTree's leafsize)


# --- libstdc++'s std::nth_element on indices compared by one coordinate --------------------------

@numba.njit(cache=True, inline="always")
def _less(data, d, a, b):
    return data[a, d] < data[b, d]


@numba.njit(cache=True)
def _sift(idx, data, d, base, hole, length, value):
    """__adjust_heap then __push_heap: a max-heap on idx[base:base + length]."""
    top, child = hole, hole
    while child < (length - 1) // 2:
        child = 2 * (child + 1)
        if _less(data, d, idx[base + child], idx[base + child - 1]):
            child -= 1
        idx[base + hole] = idx[base + child]
        hole = child
    if length % 2 == 0 and child == (length - 2) // 2:
        child = 2 * (child + 1)
        idx[base + hole] = idx[base + child - 1]
        hole = child - 1
    parent = (hole - 1) // 2
    while hole > top and _less(data, d, idx[base + parent], value):
        idx[base + hole] = idx[base + parent]
        hole = parent
        parent = (hole - 1) // 2
    idx[base + hole] = value


@numba.njit(cache=True)
def _heap_select(idx, data, d, first, middle, last):
    length = middle - first
    if length >= 2:
        parent = (length - 2) // 2
        while True:
            _sift(idx, data, d, first, parent, length, idx[first + parent])
            if parent == 0:
                break
            parent -= 1
    for i in range(middle, last):
        if _less(data, d, idx[i], idx[first]):
            value = idx[i]
            idx[i] = idx[first]
            _sift(idx, data, d, first, 0, length, value)


@numba.njit(cache=True)
def _nth_element(idx, data, d, first, nth, last):
    """Introselect: median-of-three Hoare partitions, a heap below 2·log2(n) of them, then
    insertion sort of the last three elements or fewer."""
    depth, size = 0, last - first
    while size > 1:
        size >>= 1
        depth += 1
    depth *= 2
    while last - first > 3:
        if depth == 0:
            _heap_select(idx, data, d, first, nth + 1, last)
            idx[first], idx[nth] = idx[nth], idx[first]
            return
        depth -= 1
        a, b, c = first + 1, first + (last - first) // 2, last - 1
        if _less(data, d, idx[a], idx[b]):
            m = b if _less(data, d, idx[b], idx[c]) else (c if _less(data, d, idx[a], idx[c]) else a)
        else:
            m = a if _less(data, d, idx[a], idx[c]) else (c if _less(data, d, idx[b], idx[c]) else b)
        idx[first], idx[m] = idx[m], idx[first]
        lo, hi = first + 1, last
        while True:
            while _less(data, d, idx[lo], idx[first]):
                lo += 1
            hi -= 1
            while _less(data, d, idx[first], idx[hi]):
                hi -= 1
            if not lo < hi:
                break
            idx[lo], idx[hi] = idx[hi], idx[lo]
            lo += 1
        if lo <= nth:
            first = lo
        else:
            last = lo
    for i in range(first + 1, last):
        value = idx[i]
        if data[value, d] < data[idx[first], d]:
            idx[first + 1:i + 1] = idx[first:i].copy()
            idx[first] = value
        else:
            j = i
            while data[value, d] < data[idx[j - 1], d]:
                idx[j] = idx[j - 1]
                j -= 1
            idx[j] = value


@numba.njit(cache=True)
def _partition(idx, data, d, first, last, pivot):
    """std::partition (the two-ended one): those with a coordinate below `pivot` first; returns
    where the others begin."""
    while True:
        while True:
            if first == last:
                return first
            if not data[idx[first], d] >= pivot:
                first += 1
            else:
                break
        last -= 1
        while True:
            if first == last:
                return first
            if data[idx[last], d] >= pivot:
                last -= 1
            else:
                break
        idx[first], idx[last] = idx[last], idx[first]
        first += 1


# --- the tree --------------------------------------------------------------------------------------

@numba.njit(cache=True, inline="always")
def _extreme(idx, data, d, s, e, largest):
    """The position in idx[s:e] of the first point with the smallest coordinate d (the largest
    with `largest`)."""
    k = s
    for i in range(s + 1, e):
        if (data[idx[k], d] < data[idx[i], d]) if largest else (data[idx[i], d] < data[idx[k], d]):
            k = i
    return k


@numba.njit(cache=True)
def _split(data, idx, s, e, lo, hi, median):
    """(dimension, split value, first index of the upper part) of one node, or (-1, 0, s): a leaf;
    (-2, 0, s): every point shares the coordinate of the widest side, try again without it."""
    d, size = 0, 0.0
    for i in range(3):
        if hi[i] - lo[i] > size:
            d, size = i, hi[i] - lo[i]
    if hi[d] == lo[d]:
        return -1, 0.0, s
    if median:
        mid = s + (e - s) // 2
        _nth_element(idx, data, d, s, mid, e)
        split = data[idx[mid], d]
        p = _partition(idx, data, d, s, mid, split)
    else:
        split = (hi[d] + lo[d]) / 2
        p = _partition(idx, data, d, s, e, split)
    if p == s:  # every point on the upper side: split just above the smallest
        split = np.nextafter(data[idx[_extreme(idx, data, d, s, e, False)], d], np.inf)
        p = _partition(idx, data, d, s, e, split)
    elif p == e:  # every point on the lower side: split at the largest
        split = data[idx[_extreme(idx, data, d, s, e, True)], d]
        p = _partition(idx, data, d, s, e, split)
    if p == s or p == e:
        return -2, 0.0, s
    return d, split, p


@numba.njit(cache=True)
def _grown(a, rows):
    """`a` with room for at least `rows` rows (doubled as often as needed), its rows kept."""
    if rows <= a.shape[0]:
        return a
    size = a.shape[0]
    while size < rows:
        size *= 2
    b = np.zeros((size, a.shape[1]), a.dtype)
    b[:a.shape[0]] = a
    return b


@numba.njit(cache=True)
def _build(data, lo0, hi0, median, compact):
    """(idx, node, split): node i holds idx[node[i, 0]:node[i, 1]], splits dimension node[i, 2]
    (-1: a leaf) at split[i, 0] into nodes node[i, 3] and node[i, 4]. Nodes are split as cKDTree
    splits them (module docstring); split[i, 1:] are the bounds a node passes to its children."""
    n = data.shape[0]
    idx = np.arange(n)
    cap = 4 * (n // LEAF) + 16  # grown when sliding midpoints cut small leaves
    node = np.zeros((cap, 5), np.int64)
    split = np.zeros((cap, 7))
    todo = np.zeros((cap, 1), np.int64)  # node ids still to split, depth first
    node[0, 1], node[0, 2] = n, -1
    split[0, 1:4], split[0, 4:] = lo0, hi0
    count, top = 1, 1
    lo, hi = np.empty(3), np.empty(3)
    while top > 0:
        top -= 1
        nd = todo[top, 0]
        s, e = node[nd, 0], node[nd, 1]
        if e - s <= LEAF:
            continue
        lo[:], hi[:] = split[nd, 1:4], split[nd, 4:]
        if compact:
            lo[:], hi[:] = data[idx[s]], data[idx[s]]
            for j in range(s + 1, e):
                for i in range(3):
                    lo[i] = min(lo[i], data[idx[j], i])
                    hi[i] = max(hi[i], data[idx[j], i])
        d, v, p = _split(data, idx, s, e, lo, hi, median)
        while d == -2:  # not compact: the bounds were wider than the points
            d = 0
            for i in range(1, 3):
                if hi[i] - lo[i] > hi[d] - lo[d]:
                    d = i
            lo[d] = hi[d] = data[idx[s], d]
            d, v, p = _split(data, idx, s, e, lo, hi, median)
        if d < 0:
            continue
        node = _grown(node, count + 2)
        split = _grown(split, count + 2)
        todo = _grown(todo, top + 2)
        a, b = count, count + 1
        count += 2
        node[nd, 2], node[nd, 3], node[nd, 4], split[nd, 0] = d, a, b, v
        node[a, 0], node[a, 1], node[b, 0], node[b, 1] = s, p, p, e
        node[a, 2] = node[b, 2] = -1
        split[a, 1:4], split[a, 4:], split[b, 1:4], split[b, 4:] = lo, hi, lo, hi
        split[a, 4 + d] = v
        split[b, 1 + d] = v
        todo[top, 0], todo[top + 1, 0] = b, a
        top += 2
    return idx, node[:count].copy(), split[:count, 0].copy()


# --- the query ------------------------------------------------------------------------------------

@numba.njit(cache=True, inline="always")
def _push(pri, val, n, p, v):
    """cKDTree's binary min-heap: push (p, v) onto pri[:n], val[:n]; returns n + 1."""
    i = n
    pri[i], val[i] = p, v
    while i > 0 and pri[i] < pri[(i - 1) // 2]:
        j = (i - 1) // 2
        pri[i], pri[j] = pri[j], pri[i]
        val[i], val[j] = val[j], val[i]
        i = j
    return n + 1


@numba.njit(cache=True, inline="always")
def _remove(pri, val, n):
    """Drop the heap's first item; returns n - 1."""
    n -= 1
    pri[0], val[0] = pri[n], val[n]
    i = 0
    while True:
        j, k = 2 * i + 1, 2 * i + 2
        if not ((j < n and pri[i] > pri[j]) or (k < n and pri[i] > pri[k])):
            return n
        m = k if (k < n and pri[j] > pri[k]) else j
        pri[i], pri[m] = pri[m], pri[i]
        val[i], val[m] = val[m], val[i]
        i = m


@numba.njit(cache=True)
def _one(data, tree, root, lo0, hi0, x, k, bound, node_of, min_of, side_of, qp, qv, npri, nval, out_d, out_i):
    """The k nearest of `data` to `x` with d² < bound², as cKDTree's query walks the tree from node
    `root`: nearer children first, farther ones on a heap by their least distance."""
    idx, node, split = tree
    ub = bound * bound
    node_of[0], min_of[0], free = root, 0.0, 1
    for i in range(3):
        s = max(x[i] - hi0[i], 0.0)
        if not x[i] - hi0[i] > 0.0:
            s = max(lo0[i] - x[i], 0.0)
        side_of[0, i] = s * s
        min_of[0] += s * s
    cur, qn, nn = 0, 0, 0
    while True:
        nd = node_of[cur]
        if node[nd, 2] < 0:
            for t in range(node[nd, 0], node[nd, 1]):
                j = idx[t]
                s = 0.0
                for i in range(3):
                    u = data[j, i] - x[i]
                    s += u * u
                if s < ub:
                    if nn == k:
                        nn = _remove(npri, nval, nn)
                    nn = _push(npri, nval, nn, -s, j)
                    if nn == k:
                        ub = -npri[0]
            if qn == 0:
                break
            cur = qv[0]
            qn = _remove(qp, qv, qn)
            continue
        if min_of[cur] > ub:
            break
        if free == node_of.shape[0]:
            return False  # the pool is full: the caller grows it and asks again
        d, v = node[nd, 2], split[nd]
        far = free
        free += 1
        min_of[far], side_of[far] = min_of[cur], side_of[cur]
        if x[d] < v:
            node_of[cur], node_of[far], s = node[nd, 3], node[nd, 4], v - x[d]
        else:
            node_of[cur], node_of[far], s = node[nd, 4], node[nd, 3], x[d] - v
        min_of[far] += s * s - side_of[far, d]
        side_of[far, d] = s * s
        if min_of[cur] > min_of[far]:
            cur, far = far, cur
        if min_of[far] <= ub:
            qn = _push(qp, qv, qn, min_of[far], far)
    for r in range(nn - 1, -1, -1):
        out_d[r], out_i[r] = np.sqrt(-npri[0]), nval[0]
        _remove(npri, nval, r + 1)
    return True


class KDTree:
    """The tree over (N, 3) points, kept as float64 copies. `balanced`: median splits (cKDTree's
    default), else sliding midpoints; `compact`: each node's bounds shrunk to its points (default)."""

    def __init__(self, points, balanced: bool = True, compact: bool = True):
        self.points = np.ascontiguousarray(np.asarray(points, np.float64).reshape(-1, 3))
        if len(self.points):
            self.lo, self.hi = self.points.min(axis=0), self.points.max(axis=0)
        else:
            self.lo = self.hi = np.zeros(3)
        self._tree = _build(self.points, self.lo, self.hi, bool(balanced), bool(compact))

    def query(self, x, k: int, distance_upper_bound: float = np.inf):
        """((M, k) distances, (M, k) int64 indices) of the k nearest points to each of the (M, 3)
        `x`, nearest first; a point counts only closer than `distance_upper_bound`. Where fewer are
        found, the row ends in (inf, N)."""
        x = np.ascontiguousarray(np.asarray(x, np.float64).reshape(-1, 3))
        n, k = len(self.points), int(k)
        if k < 1:
            raise ValueError(f"KDTree.query: k must be at least 1, not {k}")
        dist = np.full((len(x), k), np.inf)
        idx = np.full((len(x), k), n, np.int64)
        if n and len(x):
            blocks = min(len(x), 4 * numba.get_num_threads())
            forest = (*self._tree, np.array([0, len(self._tree[1])], np.int64), self.lo[None], self.hi[None])
            _forest_query(self.points, forest, x, np.zeros(len(x), np.int64), np.array([k], np.int64),
                          np.array([float(distance_upper_bound)]), dist, idx, blocks)
        return dist, idx


# --- many trees at once ----------------------------------------------------------------------------

@numba.njit(cache=True)
def _forest(data, start, count):
    """The tree of each group of points data[start[g]:start[g] + count[g]] (count 0: none), built as
    KDTree builds it, the trees laid end to end and their indices made global: (idx; node and split,
    group g's root at row first[g]; first; each group's lo and hi)."""
    groups = start.shape[0]
    lo, hi = np.zeros((groups, 3)), np.zeros((groups, 3))
    idx = np.zeros(data.shape[0], np.int64)
    node, split = np.zeros((16, 5), np.int64), np.zeros((16, 1))
    first = np.zeros(groups + 1, np.int64)
    used = 0
    for g in range(groups):
        a, n = start[g], count[g]
        first[g] = used
        if n == 0:
            continue
        points = data[a:a + n]
        for i in range(3):
            lo[g, i], hi[g, i] = points[:, i].min(), points[:, i].max()
        t_idx, t_node, t_split = _build(points, lo[g], hi[g], True, True)
        m = t_node.shape[0]
        node, split = _grown(node, used + m), _grown(split, used + m)
        idx[a:a + n] = t_idx + a
        node[used:used + m] = t_node
        node[used:used + m, :2] += a
        node[used:used + m, 3:] += used
        split[used:used + m, 0] = t_split
        used += m
    first[groups] = used
    return idx, node[:used].copy(), split[:used, 0].copy(), first, lo, hi


@numba.njit(cache=True, parallel=True)
def _forest_query(data, forest, xs, group, k, bound, out_d, out_i, blocks):
    """The k nearest points (`_one`) of each query in its own group's tree (`_forest`; KDTree.query:
    one tree), with the group's k and bound, the queries in `blocks` runs over every core."""
    idx, node, split, first, lo, hi = forest
    m = xs.shape[0]
    for b in numba.prange(blocks):
        cap = 256
        npri, nval = np.empty(out_d.shape[1]), np.empty(out_d.shape[1], np.int64)
        q = b * m // blocks
        while q < (b + 1) * m // blocks:
            node_of, min_of, side_of = np.empty(cap, np.int64), np.empty(cap), np.empty((cap, 3))
            qp, qv = np.empty(cap), np.empty(cap, np.int64)
            while q < (b + 1) * m // blocks:
                g = group[q]
                if not _one(data, (idx, node, split), first[g], lo[g], hi[g], xs[q], k[g], bound[g], node_of,
                            min_of, side_of, qp, qv, npri, nval, out_d[q], out_i[q]):
                    break
                q += 1
            cap *= 2


def query_groups(points, start, count, x, group, k, bound):
    """For each of the (M, 3) points `x` in group `group[q]`, what KDTree(points[a:a + n]).query(x, k[g],
    bound[g]) gives (a = start[g], n = count[g]), its indices + a: ((M, max k) distances, (M, max k)
    indices into `points`), a row past its k, or short of neighbours, ending in (inf, len(points)).
    Every group's tree is built and asked in one call: no Python work per group (1,500 small
    objects, a tree each, took 0.5 s)."""
    points = np.ascontiguousarray(np.asarray(points, np.float64).reshape(-1, 3))
    x = np.ascontiguousarray(np.asarray(x, np.float64).reshape(-1, 3))
    start, count = np.asarray(start, np.int64), np.asarray(count, np.int64)
    group = np.ascontiguousarray(group, np.int64)
    k = np.ascontiguousarray(np.broadcast_to(k, count.shape), np.int64)
    if len(group) and (k[group] < 1).any():
        raise ValueError("query_groups: k must be at least 1 in every group asked")
    width = int(k[group].max()) if len(group) else 1
    dist = np.full((len(x), width), np.inf)
    idx = np.full((len(x), width), len(points), np.int64)
    if len(x):
        asked = np.zeros(len(count), bool)
        asked[group] = True
        forest = _forest(points, start, np.where(asked, count, 0))
        bound = np.ascontiguousarray(np.broadcast_to(bound, count.shape), np.float64)
        blocks = min(len(x), 4 * numba.get_num_threads())
        _forest_query(points, forest, x, group, k, bound, dist, idx, blocks)
    return dist, idx
