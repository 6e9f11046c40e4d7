"""A bounding-volume hierarchy over the DETP discs, built from their Z-order, compiled with numba.

Build: the items (loose discs, and lattice patches of a flat chart's discs: patches.py) are sorted
along a 63-bit Morton curve (morton.py) and a node splits its run of items where the highest
Morton bit that differs across the run flips (a radix split, the idea of Karras's LBVH), so every
node is one cell of the Z-order octree and its box stays compact. No sort per level: the codes
are sorted once, and the split is a binary search. Runs of equal codes split in the middle.
Leaves hold one item or at most `leaf` discs; discs are stored in item order.

Each node is one float32 row: its box, rounded outwards so that a segment never misses a disc it
crosses, and a normal cone (axis a, threshold c) such that every disc below it faces away from any
direction w with w·a ≥ c. DETP counts only segments that arrive from the front, so a segment
leaving a floor skips the floor's whole subtree instead of testing every disc round its origin.

`clusters` cut the tree into subtrees of at most `cluster` discs: the disc index's unit of parallel
work. Every disc lies in one cluster, so no two threads ever add to the same disc.

The same radix tree over triangle boxes serves tangent clearance (discs_meet_triangles): which
texels need Embree's rays at all.
"""
from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from .morton import morton_codes

LEAF_SIZE = 4
CONE_NONE = 2.0  # a threshold no unit direction reaches: the node's discs face every way
# Row layout of `node`: box lo (0-2), box hi (3-5), cone axis (6-8), cone threshold (9).
LO, HI, AXIS, CONE = 0, 3, 6, 9
STACK_DEPTH = 256  # a walk holds at most depth + 1 nodes; radix splits of 63-bit codes go < 100 deep
AGAINST = 0.99  # faces_against: two faces within 8° of back to back touch face to face


@dataclass
class DiscTree:
    """The tree over items (loose discs and lattice patches, patches.py), discs in item order."""
    order: np.ndarray  # (n,) int64: the disc at each sorted position
    node: np.ndarray  # (m, 10) float32: box lo, box hi, cone axis, cone threshold
    left: np.ndarray  # (m,) int32: first child (the second is left + 1), -1 for a leaf
    first: np.ndarray  # (m,) int32: first sorted disc under the node
    count: np.ndarray  # (m,) int32: discs under the node
    item_first: np.ndarray  # (m,) int32: first item under the node
    item_count: np.ndarray  # (m,) int32: items under the node
    item_disc: np.ndarray  # (items + 1,) int64: first sorted disc of each item
    item_patch: np.ndarray  # (items,) int32: the item's patch, −1 for a loose disc
    patch_geo: np.ndarray  # (patches, patches.GEO) float64: lattice, normal, radius, tolerances
    patch_site: np.ndarray  # (patches, SIDE²) int32: sorted disc at each lattice site (−1: none; see patches)
    clusters: np.ndarray  # (k,) int32: roots of the subtrees that are the units of parallel work

    @property
    def nodes(self) -> int:
        return len(self.left)

    @property
    def depth(self) -> int:
        return _depth(self.left)


@numba.njit(cache=True)
def _topology(codes, leaf, item_disc):
    """Radix splits of the items' sorted codes, depth first (a parent before its children). A
    node is a leaf when it holds one item or at most `leaf` discs; item_disc[k] is item k's first
    disc, so node ranges come out in items and in discs."""
    n = codes.shape[0]
    cap = 2 * n + 1
    left = np.full(cap, -1, np.int32)
    ifirst = np.zeros(cap, np.int32)
    icount = np.zeros(cap, np.int32)
    stack = np.empty((256, 3), np.int64)
    stack[0, 0], stack[0, 1], stack[0, 2] = 0, 0, n
    sp = 1
    used = 1
    while sp > 0:
        sp -= 1
        node, a, b = stack[sp, 0], stack[sp, 1], stack[sp, 2]
        ifirst[node] = a
        icount[node] = b - a
        if b - a <= 1 or item_disc[b] - item_disc[a] <= leaf:
            continue
        mid = (a + b) // 2
        diff = codes[a] ^ codes[b - 1]
        if diff != 0:
            bit = np.int64(1)
            while diff > 1:
                diff >>= 1
                bit <<= 1
            lo, hi = a + 1, b - 1  # the first code with `bit` set; codes[b - 1] has it
            while lo < hi:
                m = (lo + hi) // 2
                if codes[m] & bit:
                    hi = m
                else:
                    lo = m + 1
            mid = lo
        child = used
        used += 2
        left[node] = child
        stack[sp, 0], stack[sp, 1], stack[sp, 2] = child + 1, mid, b
        stack[sp + 1, 0], stack[sp + 1, 1], stack[sp + 1, 2] = child, a, mid
        sp += 2
    left, ifirst, icount = left[:used].copy(), ifirst[:used].copy(), icount[:used].copy()
    first = np.empty(used, np.int32)
    count = np.empty(used, np.int32)
    for k in range(used):
        first[k] = item_disc[ifirst[k]]
        count[k] = item_disc[ifirst[k] + icount[k]] - first[k]
    return left, first, count, ifirst, icount


@numba.njit(cache=True)
def _items(centre, patch_of, site_of, patches, side):
    """Items: every patch (at the mean of its discs) and every loose disc. Returns the items'
    centres and patches, and per patch its discs by lattice site."""
    n = centre.shape[0]
    loose = 0
    for d in range(n):
        loose += patch_of[d] < 0
    items = patches + loose
    where = np.zeros((items, 3))
    item_patch = np.full(items, -1, np.int32)
    item_one = np.full(items, -1, np.int64)  # a loose item's disc
    by_site = np.full((patches, side * side), -1, np.int64)
    size = np.zeros(patches, np.int64)
    k = patches
    for d in range(n):
        p = patch_of[d]
        if p >= 0:
            by_site[p, site_of[d]] = d
            size[p] += 1
            for c in range(3):
                where[p, c] += centre[d, c]
        else:
            item_one[k] = d
            for c in range(3):
                where[k, c] = centre[d, c]
            k += 1
    for p in range(patches):
        item_patch[p] = p
        for c in range(3):
            where[p, c] /= size[p]
    return where, item_patch, item_one, by_site


@numba.njit(cache=True)
def _disc_order(item_order, item_patch, item_one, by_site, n):
    """Discs in item order (a patch's by site) and each item's first disc; the patches' sites as
    sorted disc positions."""
    order = np.empty(n, np.int64)
    item_disc = np.empty(item_order.shape[0] + 1, np.int64)
    site = np.full(by_site.shape, -1, np.int32)
    pos = 0
    for k in range(item_order.shape[0]):
        it = item_order[k]
        item_disc[k] = pos
        p = item_patch[it]
        if p < 0:
            order[pos] = item_one[it]
            pos += 1
            continue
        for s in range(by_site.shape[1]):
            if by_site[p, s] >= 0:
                order[pos] = by_site[p, s]
                site[p, s] = pos
                pos += 1
    item_disc[item_order.shape[0]] = pos
    return order, item_disc, site


@numba.njit(cache=True, inline="always")
def _down(x):
    f = np.float32(x)
    return np.nextafter(f, np.float32(-np.inf)) if np.float64(f) > x else f


@numba.njit(cache=True, inline="always")
def _up(x):
    f = np.float32(x)
    return np.nextafter(f, np.float32(np.inf)) if np.float64(f) < x else f


@numba.njit(cache=True, inline="always")
def _cylinder(c, n, r, slab, eps):
    """One axis of the box round a disc's cylinder, as Discs.bounds computes it."""
    half = r * np.sqrt(min(max(1.0 - n * n, 0.0), 1.0))
    top = c + n * slab
    return min(c, top) - half - eps, max(c, top) + half + eps


@numba.njit(cache=True, inline="always")
def _store_axis(node, k, s0, s1, s2):
    """Store the normalised sum of normals (s0, s1, s2) as node k's cone axis, in float32; False
    when the normals cancel out (no cone)."""
    norm = np.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    if norm < 1e-9:
        node[k, AXIS] = node[k, AXIS + 1] = node[k, AXIS + 2] = 0.0
        node[k, CONE] = CONE_NONE
        return False
    node[k, AXIS], node[k, AXIS + 1], node[k, AXIS + 2] = s0 / norm, s1 / norm, s2 / norm
    return True


@numba.njit(cache=True, inline="always")
def _store_cone(node, k, worst):
    """Threshold for `worst` = max |n − a| over the node's normals (a: the stored axis). Since
    w·n ≥ w·a − |w|·|n − a| and |w| < 1 + 1e-6 for float32 unit directions, w·a ≥ threshold gives
    w·n > 0 for every disc below; 1e-9 covers the rounding of both dot products."""
    c = worst * (1.0 + 1e-6) + 1e-9
    if c < 1.0:
        node[k, CONE] = _up(c)
        return worst
    node[k, CONE] = CONE_NONE
    return CONE_NONE


@numba.njit(cache=True, parallel=True)
def _leaves(disc, eps, left, first, count, node, spread):
    """Boxes of the discs' cylinders and normal cones, per leaf."""
    for k in numba.prange(left.shape[0]):
        if left[k] >= 0:
            continue
        a, b = first[k], first[k] + count[k]
        l0 = l1 = l2 = np.inf
        h0 = h1 = h2 = -np.inf
        s0 = s1 = s2 = 0.0
        for j in range(a, b):
            r, sl = disc[6, j], disc[7, j]
            lo, hi = _cylinder(disc[0, j], disc[3, j], r, sl, eps)
            l0, h0 = min(l0, lo), max(h0, hi)
            lo, hi = _cylinder(disc[1, j], disc[4, j], r, sl, eps)
            l1, h1 = min(l1, lo), max(h1, hi)
            lo, hi = _cylinder(disc[2, j], disc[5, j], r, sl, eps)
            l2, h2 = min(l2, lo), max(h2, hi)
            s0 += disc[3, j]
            s1 += disc[4, j]
            s2 += disc[5, j]
        node[k, LO], node[k, LO + 1], node[k, LO + 2] = _down(l0), _down(l1), _down(l2)
        node[k, HI], node[k, HI + 1], node[k, HI + 2] = _up(h0), _up(h1), _up(h2)
        if not _store_axis(node, k, s0, s1, s2):
            spread[k] = CONE_NONE
            continue
        a0, a1, a2 = np.float64(node[k, AXIS]), np.float64(node[k, AXIS + 1]), np.float64(node[k, AXIS + 2])
        worst = 0.0
        for j in range(a, b):
            d0, d1, d2 = disc[3, j] - a0, disc[4, j] - a1, disc[5, j] - a2
            worst = max(worst, np.sqrt(d0 * d0 + d1 * d1 + d2 * d2))
        spread[k] = _store_cone(node, k, worst)


@numba.njit(cache=True)
def _inner(left, count, node, spread):
    """Boxes and cones of inner nodes from their children, bottom up (children follow parents)."""
    for k in range(left.shape[0] - 1, -1, -1):
        l = left[k]
        if l < 0:
            continue
        for c in range(3):
            node[k, LO + c] = min(node[l, LO + c], node[l + 1, LO + c])
            node[k, HI + c] = max(node[l, HI + c], node[l + 1, HI + c])
        spread[k] = CONE_NONE
        if node[l, CONE] > 1.0 or node[l + 1, CONE] > 1.0:
            node[k, AXIS] = node[k, AXIS + 1] = node[k, AXIS + 2] = 0.0
            node[k, CONE] = CONE_NONE
            continue
        s0 = s1 = s2 = 0.0
        for q in range(l, l + 2):
            s0 += np.float64(node[q, AXIS]) * count[q]
            s1 += np.float64(node[q, AXIS + 1]) * count[q]
            s2 += np.float64(node[q, AXIS + 2]) * count[q]
        if not _store_axis(node, k, s0, s1, s2):
            continue
        worst = 0.0
        for q in range(l, l + 2):  # |n − a| ≤ |n − a_child| + |a_child − a|
            d = 0.0
            for c in range(AXIS, AXIS + 3):
                d += (np.float64(node[q, c]) - np.float64(node[k, c])) ** 2
            worst = max(worst, np.sqrt(d) + spread[q])
        spread[k] = _store_cone(node, k, worst)


@numba.njit(cache=True)
def _clusters(left, count, size):
    """Roots of the subtrees, largest first below the root, that hold at most `size` discs."""
    roots = np.empty(left.shape[0], np.int32)
    k = 0
    stack = np.empty(256, np.int32)
    stack[0] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        node = stack[sp]
        if count[node] <= size or left[node] < 0:
            roots[k] = node
            k += 1
        else:
            stack[sp] = left[node] + 1
            stack[sp + 1] = left[node]
            sp += 2
    return roots[:k].copy()


@numba.njit(cache=True, parallel=True)
def gather_discs(order, centre, normal, radius, slab):
    """The discs' data in sorted order, one row per quantity (x, y, z, nx, ny, nz, r, δ, 1/(πr²)):
    a leaf's discs are contiguous in every row."""
    n = order.shape[0]
    disc = np.empty((9, n))
    for i in numba.prange(n):
        j = order[i]
        for c in range(3):
            disc[c, i] = centre[j, c]
            disc[3 + c, i] = normal[j, c]
        r = radius[j]
        disc[6, i] = r
        disc[7, i] = slab[j]
        disc[8, i] = 1.0 / (np.pi * (r * r))
    return disc


@numba.njit(cache=True)
def _depth(left):
    depth = np.ones(left.shape[0], np.int64)
    best = 1
    for k in range(left.shape[0]):  # children always come after their parent
        if left[k] >= 0:
            depth[left[k]] = depth[left[k] + 1] = depth[k] + 1
        best = max(best, depth[k])
    return best


def build(centre: np.ndarray, normal: np.ndarray, radius: np.ndarray, slab: np.ndarray, eps: float,
          leaf: int = LEAF_SIZE, cluster: int = 1 << 14, patch_of=None, site_of=None, patch_geo=None,
          side: int = 8) -> tuple[DiscTree, np.ndarray, dict]:
    """The tree over the discs (grouped in patches where patch_of ≥ 0, at lattice site site_of),
    their data in tree order (gather_discs) and seconds per step."""
    import time

    t0 = time.perf_counter()
    n = len(radius)
    centre = np.ascontiguousarray(centre, np.float64)
    if patch_of is None:
        patch_of, site_of, patch_geo = np.full(n, -1, np.int64), np.full(n, -1, np.int64), np.zeros((0, 1))
    where, item_patch, item_one, by_site = _items(centre, patch_of, site_of, len(patch_geo), side)
    codes = morton_codes(where)
    item_order = np.argsort(codes)  # the tree depends on ties' order, the estimate does not
    codes = codes[item_order]
    order, item_disc, site = _disc_order(item_order, item_patch, item_one, by_site, n)
    disc = gather_discs(order, centre, np.ascontiguousarray(normal, np.float64),
                        np.ascontiguousarray(radius, np.float64), np.ascontiguousarray(slab, np.float64))
    t1 = time.perf_counter()
    left, first, count, ifirst, icount = _topology(codes, int(leaf), item_disc)
    node = np.empty((len(left), 10), np.float32)
    spread = np.empty(len(left))
    _leaves(disc, float(eps), left, first, count, node, spread)
    _inner(left, count, node, spread)
    tree = DiscTree(order, node, left, first, count, ifirst, icount, item_disc, item_patch[item_order], patch_geo,
                    site, _clusters(left, count, int(cluster)))
    t2 = time.perf_counter()
    return tree, disc, {"sort": t1 - t0, "tree": t2 - t1}


@numba.njit(cache=True, parallel=True)
def _box_leaves(lo, hi, order, left, first, count, node):
    for k in numba.prange(left.shape[0]):
        if left[k] >= 0:
            continue
        for c in range(3):
            a, b = np.inf, -np.inf
            for p in range(first[k], first[k] + count[k]):
                a, b = min(a, lo[order[p], c]), max(b, hi[order[p], c])
            node[k, LO + c], node[k, HI + c] = _down(a), _up(b)


@numba.njit(cache=True)
def _box_inner(left, node):
    for k in range(left.shape[0] - 1, -1, -1):
        l = left[k]
        if l >= 0:
            for c in range(3):
                node[k, LO + c] = min(node[l, LO + c], node[l + 1, LO + c])
                node[k, HI + c] = max(node[l, HI + c], node[l + 1, HI + c])


@numba.njit(cache=True, inline="always")
def _misses_node(lo, hi, node, k):
    """The box lo..hi and node k's box (float32, LO/HI columns) do not overlap."""
    return (lo[0] > node[k, HI] or hi[0] < node[k, LO] or lo[1] > node[k, HI + 1] or hi[1] < node[k, LO + 1]
            or lo[2] > node[k, HI + 2] or hi[2] < node[k, LO + 2])


@numba.njit(cache=True, inline="always")
def _misses_triangle(lo, hi, tri_lo, tri_hi, t):
    """The box lo..hi and triangle t's box do not overlap."""
    return (lo[0] > tri_hi[t, 0] or hi[0] < tri_lo[t, 0] or lo[1] > tri_hi[t, 1] or hi[1] < tri_lo[t, 1]
            or lo[2] > tri_hi[t, 2] or hi[2] < tri_lo[t, 2])


@numba.njit(cache=True, parallel=True)
def _discs_meet(tri, tri_lo, tri_hi, order, node, left, first, count, origin, normal, reach, out):
    """out[i]: some triangle's box overlaps disc i's box and the triangle reaches its plane (both
    padded by 1e-5 of the disc's size and distance from the origin: a hundred times what float32
    rays and Embree's float32 hit test can stray)."""
    for i in numba.prange(origin.shape[0]):
        pad = 1e-5 * (reach[i] + max(abs(origin[i, 0]), max(abs(origin[i, 1]), abs(origin[i, 2]))))
        lo = np.empty(3)
        hi = np.empty(3)
        for c in range(3):
            half = reach[i] * np.sqrt(max(1.0 - normal[i, c] ** 2, 0.0)) + pad
            lo[c], hi[c] = origin[i, c] - half, origin[i, c] + half
        stack = np.empty(STACK_DEPTH, np.int32)
        stack[0] = 0
        sp = 1
        while sp > 0 and not out[i]:
            sp -= 1
            k = stack[sp]
            if _misses_node(lo, hi, node, k):
                continue
            if left[k] >= 0:
                stack[sp], stack[sp + 1] = left[k], left[k] + 1
                sp += 2
                continue
            for p in range(first[k], first[k] + count[k]):
                t = order[p]
                if _misses_triangle(lo, hi, tri_lo, tri_hi, t):
                    continue
                below = above = False
                for v in range(3):
                    d = 0.0
                    for c in range(3):
                        d += (tri[t, v, c] - origin[i, c]) * normal[i, c]
                    below |= d <= pad
                    above |= d >= -pad
                if below and above:
                    out[i] = True
                    break


class TriangleTree:
    """A radix tree over the boxes of triangles (T, 3, 3), built once and asked many times: whether
    triangles cross discs (`discs_meet`) or lie face to face against points (`faces_against`)."""

    def __init__(self, positions: np.ndarray):
        self.tri = tri = np.ascontiguousarray(positions, np.float64)
        self.nodes = None
        if len(tri):
            lo, hi = tri.min(axis=1), tri.max(axis=1)
            codes = morton_codes(0.5 * (lo + hi))
            order = np.argsort(codes)
            left, first, count, _, _ = _topology(codes[order], LEAF_SIZE, np.arange(len(tri) + 1))
            node = np.zeros((len(left), 10), np.float32)
            _box_leaves(lo, hi, order, left, first, count, node)
            _box_inner(left, node)
            self.nodes = (lo, hi, order, node, left, first, count)

    def discs_meet(self, origin: np.ndarray, normal: np.ndarray, reach: np.ndarray) -> np.ndarray:
        """Per disc (origin, unit normal, radius `reach`): whether some triangle may cross it.
        Conservative: False only where no ray within the disc can hit a triangle."""
        out = np.zeros(len(origin), np.bool_)
        if self.nodes is not None and len(origin):
            _discs_meet(self.tri, *self.nodes, np.ascontiguousarray(origin, np.float64),
                        np.ascontiguousarray(normal, np.float64), np.ascontiguousarray(reach, np.float64), out)
        return out

    def faces_against(self, facing: np.ndarray, point: np.ndarray, normal: np.ndarray, own: np.ndarray,
                      reach: np.ndarray) -> np.ndarray:
        """Per point (on triangle `own`, unit `normal` its front): whether the front of another
        triangle (unit `facing` normals, per triangle) lies face to face against it, crossing the
        normal within `reach` in front of the point (or a float's width behind it): a box's bottom
        face standing on a floor is covered so, and so is the floor under it, and the end faces of
        two boxes put end to end."""
        out = np.zeros(len(point), np.bool_)
        if self.nodes is not None and len(point):
            _against(self.tri, np.ascontiguousarray(facing, np.float64), *self.nodes,
                     np.ascontiguousarray(point, np.float64), np.ascontiguousarray(normal, np.float64),
                     np.ascontiguousarray(own, np.int64), np.ascontiguousarray(reach, np.float64), out)
        return out


def discs_meet_triangles(positions: np.ndarray, origin: np.ndarray, normal: np.ndarray,
                         reach: np.ndarray) -> np.ndarray:
    """TriangleTree(positions).discs_meet, the tree built for this one call."""
    if len(origin) == 0:
        return np.zeros(0, np.bool_)
    return TriangleTree(positions).discs_meet(origin, normal, reach)


@numba.njit(cache=True, parallel=True)
def _against(tri, facing, tri_lo, tri_hi, order, node, left, first, count, point, normal, own, reach, out):
    """out[i]: a triangle other than own[i], its front (`facing`) turned back to normal[i] (within
    AGAINST), crosses the segment from point[i] − pad·normal[i] to point[i] + reach[i]·normal[i]
    (pad as _discs_meet)."""
    for i in numba.prange(point.shape[0]):
        pad = 1e-5 * (reach[i] + max(abs(point[i, 0]), max(abs(point[i, 1]), abs(point[i, 2]))))
        lo = np.empty(3)
        hi = np.empty(3)
        for c in range(3):
            a, b = point[i, c] - pad * normal[i, c], point[i, c] + reach[i] * normal[i, c]
            lo[c], hi[c] = min(a, b) - pad, max(a, b) + pad
        stack = np.empty(STACK_DEPTH, np.int32)
        stack[0] = 0
        sp = 1
        while sp > 0 and not out[i]:
            sp -= 1
            k = stack[sp]
            if _misses_node(lo, hi, node, k):
                continue
            if left[k] >= 0:
                stack[sp], stack[sp + 1] = left[k], left[k] + 1
                sp += 2
                continue
            for p in range(first[k], first[k] + count[k]):
                t = order[p]
                if t == own[i] or _misses_triangle(lo, hi, tri_lo, tri_hi, t):
                    continue
                cos = facing[t, 0] * normal[i, 0] + facing[t, 1] * normal[i, 1] + facing[t, 2] * normal[i, 2]
                if cos > -AGAINST:
                    continue  # not face to face: an edge touching it, or its own surface, a decal on it
                # Where the segment meets the triangle's plane, and whether that point lies on it.
                s = 0.0
                for c in range(3):
                    s += (tri[t, 0, c] - point[i, c]) * facing[t, c]
                s /= cos
                if s < -pad or s > reach[i]:
                    continue
                q = np.empty(3)
                for c in range(3):
                    q[c] = point[i, c] + s * normal[i, c]
                inside = True
                for e in range(3):
                    a, b = tri[t, e], tri[t, (e + 1) % 3]
                    # The edge's inward side, in the plane: (b − a) × facing points inwards for CCW.
                    ex, ey, ez = b[0] - a[0], b[1] - a[1], b[2] - a[2]
                    ix = ey * facing[t, 2] - ez * facing[t, 1]
                    iy = ez * facing[t, 0] - ex * facing[t, 2]
                    iz = ex * facing[t, 1] - ey * facing[t, 0]
                    third = tri[t, (e + 2) % 3]
                    side = (third[0] - a[0]) * ix + (third[1] - a[1]) * iy + (third[2] - a[2]) * iz
                    here = (q[0] - a[0]) * ix + (q[1] - a[1]) * iy + (q[2] - a[2]) * iz
                    length = np.sqrt(ix * ix + iy * iy + iz * iz)
                    if here * np.sign(side) < -pad * length:
                        inside = False
                        break
                if inside:
                    out[i] = True
                    break


def faces_against(positions: np.ndarray, facing: np.ndarray, point: np.ndarray, normal: np.ndarray,
                  own: np.ndarray, reach: np.ndarray) -> np.ndarray:
    """TriangleTree(positions).faces_against, the tree built for this one call."""
    if len(point) == 0:
        return np.zeros(0, np.bool_)
    return TriangleTree(positions).faces_against(facing, point, normal, own, reach)
