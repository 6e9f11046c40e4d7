"""Lattice patches: the discs a segment crosses on a flat chart, found a row at a time.

The texels of a flat chart sit on a lattice, c(i, j) = c0 + i·du + j·dv, with one normal and one
disc radius. A segment crosses the lattice discs whose centres lie within r of one point (its plane
hit, or under rule (b) its end dropped onto the plane): per lattice row a run of sites, found with
one square root. Testing each disc costs about ten times more, and on 3-4-texel discs a segment
crosses some fifty of them, so 8x8 blocks of such texels become patches, one item of the BVH.

Exactness: every bound is widened by the patch's measured lattice and normal deviations and by
float rounding (and float32 rounding of a segment's end); sites inside that band of the circle,
and every segment for which the rule itself is in doubt (grazing, ending within rounding of the
plane or the slab), are decided by crossing_weight itself. So a patch finds the oracle's crossings
and adds the oracle's weights; only the order of additions may differ.
"""
from __future__ import annotations

import numba
import numpy as np

from .discs import add_l1, crossing_weight

SIDE = 32  # lattice sites per patch row and column
MIN_SITES = 12  # smaller groups stay loose discs
LATTICE_TOL = 1e-6  # largest deviation from the fitted lattice, as a fraction of the site spacing
NORMAL_TOL = 1e-9  # largest normal deviation from the patch's normal
# Columns of `geo`, one row per patch.
C0, DU, DV, NRM, RAD, SLAB, INV_AREA, TOL_C, TOL_N, DIAM, INV_UU = 0, 3, 6, 9, 12, 13, 14, 15, 16, 17, 18
GINV, RECT = 19, 22  # inverse Gram matrix of (du, dv): g00, g01, g11; occupied sites: i0, i1, j0, j1
TOL_H = 26  # largest |(c − c0)·n| over the sites: how far they stand off the patch's plane
SKEW, SCHUR = 27, 28  # (du·dv)/|du|², |dv|² − (du·dv)²/|du|²: a row's circle, see _rows
GEO = 29


def group_keys(lightmap: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """One key per SIDE x SIDE block of a lightmap's pixels."""
    return (lightmap.astype(np.int64) << 42) | ((j.astype(np.int64) // SIDE) << 21) | (i.astype(np.int64) // SIDE)


@numba.njit(cache=True)
def _fit(grid, member, centre):
    """Least-squares lattice c = c0 + i·du + j·dv over the block's member sites; (ok, c0, du, dv)."""
    m = np.zeros((3, 3))
    rhs = np.zeros((3, 3))
    for s in range(SIDE * SIDE):
        if not member[s]:
            continue
        x0, x1, x2 = 1.0, float(s % SIDE), float(s // SIDE)
        d = grid[s]
        for a in range(3):
            xa = x0 if a == 0 else (x1 if a == 1 else x2)
            m[a, 0] += xa * x0
            m[a, 1] += xa * x1
            m[a, 2] += xa * x2
            for c in range(3):
                rhs[a, c] += xa * centre[d, c]
    det = (m[0, 0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1]) - m[0, 1] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0])
           + m[0, 2] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]))
    if abs(det) < 1e-6:  # all in one row or column
        return False, np.zeros(3), np.zeros(3), np.zeros(3)
    sol = np.linalg.solve(m, rhs)
    return True, sol[0].copy(), sol[1].copy(), sol[2].copy()


@numba.njit(cache=True, inline="always")
def _dist(centre, d, c0, du, dv, i, j):
    e = 0.0
    for c in range(3):
        e += (centre[d, c] - c0[c] - i * du[c] - j * dv[c]) ** 2
    return np.sqrt(e)


@numba.njit(cache=True)
def _grow(grid, free, centre, normal, radius, slab, seed, member, queue, lattice_tol, normal_tol):
    """Flood-fill from the seed over free neighbouring sites on the seed's lattice (du, dv from its
    neighbours) with its normal; returns how many (queue[:count]), 0 when the seed has no
    neighbour along a row and along a column."""
    si, sj = seed % SIDE, seed // SIDE
    d0 = grid[seed]
    step = np.zeros((2, 3))
    for axis in range(2):
        found = False
        for sign in (1, -1):
            i, j = si + sign * (axis == 0), sj + sign * (axis == 1)
            if 0 <= i < SIDE and 0 <= j < SIDE and free[j * SIDE + i]:
                for c in range(3):
                    step[axis, c] = sign * (centre[grid[j * SIDE + i], c] - centre[d0, c])
                found = True
                break
        if not found:
            return 0
    du, dv = step[0], step[1]
    spacing = min(np.sqrt((du * du).sum()), np.sqrt((dv * dv).sum()))
    c0 = np.empty(3)
    for c in range(3):
        c0[c] = centre[d0, c] - si * du[c] - sj * dv[c]
    member[seed] = True
    queue[0] = seed
    head, tail = 0, 1
    while head < tail:
        s = queue[head]
        head += 1
        for k in range(4):
            i = s % SIDE + (1 if k == 0 else (-1 if k == 1 else 0))
            j = s // SIDE + (1 if k == 2 else (-1 if k == 3 else 0))
            if not (0 <= i < SIDE and 0 <= j < SIDE):
                continue
            s2 = j * SIDE + i
            d = grid[s2]
            if not free[s2] or member[s2]:
                continue
            dn = 0.0
            for c in range(3):
                dn += (normal[d, c] - normal[d0, c]) ** 2
            # Twice the tolerances: the seed itself deviates too.
            if dn <= (2 * normal_tol) ** 2 and _dist(centre, d, c0, du, dv, i, j) <= 2 * lattice_tol * spacing:
                member[s2] = True
                queue[tail] = s2
                tail += 1
    return tail


@numba.njit(cache=True)
def _accept(grid, member, centre, normal, radius, slab, lattice_tol, normal_tol, geo, p):
    """Fit the lattice to the member sites and check it; when it holds, write patch p's geometry
    into geo[p] and return True."""
    ok, c0, du, dv = _fit(grid, member, centre)
    if not ok:
        return False
    nm = np.zeros(3)
    r = sl = 0.0
    for s in range(SIDE * SIDE):
        if member[s]:
            d = grid[s]
            for c in range(3):
                nm[c] += normal[d, c]
            r, sl = max(r, radius[d]), max(sl, slab[d])
    nm /= np.sqrt(nm[0] ** 2 + nm[1] ** 2 + nm[2] ** 2)
    res = 0.0
    tol_n = 0.0
    tol_h = 0.0
    lo_i, hi_i, lo_j, hi_j = SIDE, -1, SIDE, -1
    for s in range(SIDE * SIDE):
        if member[s]:
            d = grid[s]
            res = max(res, _dist(centre, d, c0, du, dv, s % SIDE, s // SIDE))
            dn = h = 0.0
            for c in range(3):
                dn += (normal[d, c] - nm[c]) ** 2
                h += (centre[d, c] - c0[c]) * nm[c]
            tol_n = max(tol_n, np.sqrt(dn))
            tol_h = max(tol_h, abs(h))  # off the plane
            lo_i, hi_i = min(lo_i, s % SIDE), max(hi_i, s % SIDE)
            lo_j, hi_j = min(lo_j, s // SIDE), max(hi_j, s // SIDE)
    uu = du[0] * du[0] + du[1] * du[1] + du[2] * du[2]
    uv = du[0] * dv[0] + du[1] * dv[1] + du[2] * dv[2]
    vv = dv[0] * dv[0] + dv[1] * dv[1] + dv[2] * dv[2]
    # Sites further apart than the diameter (stretched charts) gain nothing from runs and would
    # make a long box that many segments enter.
    if not (res <= lattice_tol * np.sqrt(min(uu, vv)) and tol_n <= normal_tol and max(uu, vv) <= 4 * r * r):
        return False
    det = uu * vv - uv * uv
    if not (min(uu, vv) > 0.0 and det > 1e-12 * uu * vv):  # sites on one point or one line (a pole)
        return False
    geo[p, C0:C0 + 3], geo[p, DU:DU + 3], geo[p, DV:DV + 3], geo[p, NRM:NRM + 3] = c0, du, dv, nm
    geo[p, RAD], geo[p, SLAB], geo[p, INV_AREA] = r, sl, 1.0 / (np.pi * (r * r))
    geo[p, TOL_C], geo[p, TOL_N], geo[p, TOL_H] = res, tol_n, tol_h * (1.0 + 1e-9) + 1e-15
    geo[p, DIAM] = (SIDE - 1) * (np.sqrt(uu) + np.sqrt(vv)) + res
    geo[p, INV_UU] = 1.0 / uu
    geo[p, SKEW], geo[p, SCHUR] = uv / uu, vv - uv * uv / uu
    geo[p, GINV], geo[p, GINV + 1], geo[p, GINV + 2] = vv / det, -uv / det, uu / det
    geo[p, RECT], geo[p, RECT + 1], geo[p, RECT + 2], geo[p, RECT + 3] = lo_i, hi_i, lo_j, hi_j
    return True


@numba.njit(cache=True, parallel=True)
def form_patches(keys_sorted, order, li, lj, centre, normal, radius, slab, lattice_tol, normal_tol):
    """Patches from discs grouped by block (`order` sorts them by key; li, lj: pixel within the
    block). A block holds one patch per chart lattice found in it (grown from a seed texel, then
    fitted and checked against the tolerances); texels off every lattice (chart borders) stay
    loose. Blocks are independent: threads take them, and patches are numbered in block order.
    Returns per disc its patch (−1: loose) and site, and the patches' geometry."""
    n = order.shape[0]
    blocks = 0
    for q in range(n):
        blocks += q == 0 or keys_sorted[q] != keys_sorted[q - 1]
    start = np.empty(blocks + 1, np.int64)
    k = 0
    for q in range(n):
        if q == 0 or keys_sorted[q] != keys_sorted[q - 1]:
            start[k] = q
            k += 1
    start[blocks] = n
    local = np.full(n, -1, np.int64)  # patch within its block
    site_of = np.full(n, -1, np.int64)
    # A block of m discs makes at most m // MIN_SITES patches: its rows of `slots` start at a // MIN_SITES.
    slots = np.zeros((n // MIN_SITES + 1, GEO))
    made = np.zeros(blocks, np.int64)
    for blk in numba.prange(blocks):
        a, b = start[blk], start[blk + 1]
        grid = np.full(SIDE * SIDE, -1, np.int64)
        free = np.zeros(SIDE * SIDE, np.bool_)
        member = np.zeros(SIDE * SIDE, np.bool_)
        queue = np.empty(SIDE * SIDE, np.int64)
        for q in range(a, b):
            s = int(lj[order[q]]) * SIDE + int(li[order[q]])
            grid[s] = order[q]
            free[s] = True
        seedable = free.copy()
        count = 0
        for seed in range(SIDE * SIDE):
            if not seedable[seed]:
                continue
            k = _grow(grid, free, centre, normal, radius, slab, seed, member, queue, lattice_tol, normal_tol)
            ok = k >= MIN_SITES and _accept(grid, member, centre, normal, radius, slab, lattice_tol, normal_tol,
                                            slots, a // MIN_SITES + count)
            for q in range(k):
                s = queue[q]
                member[s] = False
                seedable[s] = False  # another seed on the same lattice would be turned down too
                if ok:
                    local[grid[s]] = count
                    site_of[grid[s]] = s
                    free[s] = False
            count += ok
        made[blk] = count
    first = np.zeros(blocks + 1, np.int64)
    for blk in range(blocks):
        first[blk + 1] = first[blk] + made[blk]
    geo = np.empty((first[blocks], GEO))
    patch_of = np.full(n, -1, np.int64)
    for blk in numba.prange(blocks):
        a = start[blk]
        for k in range(made[blk]):
            geo[first[blk] + k] = slots[a // MIN_SITES + k]
        for q in range(a, start[blk + 1]):
            d = order[q]
            if local[d] >= 0:
                patch_of[d] = first[blk] + local[d]
    return patch_of, site_of, geo


@numba.njit(cache=True, inline="always")
def patch_splat(p, geo, site, disc, o, w, length, flux, i, eps, kernel, acc, acc_l1):
    """Add segment i to the discs of patch p it crosses; returns (disc tests, crossings). Inlined
    into the traversal: a call would take and release a reference to every array it is passed."""
    mode, px, py, pz, dp, hb, dh = _point(p, geo, o, w, length, i, eps)
    if mode == 0:
        return 0, 0
    if mode == 1:
        return _rows(p, geo, site, disc, o, w, length, flux, i, eps, kernel, acc, acc_l1, px, py, pz, dp, hb, dh)
    # In doubt (grazing, or ending within rounding of the plane or the slab): test every disc.
    tests = 0
    hits = 0
    for s in range(SIDE * SIDE):
        d = site[p, s]
        if d != -1:
            tests += 1
            hits += _add(d if d >= 0 else -d - 2, disc, o, w, length, flux, i, eps, kernel, acc, acc_l1)
    return tests, hits


@numba.njit(cache=True, inline="always")
def _point(p, geo, o, w, length, i, eps):
    """Where segment i meets patch p for every disc of it at once: (0, ...) when it crosses none,
    (1, x, y, z, dp, h, dh) when each disc's rule measures from a point within dp of (x, y, z),
    (2, ...) when in doubt. Under rule (b), h is the end's height over the patch's plane, each
    disc's own within dh (its slab decides); under rule (a), h = −inf."""
    n0, n1, n2 = geo[p, NRM], geo[p, NRM + 1], geo[p, NRM + 2]
    tol_c, tol_n, tol_h = geo[p, TOL_C], geo[p, TOL_N], geo[p, TOL_H]
    ox, oy, oz = np.float64(o[i, 0]), np.float64(o[i, 1]), np.float64(o[i, 2])
    wx, wy, wz = np.float64(w[i, 0]), np.float64(w[i, 1]), np.float64(w[i, 2])
    wn = wx * n0 + wy * n1 + wz * n2
    tn = tol_n * (1.0 + 1e-6) + 1e-15
    if wn >= tn:
        return 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0  # every disc faces away: w·n_j ≥ w·n − |w|·|n_j − n| > 0
    if wn > -tn:
        return 2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    dx, dy, dz = geo[p, C0] - ox, geo[p, C0 + 1] - oy, geo[p, C0 + 2] - oz
    big = np.sqrt(dx * dx + dy * dy + dz * dz) + geo[p, DIAM]  # ≥ |c_j − o|
    t = (dx * n0 + dy * n1 + dz * n2) / wn
    scale = big + abs(t) + 1.0 + max(abs(ox), max(abs(oy), abs(oz)))
    rho = 1e-13 * scale  # far above the rounding of any product or sum here
    dt = (tol_h + (big + abs(t)) * tol_n * (1.0 + 1e-6) + rho) / (-wn - tn)
    limit = length[i] + eps
    if t + dt <= 0.0:
        return 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0  # t_j ≤ 0 for every disc
    if t - dt > 0.0 and t + dt <= limit:  # rule (a) for every disc: the plane hit
        return 1, ox + t * wx, oy + t * wy, oz + t * wz, dt * (1.0 + 1e-6) + tol_c + rho, -np.inf, 0.0
    if t - dt <= limit:
        return 2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    # Rule (b) for every disc: the end, if within the slab; e as crossing_weight computes it (float32).
    ex = np.float64(o[i, 0] + length[i] * w[i, 0])
    ey = np.float64(o[i, 1] + length[i] * w[i, 1])
    ez = np.float64(o[i, 2] + length[i] * w[i, 2])
    de = 2.4e-7 * (max(abs(ox), max(abs(oy), abs(oz))) + length[i])  # float32 rounding, twice over
    fx, fy, fz = ex - geo[p, C0], ey - geo[p, C0 + 1], ez - geo[p, C0 + 2]
    h = fx * n0 + fy * n1 + fz * n2
    dh = tol_h + (np.sqrt(fx * fx + fy * fy + fz * fz) + geo[p, DIAM]) * tol_n + de + rho
    if h - dh > geo[p, SLAB]:
        return 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    if h + dh > geo[p, SLAB]:
        return 2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    return 1, ex - h * n0, ey - h * n1, ez - h * n2, dh + (abs(h) + dh) * tol_n + tol_c + de + rho, h, dh


@numba.njit(cache=True, inline="always")
def _add(d, disc, o, w, length, flux, i, eps, kernel, acc, acc_l1):
    k = crossing_weight(o[i, 0], o[i, 1], o[i, 2], w[i, 0], w[i, 1], w[i, 2], length[i], disc[0, d], disc[1, d],
                        disc[2, d], disc[3, d], disc[4, d], disc[5, d], disc[6, d], disc[7, d], eps, kernel)
    if k > 0.0:
        acc[d, 0] += k * flux[i, 0]
        acc[d, 1] += k * flux[i, 1]
        acc[d, 2] += k * flux[i, 2]
        add_l1(acc_l1, d, k, flux, w, i)
        return 1
    return 0


@numba.njit(cache=True, inline="always")
def _cut_site(d, disc, kernel, px, py, pz, dp, hb, dh):
    """Whether cut disc d is crossed: 1 surely, 0 surely not, 2 in doubt (crossing_weight decides).
    The point is within dp of where its rule measures, the end's height within dh of its own."""
    if kernel != 0:
        return 2
    if hb != -np.inf:  # rule (b): the end must lie within this disc's own slab
        if hb - dh > disc[7, d]:
            return 0
        if hb + dh > disc[7, d]:
            return 2
    r = disc[6, d]
    slack = 1e-9 * r
    qx, qy, qz = px - disc[0, d], py - disc[1, d], pz - disc[2, d]
    q2 = qx * qx + qy * qy + qz * qz
    r_out = r + dp + slack
    if q2 > r_out * r_out:
        return 0
    r_in = r - dp - slack
    if r_in > 0.0 and q2 < r_in * r_in:
        return 1
    return 2


@numba.njit(cache=True, inline="always")
def _rows(p, geo, site, disc, o, w, length, flux, i, eps, kernel, acc, acc_l1, px, py, pz, dp, hb, dh):
    """Sites within r of the point (px, py, pz), each row's run from one square root. Within
    dp + slack of the circle, and for the Epanechnikov kernel, crossing_weight decides. A disc cut
    short (by tangent clearance: its own radius and slab) is decided the same way on its own
    circle and slab, by one distance."""
    r = geo[p, RAD]
    slack = 1e-9 * r
    r_in = r - dp - slack
    r_out = r + dp + slack
    if r_in <= 0.0:
        r_in = 0.0
    qx, qy, qz = px - geo[p, C0], py - geo[p, C0 + 1], pz - geo[p, C0 + 2]
    # The point in lattice coordinates (si, sj) and the circle's reach along them: only rows and
    # columns of occupied sites within that reach can hold a crossed disc.
    qu = qx * geo[p, DU] + qy * geo[p, DU + 1] + qz * geo[p, DU + 2]
    qv = qx * geo[p, DV] + qy * geo[p, DV + 1] + qz * geo[p, DV + 2]
    g00, g01, g11 = geo[p, GINV], geo[p, GINV + 1], geo[p, GINV + 2]
    si, sj = g00 * qu + g01 * qv, g01 * qu + g11 * qv
    reach_i, reach_j = r_out * np.sqrt(g00) + 1e-9, r_out * np.sqrt(g11) + 1e-9
    if si + reach_i < geo[p, RECT] or si - reach_i > geo[p, RECT + 1]:
        return 0, 0
    j_lo = max(int(geo[p, RECT + 2]), int(np.ceil(sj - reach_j)))
    j_hi = min(int(geo[p, RECT + 3]), int(np.floor(sj + reach_j)))
    # |q − i·du − j·dv|² = |du|²·(i − c_j)² + SCHUR·(j − sj)² + h², c_j = si − (j − sj)·SKEW, h the
    # distance of q from the lattice's plane: per row, one centre and one half-width.
    h2 = max(qx * qx + qy * qy + qz * qz - (si * qu + sj * qv), 0.0)
    skew, schur, inv_uu = geo[p, SKEW], geo[p, SCHUR], geo[p, INV_UU]
    out2, in2 = r_out * r_out, r_in * r_in
    k_in = geo[p, INV_AREA]
    f0, f1, f2 = flux[i, 0], flux[i, 1], flux[i, 2]
    tests = 0
    hits = 0
    for jl in range(j_lo, j_hi + 1):
        dj = jl - sj
        perp = schur * dj * dj + h2  # squared distance from the row's line
        if perp > out2:
            continue
        centre = si - dj * skew
        half = np.sqrt((out2 - perp) * inv_uu)
        lo = max(int(geo[p, RECT]), int(np.ceil(centre - half - 1e-9)))
        hi = min(int(geo[p, RECT + 1]), int(np.floor(centre + half + 1e-9)))
        in_lo, in_hi = 1, 0
        if kernel == 0 and perp < in2:
            half_in = np.sqrt((in2 - perp) * inv_uu)
            in_lo = int(np.ceil(centre - half_in + 1e-9))
            in_hi = int(np.floor(centre + half_in - 1e-9))
        for il in range(lo, hi + 1):
            d = site[p, jl * SIDE + il]
            if d == -1:
                continue
            if d < -1:  # a disc cut short: the certain run does not hold for it
                c = _cut_site(-d - 2, disc, kernel, px, py, pz, dp, hb, dh)
                if c == 1:
                    dd = -d - 2
                    k = disc[8, dd]  # 1/(πr²) as crossing_weight computes it, to the bit
                    hits += 1
                    acc[dd, 0] += k * f0
                    acc[dd, 1] += k * f1
                    acc[dd, 2] += k * f2
                    add_l1(acc_l1, dd, k, flux, w, i)
                elif c == 2:
                    tests += 1
                    hits += _add(-d - 2, disc, o, w, length, flux, i, eps, kernel, acc, acc_l1)
            elif in_lo <= il <= in_hi:
                hits += 1
                acc[d, 0] += k_in * f0
                acc[d, 1] += k_in * f1
                acc[d, 2] += k_in * f2
                add_l1(acc_l1, d, k_in, flux, w, i)
            else:
                tests += 1
                hits += _add(d, disc, o, w, length, flux, i, eps, kernel, acc, acc_l1)
    return tests, hits


@numba.njit(cache=True)
def mark_cut(site, disc, geo):
    """Sites whose disc is smaller than the patch's (cut short by tangent clearance) become
    −(disc + 2): they are always tested one by one."""
    for p in range(site.shape[0]):
        for s in range(site.shape[1]):
            d = site[p, s]
            if d >= 0 and (disc[6, d] != geo[p, RAD] or disc[7, d] != geo[p, SLAB]):
                site[p, s] = -d - 2
