"""Points spread over a texel's middle, for direct light averaged over the texel as Cycles does.

Cycles bakes a texel as the mean of its samples, each at a point jittered round the texel's centre
and kept on the texel's triangle. The jitter spans half a texel each way: Blender's bake takes the
barycentric differentials as half the change per pixel (`bake_differentials` in its bake code,
`A = 0.5f / A`), and Cycles offsets by them times a number in [−½, ½]. Direct light read at the centre
differs from that mean wherever a shadow edge or a spot's rim crosses the texel: at 64² per object
the patio's roof, crossed by straight shadow edges along a texel row, read −4.7 % against Cycles
(benchmarks/objects.py). So every shadow ray starts at its own point: the texel's centre offset by a
low-discrepancy point of the square SPAN texels wide (Halton bases 3 and 5, so the points do not
line up with the light's own Hammersley samples in bases 2 and 1/n), rotated per texel, and kept
when it lies on the texel's triangle (Cycles mirrors it back onto the triangle). A point off the
triangle (a texel at a chart's border, partly covered) is replaced by the next point of the
sequence, a few times, then by the texel's own position: the rays stay on the covered part, so seams
keep their values. A light that adds rays only where a texel's first ones disagree (a point light or
a sharp sun) starts those first ones at the square's corners (`square_corner`), so that no straight
shadow edge crossing the square goes unseen.
"""
from __future__ import annotations

import numpy as np

from ..sampling import inline
from .texels import pixel_steps

TRIES = 8  # points tried per sample before the texel's own position is used
SPAN = 0.5  # the square's width in texels: Cycles' bake jitter
CORNER_INSET = 1.0 / 16.0  # square_corner's corners, this share of the square in from its edge
PROBES = 4  # square_corner's corners


@inline
def _radical_inverse(k, base):
    inv = 1.0 / base
    f = inv
    r = 0.0
    while k > 0:
        r += f * (k % base)
        k //= base
        f *= inv
    return r


@inline
def square_of(spread, i, tri, cx, cy, sx, sy, cut_of, cut_p, cut_n, uvs, positions, pos):
    """Texel i's square as plain numbers, read once per texel for all its samples (`square_point`,
    `square_corner`): whether rays spread over it, its triangle's corners in pixels of its w × h
    lightmap (with their determinant) and in world space, its centre in pixels, its own position
    `pos[i]`, and its cut's two planes (validity.py; none where `cut_of[i]` < 0). The same helper
    handed sixteen arrays for every sample made the direct pass's ray generation about five times
    slower (numba keeps each array's reference count across the inlined call)."""
    t = tri[i]
    w, h = np.float64(sx[i]), np.float64(sy[i])
    ax, ay = uvs[t, 0, 0] * w, uvs[t, 0, 1] * h
    bx, by = uvs[t, 1, 0] * w, uvs[t, 1, 1] * h
    ex, ey = uvs[t, 2, 0] * w, uvs[t, 2, 1] * h
    den = (by - ey) * (ax - ex) + (ex - bx) * (ay - ey)
    p = positions[t]
    world = (np.float64(p[0, 0]), np.float64(p[0, 1]), np.float64(p[0, 2]), np.float64(p[1, 0]),
             np.float64(p[1, 1]), np.float64(p[1, 2]), np.float64(p[2, 0]), np.float64(p[2, 1]),
             np.float64(p[2, 2]))
    c = cut_of[i]
    cut = c >= 0
    k = max(c, 0)
    planes = (cut_p[k, 0, 0], cut_p[k, 0, 1], cut_p[k, 0, 2], cut_n[k, 0, 0], cut_n[k, 0, 1], cut_n[k, 0, 2],
              cut_p[k, 1, 0], cut_p[k, 1, 1], cut_p[k, 1, 2], cut_n[k, 1, 0], cut_n[k, 1, 1], cut_n[k, 1, 2])
    return (spread, (ax, ay, bx, by, ex, ey, den), (np.float64(cx[i]), np.float64(cy[i])), world,
            (np.float64(pos[i, 0]), np.float64(pos[i, 1]), np.float64(pos[i, 2])), cut, planes)


@inline
def _on_square_side(sq, px, py, pz):
    """Whether a point lies on the square's side of its cut (validity.on_side)."""
    if not sq[5]:
        return True
    q = sq[6]
    if (px - q[0]) * q[3] + (py - q[1]) * q[4] + (pz - q[2]) * q[5] < 0.0:
        return False
    return not (px - q[6]) * q[9] + (py - q[7]) * q[10] + (pz - q[8]) * q[11] < 0.0


@inline
def _square_at(sq, x, y):
    """(inside, px, py, pz): whether pixel point (x, y) lies on the square's triangle, and its world
    position when it does."""
    ax, ay, bx, by, ex, ey, den = sq[1]
    if den == 0.0:
        return False, 0.0, 0.0, 0.0
    l0 = ((by - ey) * (x - ex) + (ex - bx) * (y - ey)) / den
    l1 = ((ey - ay) * (x - ex) + (ax - ex) * (y - ey)) / den
    l2 = 1.0 - l0 - l1
    if l0 < 0.0 or l1 < 0.0 or l2 < 0.0:
        return False, 0.0, 0.0, 0.0
    p = sq[3]
    return (True, l0 * p[0] + l1 * p[3] + l2 * p[6], l0 * p[1] + l1 * p[4] + l2 * p[7],
            l0 * p[2] + l1 * p[5] + l2 * p[8])


@inline
def square_point(sq, j, samples, q0, q1):
    """Sample j of `samples` on texel square `sq` (square_of): a point of the square SPAN wide round
    its centre, rotated by (q0, q1), on its triangle and on its side of its cut; the texel's own
    position when no tried point lies there, or when rays do not spread."""
    if sq[0] and sq[1][6] != 0.0:
        cx, cy = sq[2]
        for attempt in range(TRIES):
            k = j + attempt * samples
            fx = _radical_inverse(k + 1, 3) + q0
            fy = _radical_inverse(k + 1, 5) + q1
            inside, px, py, pz = _square_at(sq, cx + SPAN * (fx - np.floor(fx) - 0.5),
                                            cy + SPAN * (fy - np.floor(fy) - 0.5))
            if inside and _on_square_side(sq, px, py, pz):
                return px, py, pz
    return sq[4]


@inline
def square_corner(sq, j, samples, q0, q1):
    """Sample j (0 … 3) of a texel's first rays for a light that adds rays where they disagree:
    corner j of the square SPAN wide round its centre, pulled in by CORNER_INSET. Any straight
    shadow edge that crosses the square has corners on both sides of it, so four corner rays
    see every such edge, where four points inside the square miss about half of them (a texel
    whose first rays agree takes no more, whatever the ray count: its error would not fall with
    more rays). A corner off the texel's triangle or cut falls back to square_point."""
    if sq[0]:
        reach = 0.5 * SPAN * (1.0 - CORNER_INSET)
        cx, cy = sq[2]
        inside, px, py, pz = _square_at(sq, cx + (reach if j % 2 == 1 else -reach),
                                        cy + (reach if (j // 2) % 2 == 1 else -reach))
        if inside and _on_square_side(sq, px, py, pz):
            return px, py, pz
    return square_point(sq, j, samples, q0, q1)


def texel_squares(texels, a: int = 0, b: int | None = None) -> tuple:
    """(tri, cx, cy, sx, sy, cut_of, cut_p, cut_n) for square_of, for texels a … b−1 (all by
    default; texel a is row 0): each texel's triangle, its centre in pixels, its lightmap's width
    and height, and its cut. By range, so that the direct pass holds them for one chunk of texels
    at a time instead of 24 bytes for every texel; the same float32 values as texel_centres."""
    b = len(texels) if b is None else b
    ends = np.array([lm.offset + lm.count for lm in texels.lightmaps], np.int64)
    which = np.searchsorted(ends, np.arange(a, b), side="right")  # each texel's lightmap
    sx = np.array([lm.width for lm in texels.lightmaps], np.float32)[which]
    sy = np.array([lm.height for lm in texels.lightmaps], np.float32)[which]
    width = np.maximum(sx.astype(np.int64), 1)
    pixel = texels.pixel[a:b].astype(np.int64)
    cx = (pixel % width).astype(np.float32) + np.float32(0.5)
    cy = (pixel // width).astype(np.float32) + np.float32(0.5)
    if texels.cuts is None:
        of, cut_p, cut_n = np.full(b - a, -1, np.int32), np.zeros((1, 2, 3)), np.zeros((1, 2, 3))
    else:
        of, cut_p, cut_n = texels.cuts.kernel_arrays()
        of = of[a:b]
    return (np.ascontiguousarray(texels.triangle[a:b], np.int32), cx, cy, sx, sy, of, cut_p, cut_n)


def spread_reach(texels, scene) -> np.ndarray:
    """Per texel, how far from its position its rays may start (a bound for the points square_point
    returns): half the diagonal of the SPAN-wide square on its triangle, in world metres, when its
    centre lies on the surface; at a chart's border, where its position is the point of its
    triangle nearest the centre, itself up to half a texel's diagonal away, that much more."""
    du, dv = pixel_steps(texels, scene)
    return np.where(texels.centre_inside, 0.5 * SPAN, 0.5 + 0.5 * SPAN) * (np.linalg.norm(du, axis=1)
                                                                          + np.linalg.norm(dv, axis=1))
