"""Texel validity: the part of a texel's square that light can reach from the texel's own side.

A texel is a square of surface, and other geometry may stand on it: a wall on a floor, a box on a
table. Light that falls on the square's far side of the wall is not light of the texel's side, and a
texel whose centre lies under the wall stands for nothing anyone sees. Read as they are, such
texels give a floor inside a sealed room a rim of sunlight from outside.

So before any light is gathered, every texel with geometry near it casts DIRECTIONS probe rays along
its surface (LIFT texel sizes above it, as far as its square reaches):
- a texel whose centre lies inside a solid (two opposite probes both meet faces from behind, as
  under a wall with thickness, or one probe does and so does a ray straight up from the surface, as
  under a box; a one-sided wall beside the texel is not a solid) moves its sample point
  just out of the solid, across the nearest face it met from behind: it takes the light of the side
  it is moved to (Godot's lightmapper "unoccludes" its texels the same way);
- the nearest face met (after the move, the face it moved across) cuts the texel's square along a
  line, and only the side of the sample point counts: direct light's shadow rays start there
  (texel_area.square_point), photon landings on the other side are left out and the texel's area is
  the area of surface on its side (texel histogram): of every triangle in its square, clipped to
  the square and to the cut lines' planes, as the landings are tested (`_near_areas`).
One cut a texel: in a corner where two walls cross one square, the nearer one.

A texel whose point lies against the front of another face (a box's bottom face standing on the
floor: the two faces coincide, back to back) is `covered`: no light reaches it, and Cycles' bake,
whose shadow rays skip only the point's own triangle and meet the floor at once, reads 0 there. A
shadow ray that starts a small offset off the surface would start under the floor instead and see
the sky below it (direct.py gives covered texels no direct light).

The denoiser must not carry light across a wall either. `regions` splits each lightmap's texels
into groups that see each other along the surface: neighbouring texels are linked unless a ray
between their sample points (lifted as above) is blocked. The bake denoises each group apart
(denoise.py). Only texels with a cut can lose a link, so the rays are few.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace

import numba
import numpy as np

from ..bvh import TriangleTree
from ..components import connected_components
from ..sampling import inline
from .texels import TexelSet, geometric_normals, lightmap_triangles, pixel_steps

DIRECTIONS = 8  # probe rays per texel, in opposite pairs
LIFT = 0.02  # probe height above the surface, in texel sizes
REACH = 0.75  # probe length, in texel sizes: past the half-diagonal of the square (0.707)
PUSH = 0.05  # how far past the face a moved sample point lands, in texel sizes
STANDING = np.cos(np.radians(45.0))  # faces steeper than this against the texel's surface stand on it
MIN_SHARE = 1.0 / 36  # the least share of its square's area a cut texel keeps
CHUNK = 1 << 13  # texels a probe task casts rays for: ~10 MB of float64 temporaries a task running
BLOCK = 1 << 18  # texels find_cuts holds float64 sizes, normals and discs for at once (all_regions: pairs)
NEIGHBOURS = 3.0  # texel sizes: neighbours in the image further apart than this are not tested (regions)


@dataclass
class Cuts:
    """Per texel with a cut, the two lines that bound its square (the second's normal 0 where only
    one wall crosses it): a point on each and its unit normal (in the texel's tangent plane)
    towards the texel's side, and the share of the square on that side."""
    of: np.ndarray  # (N,) int32: each texel's row below, −1 where nothing cuts it
    point: np.ndarray  # (C, 2, 3) float64
    normal: np.ndarray  # (C, 2, 3) float64
    share: np.ndarray  # (C,) float64, MIN_SHARE … 1
    moved: np.ndarray = None  # (N,) bool: the texel's centre lay inside a solid and was moved out
    covered: np.ndarray = None  # (N,) bool: the texel's point lies against the front of another face

    @classmethod
    def none(cls, n: int) -> "Cuts":
        return cls(np.full(n, -1, np.int32), np.zeros((0, 2, 3)), np.zeros((0, 2, 3)), np.zeros(0), np.zeros(n, bool),
                   np.zeros(n, bool))

    def select(self, mask: np.ndarray) -> "Cuts":
        return Cuts(self.of[mask], self.point, self.normal, self.share, self.moved[mask],
                    None if self.covered is None else self.covered[mask])

    def kernel_arrays(self) -> tuple:
        """(of, point, normal) for the compiled kernels: at least one row each, so numba sees arrays."""
        point = self.point if len(self.point) else np.zeros((1, 2, 3))
        normal = self.normal if len(self.normal) else np.zeros((1, 2, 3))
        return (np.ascontiguousarray(self.of, np.int32), np.ascontiguousarray(point, np.float64),
                np.ascontiguousarray(normal, np.float64))


@inline
def on_side(cut_of, cut_p, cut_n, i, x, y, z):
    """Whether point (x, y, z) lies on texel i's side of its cut (compiled kernels)."""
    c = cut_of[i]
    if c < 0:
        return True
    for line in range(2):
        if ((x - cut_p[c, line, 0]) * cut_n[c, line, 0] + (y - cut_p[c, line, 1]) * cut_n[c, line, 1]
                + (z - cut_p[c, line, 2]) * cut_n[c, line, 2]) < 0.0:
            return False
    return True


def _frame(g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.where(np.abs(g[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t = np.cross(g, helper)
    t /= np.linalg.norm(t, axis=1)[:, None]
    return t, np.cross(g, t)


def _probe(caster, origin, g, reach):
    """Probe rays of each texel: (directions (D, n, 3), distances (D, n) inf where nothing, unit
    face normals (D, n, 3) as Embree orients them)."""
    t, s = _frame(g)
    angle = 2.0 * np.pi * np.arange(DIRECTIONS) / DIRECTIONS
    d = np.cos(angle)[:, None, None] * t + np.sin(angle)[:, None, None] * s
    o = np.ascontiguousarray(np.tile(origin, (DIRECTIONS, 1)), np.float32)
    far = np.tile(reach.astype(np.float32), DIRECTIONS)
    dist, prim, ng = caster.intersect(o, np.ascontiguousarray(d.reshape(-1, 3), np.float32), far)
    dist = np.where(prim >= 0, dist, np.inf).reshape(DIRECTIONS, -1).astype(np.float64)
    ng = ng.reshape(DIRECTIONS, -1, 3).astype(np.float64)
    ng /= np.maximum(np.linalg.norm(ng, axis=2, keepdims=True), 1e-300)
    # A face within 45° of the texel's own plane is its own surface curving up (the inside of a
    # sphere, a fillet), not something standing on it.
    dist[np.abs(np.einsum("knc,nc->kn", ng, g)) >= STANDING] = np.inf
    return d, dist, ng


def _towards(ng, g, way, back):
    """Unit normals of faces met along `way`, laid into the tangent plane (normal `g`) and turned
    towards `back` (from the face to the sample point); along −`way` for a face parallel to it."""
    m = ng - np.einsum("nc,nc->n", ng, g)[:, None] * g
    length = np.linalg.norm(m, axis=1)
    m = np.where((length > 0.2)[:, None], m / np.maximum(length, 1e-300)[:, None], -way)
    m[np.einsum("nc,nc->n", back, m) < 0.0] *= -1.0
    return m


def _cut_chunk(caster, pos, g, size):
    """Cuts of one chunk of texels near geometry: (moved position, whether moved, has a cut, points,
    normals)."""
    n = len(pos)
    lift = LIFT * size
    d, dist, ng = _probe(caster, pos + lift[:, None] * g, g, REACH * size)
    hit = np.isfinite(dist)
    back = hit & (np.einsum("knc,knc->kn", ng, d) > 0.0)
    half = DIRECTIONS // 2
    inside = (back[:half] & back[half:]).any(axis=0)
    maybe = np.flatnonzero(back.any(axis=0) & ~inside)
    if maybe.size:  # under a solid wider than the probes reach: its top is met from behind too
        up = g[maybe]
        o = np.ascontiguousarray(pos[maybe] + lift[maybe, None] * up, np.float32)
        far = np.full(maybe.size, 1e30, np.float32)
        _, prim, ng_up = caster.intersect(o, np.ascontiguousarray(up, np.float32), far)
        inside[maybe] = (prim >= 0) & (np.einsum("nc,nc->n", ng_up.astype(np.float64), up) > 0.0)
    rows = np.arange(n)
    # The face to cross (inside a solid) or to stop at (otherwise): the nearest one met from
    # behind, or the nearest one met at all.
    pick = np.where(inside, np.argmin(np.where(back, dist, np.inf), axis=0), np.argmin(dist, axis=0))
    has = hit.any(axis=0)
    way = d[pick, rows]
    along = np.where(has, dist[pick, rows], 0.0)
    point = pos + way * along[:, None]
    moved = pos + way * (along + PUSH * size)[:, None]
    new_pos = np.where(inside[:, None], moved, pos)
    m = _towards(ng[pick, rows], g, way, new_pos - point)
    # A second line where another wall crosses the square (a corner): the nearest face met that
    # does not lie along the first.
    m_all = np.stack([_towards(ng[k], g, d[k], new_pos - (pos + d[k] * np.where(hit[k], dist[k], 0.0)[:, None]))
                      for k in range(DIRECTIONS)])
    other = hit & (np.abs(np.einsum("knc,nc->kn", m_all, m)) < 0.9)
    second = np.argmin(np.where(other, dist, np.inf), axis=0)
    has2 = other.any(axis=0)
    point2 = pos + d[second, rows] * np.where(has2, dist[second, rows], 0.0)[:, None]
    m2 = np.where(has2[:, None], m_all[second, rows], 0.0)
    return new_pos, inside & has, has, np.stack([point, point2], axis=1), np.stack([m, m2], axis=1)


@numba.njit(cache=True)
def _clip(xs, ys, fs, n, bx, by):
    """Clip the convex polygon (xs, ys)[:n] to where the affine function with vertex values fs is
    at least 0, in place (bx, by: scratch); returns its new vertex count."""
    m = 0
    for a in range(n):
        b = (a + 1) % n
        if fs[a] >= 0.0:
            bx[m], by[m] = xs[a], ys[a]
            m += 1
        if (fs[a] >= 0.0) != (fs[b] >= 0.0):
            f = fs[a] / (fs[a] - fs[b])
            bx[m], by[m] = xs[a] + f * (xs[b] - xs[a]), ys[a] + f * (ys[b] - ys[a])
            m += 1
    for a in range(m):
        xs[a], ys[a] = bx[a], by[a]
    return m


@numba.njit(cache=True)
def _near_areas(uv, positions, world_area, sides, base, texel_of, cut_of, cut_p, cut_n, out):
    """out[c] += the world area of the triangles (UVs `uv` in 0..1, world `positions`; in a lightmap
    of `sides` (width, height) whose pixels' texels are texel_of[base:], −1 for none) inside the
    square of the texel with cut c on that texel's side of both its cut lines: what the texel
    histogram's landings are tested against (on_side)."""
    xs, ys, fs = np.empty(16), np.empty(16), np.empty(16)
    bx, by = np.empty(16), np.empty(16)
    for t in range(uv.shape[0]):
        width, height = sides[t, 0], sides[t, 1]
        ax, ay = uv[t, 0, 0] * width, uv[t, 0, 1] * height
        ex, ey = uv[t, 1, 0] * width, uv[t, 1, 1] * height
        gx, gy = uv[t, 2, 0] * width, uv[t, 2, 1] * height
        den = (ey - gy) * (ax - gx) + (gx - ex) * (ay - gy)
        if abs(den) <= 1e-12:
            continue
        scale = world_area[t] / (0.5 * abs(den))
        i0 = max(0, int(np.floor(min(ax, min(ex, gx)))))
        i1 = min(width - 1, int(np.floor(max(ax, max(ex, gx)))))
        j0 = max(0, int(np.floor(min(ay, min(ey, gy)))))
        j1 = min(height - 1, int(np.floor(max(ay, max(ey, gy)))))
        for j in range(j0, j1 + 1):
            for i in range(i0, i1 + 1):
                k = texel_of[base[t] + j * width + i]
                if k < 0 or cut_of[k] < 0:
                    continue
                c = cut_of[k]
                xs[0], xs[1], xs[2] = ax, ex, gx
                ys[0], ys[1], ys[2] = ay, ey, gy
                n = 3
                for edge in range(6):  # the square's four sides, then the two cut lines
                    for a in range(n):
                        if edge == 0:
                            fs[a] = xs[a] - i
                        elif edge == 1:
                            fs[a] = i + 1.0 - xs[a]
                        elif edge == 2:
                            fs[a] = ys[a] - j
                        elif edge == 3:
                            fs[a] = j + 1.0 - ys[a]
                        else:
                            line = edge - 4
                            l0 = ((ey - gy) * (xs[a] - gx) + (gx - ex) * (ys[a] - gy)) / den
                            l1 = ((gy - ay) * (xs[a] - gx) + (ax - gx) * (ys[a] - gy)) / den
                            l2 = 1.0 - l0 - l1
                            f = 0.0
                            for q in range(3):
                                p = l0 * positions[t, 0, q] + l1 * positions[t, 1, q] + l2 * positions[t, 2, q]
                                f += (p - cut_p[c, line, q]) * cut_n[c, line, q]
                            fs[a] = f
                    n = _clip(xs, ys, fs, n, bx, by)
                    if n < 3:
                        break
                if n < 3:
                    continue
                area = 0.0
                for a in range(n):
                    b = (a + 1) % n
                    area += xs[a] * ys[b] - xs[b] * ys[a]
                out[c] += scale * 0.5 * abs(area)


def _shares(texels: TexelSet, scene, cuts: Cuts) -> np.ndarray:
    """Per cut, the share of its texel's area (all surface in its square) on the texel's side of its
    cut lines, at least MIN_SHARE."""
    near = np.zeros(len(cuts.share))
    _, cut_p, cut_n = cuts.kernel_arrays()
    world_area = 0.5 * np.linalg.norm(np.cross(scene.positions[:, 1] - scene.positions[:, 0],
                                               scene.positions[:, 2] - scene.positions[:, 0]), axis=1)
    # Every lightmap with a cut at once: each triangle reads the texels of its own lightmap's pixels.
    lms = [texels.lightmaps[i] for i in _with_cuts(texels, cuts)]
    tris = [lightmap_triangles(scene, lm) for lm in lms]
    tri, own = np.concatenate(tris), np.repeat(np.arange(len(lms)), [len(t) for t in tris])
    sides = np.array([[lm.width, lm.height] for lm in lms], np.int64)
    base = np.cumsum([0] + [lm.width * lm.height for lm in lms])
    node = np.concatenate([np.arange(lm.offset, lm.offset + lm.count) for lm in lms])
    texel_of = np.full(int(base[-1]), -1, np.int32)  # 4 bytes a pixel, not 8: fewer than 2³¹ texels
    texel_of[base[np.repeat(np.arange(len(lms)), [lm.count for lm in lms])] + texels.pixel[node]] = node
    _near_areas(np.ascontiguousarray(scene.uvs[tri], np.float64), np.ascontiguousarray(scene.positions[tri], np.float64),
                np.ascontiguousarray(world_area[tri], np.float64), sides[own], base[own].astype(np.int64), texel_of,
                np.ascontiguousarray(cuts.of), cut_p, cut_n, near)
    owner = np.empty(len(near), np.int64)
    owner[cuts.of[cuts.of >= 0]] = np.flatnonzero(cuts.of >= 0)
    return np.clip(near / np.maximum(texels.area[owner].astype(np.float64), 1e-300), MIN_SHARE, 1.0)


class _Triangles(TriangleTree):
    """The scene's triangle tree, built once for the whole of find_cuts (bvh's one-call functions
    build it on every call, 0.5 s a million triangles), with the triangles' front faces and the
    shadow rays' offset its face-to-face test needs."""

    def __init__(self, scene):
        super().__init__(scene.positions)
        p = self.tri
        facing = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        facing /= np.maximum(np.linalg.norm(facing, axis=1, keepdims=True), 1e-300)
        shading = scene.normals.astype(np.float64).sum(axis=1)
        facing[np.einsum("ij,ij->i", facing, shading) < 0.0] *= -1.0
        self.facing = facing
        self.offset = scene.ray_offset()

    def covered(self, point, g, own) -> np.ndarray:
        """Per point (on triangle `own`, geometric normal `g`), whether the front of another face lies
        against it, within twice the shadow rays' offset in front of it (direct.py)."""
        return self.faces_against(self.facing, point, g, own, np.full(len(point), 2.0 * self.offset))


def _subset(texels: TexelSet, rows) -> TexelSet:
    """Texels `rows` (a slice: views, no copies; or ascending indices) as a TexelSet of the lightmaps
    that hold some of them, each counting only those, so that the per-texel helpers (pixel_steps)
    run on a block at a time. Lightmaps with none are left out: a block of 1,500 small objects'
    texels holds a few of them, and each one kept costs a copy of its Lightmap."""
    start = np.array([lm.offset for lm in texels.lightmaps], np.int64)
    end = start + np.array([lm.count for lm in texels.lightmaps], np.int64)
    if isinstance(rows, slice):
        lo, hi = (np.clip(k, rows.start, rows.stop) - rows.start for k in (start, end))
    else:
        lo, hi = np.searchsorted(rows, start), np.searchsorted(rows, end)
    lightmaps = [replace(texels.lightmaps[i], offset=int(lo[i]), count=int(hi[i] - lo[i]))
                 for i in np.flatnonzero(hi > lo)]
    return TexelSet(texels.position[rows], texels.normal[rows], texels.triangle[rows], texels.pixel[rows],
                    texels.area[rows], texels.centre_inside[rows], lightmaps)


def _frames(sub: TexelSet, scene) -> tuple[np.ndarray, np.ndarray]:
    """(texel size: the mean of its two pixel steps, 0 where the UVs are degenerate; unit geometric
    normal) of each texel of `sub`."""
    du, dv = pixel_steps(sub, scene)
    size = 0.5 * (np.linalg.norm(du, axis=1) + np.linalg.norm(dv, axis=1))
    size = np.where(np.isfinite(size) & (size > 0), size, 0.0)
    return size, geometric_normals(scene, sub.triangle, sub.normal)


def _candidates(texels: TexelSet, scene, tris: _Triangles) -> np.ndarray:
    """The texels (ascending) with geometry near enough their square to need probe rays, found
    BLOCK texels at a time: their float64 sizes, normals and discs never exist for all at once."""
    todo = np.zeros(len(texels), bool)
    for a in range(0, len(texels), BLOCK):
        sub = _subset(texels, slice(a, min(a + BLOCK, len(texels))))
        size, g = _frames(sub, scene)
        near = tris.discs_meet(sub.position + (LIFT * size)[:, None] * g, g, REACH * size)
        todo[a:a + len(sub)] = near & (size > 0)
    return np.flatnonzero(todo).astype(np.int32)  # held while probing: half of int64's size


def _probe_all(texels: TexelSet, scene, caster, todo: np.ndarray, cuts: Cuts, threads: int) -> None:
    """Probe the texels `todo` CHUNK at a time over `threads`; moves their positions, fills the cut
    rows of `cuts` in texel order. Each chunk's results are written as it comes back and its cut rows
    copied once into the final arrays."""
    def work(idx):
        sub = _subset(texels, idx)
        size, g = _frames(sub, scene)
        new_pos, inside, has, point, m = _cut_chunk(caster, sub.position, g, size)
        return idx, new_pos, inside, has, point[has], m[has]

    points, normals = [], []
    rows = 0
    chunks = [todo[a:a + CHUNK] for a in range(0, todo.size, CHUNK)]
    with ThreadPoolExecutor(max(1, int(threads))) as pool:
        for idx, new_pos, inside, has, point, m in pool.map(work, chunks):
            texels.position[idx] = new_pos
            cuts.moved[idx] = inside
            cut = idx[has]
            cuts.of[cut] = rows + np.arange(cut.size, dtype=np.int32)
            rows += cut.size
            points.append(point)
            normals.append(m)
    cuts.point, cuts.normal = _gather(points), _gather(normals)
    cuts.share = np.ones(rows)
    if rows:
        cuts.share = _shares(texels, scene, cuts)


def _gather(parts: list) -> np.ndarray:
    """np.concatenate(parts), each part let go once copied: the parts and the whole are not all
    held at once."""
    out = np.empty((sum(len(p) for p in parts),) + parts[0].shape[1:], parts[0].dtype)
    at = 0
    while parts:
        p = parts.pop(0)
        out[at:at + len(p)] = p
        at += len(p)
    return out


def find_cuts(texels: TexelSet, scene, caster, threads: int = 1) -> Cuts:
    """The cuts of every texel with geometry standing on its square; texels whose centre lies inside
    a solid have their `position` moved out, in place (module docstring). Works BLOCK (CHUNK while
    probing) texels at a time so that its float64 temporaries stay a few megabytes: it keeps about 6
    bytes a texel, plus 100 a cut texel."""
    n = len(texels)
    cuts = Cuts.none(n)
    if n == 0:
        return cuts
    tris = _Triangles(scene)
    todo = _candidates(texels, scene, tris)
    if todo.size:
        _probe_all(texels, scene, caster, todo, cuts, threads)
    del todo
    # After the moves: a moved texel's point is tested where it now lies.
    for a in range(0, n, BLOCK):
        sl = slice(a, min(a + BLOCK, n))
        g = geometric_normals(scene, texels.triangle[sl], texels.normal[sl])
        cuts.covered[sl] = tris.covered(texels.position[sl], g, texels.triangle[sl])
    return cuts


def blocked_between(texels: TexelSet, i: np.ndarray, j: np.ndarray, lift, caster, scene,
                    threads: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(whether a ray from texel i's sample point to texel j's, both lifted `lift` metres (one for
    all, or one a pair) off their faces, meets anything on the way; the rays' lengths) for the
    texel pairs (i, j)."""
    gi = geometric_normals(scene, texels.triangle[i], texels.normal[i])
    gj = geometric_normals(scene, texels.triangle[j], texels.normal[j])
    lift = np.asarray(lift, np.float64)
    lift = lift[:, None] if lift.ndim else lift
    a = texels.position[i] + lift * gi
    span = texels.position[j] + lift * gj - a
    length = np.linalg.norm(span, axis=1)
    return caster.blocked(a, span / np.maximum(length, 1e-300)[:, None], length, threads), length


def regions(texels: TexelSet, lm, cuts: Cuts, caster, scene) -> np.ndarray:
    """(H, W) int32 image of lightmap `lm`: each covered texel's group of texels that see each other
    along the surface (0, 1, …; −1 in the gutter). Neighbours (8 ways) are linked unless a ray
    between their sample points, lifted off the surface, is blocked; only texels with a cut, less
    than NEIGHBOURS texels apart, can lose a link."""
    at = next(i for i, m in enumerate(texels.lightmaps) if m.name == lm.name)
    return _regions_of(texels, np.array([at]), cuts, caster, scene)[lm.name]


def all_regions(texels: TexelSet, cuts: Cuts, caster, scene, threads: int = 1) -> dict:
    """{name: `regions` of each lightmap with a cut texel}, found whole lightmaps at a time, about
    BLOCK texels (their pairs take some 150 bytes a texel)."""
    which = _with_cuts(texels, cuts)
    bounds = whole_batches(np.cumsum([0] + [texels.lightmaps[i].count for i in which]), BLOCK)
    out = {}
    for a, b in zip(bounds[:-1], bounds[1:]):
        out.update(_regions_of(texels, which[a:b], cuts, caster, scene, threads))
    return out


def whole_batches(ends: np.ndarray, per: int) -> np.ndarray:
    """Bounds (indices into the parts, ascending, from 0 to the last) of runs of whole parts of
    about `per` items each, the parts' items ending at `ends` (cumulative, from 0): a part larger
    than `per` is a run of its own."""
    return np.unique(np.append(np.searchsorted(ends, np.arange(0, ends[-1], per), side="right") - 1, len(ends) - 1))


def _with_cuts(texels: TexelSet, cuts: Cuts) -> np.ndarray:
    """Indices of the lightmaps with a cut texel, ascending."""
    per = np.repeat(np.arange(len(texels.lightmaps)), [lm.count for lm in texels.lightmaps])
    return np.flatnonzero(np.bincount(per[cuts.of >= 0], minlength=len(texels.lightmaps)))


def _regions_of(texels: TexelSet, which: np.ndarray, cuts: Cuts, caster, scene, threads: int = 1) -> dict:
    """`regions` of the lightmaps `which` (indices, ascending), all at once: their pairs of
    neighbours from one grid of all their pixels, one call for the rays and one for the components
    (1,500 small objects, a pass each, took a second). Components never cross lightmaps and are
    numbered by their first texel, so each lightmap's labels run on from its first texel's."""
    lms = [texels.lightmaps[i] for i in which]
    count = np.array([lm.count for lm in lms], np.int64)
    node = np.concatenate([np.arange(lm.offset, lm.offset + lm.count) for lm in lms]) if lms else np.zeros(0, int)
    own = np.repeat(np.arange(len(lms)), count)
    size = np.array([lm.texel_size for lm in lms], np.float64)
    pixel = texels.pixel[node].astype(np.int64)
    sides = np.array([[lm.width, lm.height] for lm in lms], np.int64).reshape(-1, 2)
    pairs = _pairs(pixel, own, sides, np.cumsum([0] + [lm.width * lm.height for lm in lms]))
    keep = np.ones(len(pairs), bool)
    cut = cuts.of[node] >= 0
    test = np.flatnonzero(cut[pairs[:, 0]] | cut[pairs[:, 1]])
    if test.size:
        i, j = pairs[test, 0], pairs[test, 1]
        own_size = size[own[i]]
        blocked, length = blocked_between(texels, node[i], node[j], LIFT * own_size, caster, scene, threads)
        # Neighbours in the image that lie far apart on the surface are two charts side by side in
        # the atlas: the denoiser has always seen them as one image, and no wall is to blame.
        near = (length > 0) & (length < NEIGHBOURS * own_size)
        keep[test[blocked & near]] = False
    links = pairs[keep]
    _, label = connected_components(len(node), links[:, 0], links[:, 1])
    out, at = {}, 0
    for lm in lms:
        image = np.full(lm.width * lm.height, -1, np.int32)
        if lm.count:
            image[pixel[at:at + lm.count]] = label[at:at + lm.count] - label[at]
        out[lm.name] = image.reshape(lm.height, lm.width)
        at += lm.count
    return out


@numba.njit(cache=True)
def _pairs(pixel, own, sides, base):
    """(P, 2) the pairs (a, b) of texels (rows of `pixel`, each a pixel of lightmap own[a], whose
    sides[own[a]] are its width and height and whose pixels are numbered on from base[own[a]])
    that are 8-neighbours in their image, each pair once: b right of a, above it, above and right,
    or above and left."""
    n = pixel.shape[0]
    grid = np.full(base[-1], -1, np.int32)  # 4 bytes a pixel: fewer than 2³¹ texels
    for a in range(n):
        grid[base[own[a]] + pixel[a]] = a
    step_x, step_y = np.array([1, 0, 1, -1]), np.array([0, 1, 1, 1])
    out = np.empty((4 * n, 2), np.int64)
    m = 0
    for a in range(n):
        w, h = sides[own[a], 0], sides[own[a], 1]
        x, y = pixel[a] % w, pixel[a] // w
        for d in range(4):
            if 0 <= x + step_x[d] < w and y + step_y[d] < h:
                b = grid[base[own[a]] + pixel[a] + step_y[d] * w + step_x[d]]
                if b >= 0:
                    out[m, 0], out[m, 1] = a, b
                    m += 1
    return out[:m].copy()


def by_object(texels: TexelSet, lm, scene, regions=None) -> np.ndarray:
    """(H, W) int32 labels of an atlas `lm` (−1 in the gutter): its `regions` (or one per object)
    split by object, so that the denoiser keeps every object's light to itself."""
    sl = lm.texels
    starts = np.array([scene.objects[i].first_triangle for i in lm.members])
    owner = np.searchsorted(starts, texels.triangle[sl], side="right") - 1
    base = np.zeros(lm.count, np.int64) if regions is None else regions.reshape(-1)[texels.pixel[sl]].astype(np.int64)
    _, label = np.unique(owner * (int(base.max()) + 1) + base, return_inverse=True)
    out = np.full(lm.width * lm.height, -1, np.int32)
    out[texels.pixel[sl]] = label.reshape(-1)
    return out.reshape(lm.height, lm.width)
