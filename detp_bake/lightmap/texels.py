"""Lightmap texels: which surface point each texel stands for (the gutter is filled by dilation.py).

Rasterisation is conservative: a texel counts as covered when its square can touch a UV triangle
(centre within half a diagonal of it), so texels along chart borders are baked too and no black
seams appear under bilinear filtering. A covered texel takes the triangle nearest its centre and the
nearest point of that triangle, so its world position always lies on the surface.

Image layout: texel (i, j) has its centre at UV ((i + ½)/W, (j + ½)/H); row j = 0 is v = 0, the
bottom row, as in Blender's `Image.pixels`. Files are written top row first (see images.py).
"""
from __future__ import annotations

import contextlib
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Optional

import numba
import numpy as np

from . import charts as charts_mod
from ..bvh import discs_meet_triangles
from ..errors import BakeError
from ..rays import RayCaster
from ..scene import Scene

HALF_DIAGONAL_SQ = 0.5  # (√2 / 2)², in texel units


@dataclass
class Lightmap:
    """One image and its run of texels in the TexelSet: one object's lightmap, or an atlas that
    holds the charts of several (`objects`), each texel belonging to the object of its triangle."""
    name: str
    object_index: int  # the (first) object whose charts it holds
    width: int
    height: int
    offset: int
    count: int
    texel_size: float  # world metres per texel (area-weighted over the object)
    # UV layouts that give silently wrong lightmaps (the bake warns): the share of covered texels
    # whose centre lies on two or more UV triangles (overlapping faces, Array copies sharing UVs),
    # and the share of the UV area outside 0..1 (not baked at all).
    overlap: float = 0.0
    outside: float = 0.0
    # The UV charts (charts.py): how many, the median one's width in texels (the side of a square of
    # its area), and the share of covered texels on a chart's border (a 4-neighbour not of its chart).
    charts: int = 0
    chart_width: float = 0.0
    border: float = 0.0

    # Each of its triangles' chart width in texels (charts.chart_widths, in lightmap_triangles' order),
    # set by `rasterise`; the denoiser's fragments read it (fragments.chart_widths_of).
    triangle_widths: Optional[np.ndarray] = None
    objects: tuple = ()  # an atlas: every object in it, in scene order (else empty: object_index alone)
    # An atlas: {object name: {"texels": its covered texels, "rect": [x0, y0, x1, y1] the pixels its
    # charts span (x1, y1 exclusive), "texel_size": metres per texel}} (report.json).
    placement: dict = field(default_factory=dict)

    @property
    def texels(self) -> slice:
        return slice(self.offset, self.offset + self.count)

    @property
    def members(self) -> tuple:
        """The indices of the objects whose charts the image holds."""
        return tuple(self.objects) or (self.object_index,)


def lightmap_triangles(scene: Scene, lm: Lightmap) -> np.ndarray:
    """The scene's triangles whose charts lie in lightmap `lm`, ascending (objects are runs of
    consecutive triangles in scene order): `np.searchsorted` of it turns a texel's triangle into
    an index into per-triangle arrays of the lightmap."""
    objs = [scene.objects[i] for i in lm.members]
    if len(objs) == 1:
        return np.arange(objs[0].first_triangle, objs[0].first_triangle + objs[0].triangle_count)
    return np.concatenate([np.arange(o.first_triangle, o.first_triangle + o.triangle_count) for o in objs])


@dataclass
class TexelSet:
    """All covered texels of all baked objects, concatenated object by object."""
    # Positions and normals stay float64: discs far from the origin and the lattice patches'
    # 1e-9 normal tolerance (estimators/patches.py) need it. The rest is as small as it can be.
    position: np.ndarray  # (N, 3) float64, on the surface
    normal: np.ndarray  # (N, 3) float64, unit shading normal
    triangle: np.ndarray  # (N,) int32
    pixel: np.ndarray  # (N,) int32, j * W + i within its lightmap (W, H ≤ 16384)
    area: np.ndarray  # (N,) float32, world area of surface inside the texel's square (sums to the total)
    centre_inside: np.ndarray  # (N,) bool: the texel centre lies on a UV triangle (Cycles bakes only these)
    lightmaps: list[Lightmap]
    cuts: object = None  # validity.Cuts once the bake has looked for geometry on the texels' squares

    def __len__(self) -> int:
        return len(self.pixel)

    def per_texel(self, per_lightmap: np.ndarray) -> np.ndarray:
        """Broadcast one value per lightmap to one per texel."""
        return np.repeat(np.asarray(per_lightmap, np.float64), [lm.count for lm in self.lightmaps])


@numba.njit(cache=True)
def _closest_on_triangle(px, py, ax, ay, bx, by, cx, cy):
    """Barycentrics (of A, B, C) of the point of triangle ABC nearest P, in 2D (Ericson §5.1.5)."""
    abx, aby, acx, acy = bx - ax, by - ay, cx - ax, cy - ay
    apx, apy = px - ax, py - ay
    d1 = abx * apx + aby * apy
    d2 = acx * apx + acy * apy
    if d1 <= 0.0 and d2 <= 0.0:
        return 1.0, 0.0, 0.0
    bpx, bpy = px - bx, py - by
    d3 = abx * bpx + aby * bpy
    d4 = acx * bpx + acy * bpy
    if d3 >= 0.0 and d4 <= d3:
        return 0.0, 1.0, 0.0
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return 1.0 - v, v, 0.0
    cpx, cpy = px - cx, py - cy
    d5 = abx * cpx + aby * cpy
    d6 = acx * cpx + acy * cpy
    if d6 >= 0.0 and d5 <= d6:
        return 0.0, 0.0, 1.0
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return 1.0 - w, 0.0, w
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return 0.0, 1.0 - w, w
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return 1.0 - v - w, v, w


@numba.njit(cache=True)
def _clip_area(xs, ys, n, x0, y0, x1, y1):
    """Area of the convex polygon (xs, ys)[:n] clipped to the box [x0, x1] × [y0, y1]."""
    bx = np.empty(12)
    by = np.empty(12)
    for edge in range(4):
        m = 0
        for a in range(n):
            b = (a + 1) % n
            if edge == 0:
                da, db = xs[a] - x0, xs[b] - x0
            elif edge == 1:
                da, db = x1 - xs[a], x1 - xs[b]
            elif edge == 2:
                da, db = ys[a] - y0, ys[b] - y0
            else:
                da, db = y1 - ys[a], y1 - ys[b]
            if da >= 0.0:
                bx[m] = xs[a]
                by[m] = ys[a]
                m += 1
            if (da >= 0.0) != (db >= 0.0):
                f = da / (da - db)
                bx[m] = xs[a] + f * (xs[b] - xs[a])
                by[m] = ys[a] + f * (ys[b] - ys[a])
                m += 1
        n = m
        for a in range(n):
            xs[a] = bx[a]
            ys[a] = by[a]
        if n < 3:
            return 0.0
    area = 0.0
    for a in range(n):
        b = (a + 1) % n
        area += xs[a] * ys[b] - xs[b] * ys[a]
    return 0.5 * abs(area)


@numba.njit(cache=True)
def _rasterise(uv, world_area, width, height, best_tri, best_d2, cover, inside):
    """For each texel, the UV triangle nearest its centre within half a texel diagonal, the
    world area of surface inside the texel's square (`cover`), summed over triangles, and how many
    triangles hold its centre strictly inside (`inside`: 2 or more is an overlap). Returns the UV
    area (in texels²) of all triangles, and of their parts inside 0..1. The nearest point's
    barycentrics are not kept (24 bytes a pixel): _surface finds them again, the same floats."""
    xs = np.empty(12)
    ys = np.empty(12)
    total = 0.0
    within = 0.0
    for t in range(uv.shape[0]):
        ax, ay = uv[t, 0, 0] * width, uv[t, 0, 1] * height
        bx, by = uv[t, 1, 0] * width, uv[t, 1, 1] * height
        cx, cy = uv[t, 2, 0] * width, uv[t, 2, 1] * height
        uv_area = 0.5 * abs((bx - ax) * (cy - ay) - (by - ay) * (cx - ax))
        if uv_area <= 1e-12:
            continue
        total += uv_area
        xs[0], xs[1], xs[2] = ax, bx, cx
        ys[0], ys[1], ys[2] = ay, by, cy
        within += _clip_area(xs, ys, 3, 0.0, 0.0, float(width), float(height))
        twice = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)  # signed: either winding
        scale = world_area[t] / uv_area
        i0 = max(0, int(np.floor(min(ax, min(bx, cx)) - 1.5)))
        i1 = min(width - 1, int(np.ceil(max(ax, max(bx, cx)) + 0.5)))
        j0 = max(0, int(np.floor(min(ay, min(by, cy)) - 1.5)))
        j1 = min(height - 1, int(np.ceil(max(ay, max(by, cy)) + 0.5)))
        for j in range(j0, j1 + 1):
            py = j + 0.5
            for i in range(i0, i1 + 1):
                px = i + 0.5
                w0, w1, w2 = _closest_on_triangle(px, py, ax, ay, bx, by, cx, cy)
                qx = w0 * ax + w1 * bx + w2 * cx
                qy = w0 * ay + w1 * by + w2 * cy
                d2 = (qx - px) ** 2 + (qy - py) ** 2
                k = j * width + i
                if d2 > HALF_DIAGONAL_SQ:
                    continue
                xs[0], xs[1], xs[2] = ax, bx, cx
                ys[0], ys[1], ys[2] = ay, by, cy
                cover[k] += scale * _clip_area(xs, ys, 3, px - 0.5, py - 0.5, px + 0.5, py + 0.5)
                if d2 < 1e-12:
                    # Strictly inside (a centre on a shared edge belongs to neither side).
                    ea = ((bx - px) * (cy - py) - (by - py) * (cx - px)) / twice
                    eb = ((cx - px) * (ay - py) - (cy - py) * (ax - px)) / twice
                    if ea > 1e-9 and eb > 1e-9 and 1.0 - ea - eb > 1e-9:
                        inside[k] += 1
                if d2 < best_d2[k] - 1e-12:
                    best_d2[k] = d2
                    best_tri[k] = t
    return total, within


@numba.njit(cache=True, parallel=True)
def _surface(pixel, local, tri, uv, width, height, positions, normals, position, normal):
    """Each covered texel's surface point and unit shading normal (the face normal where the
    shading normals cancel out), written straight into the TexelSet's rows: no (N, 3, 3) gathers.
    The point is the one of its triangle (`local` into `uv`, as _rasterise numbered them; `tri` in
    the scene) nearest its centre, found by the same arithmetic as _rasterise's."""
    for q in numba.prange(pixel.shape[0]):
        k = pixel[q]
        t = tri[q]
        u = local[q]
        w0, w1, w2 = _closest_on_triangle((k % width) + 0.5, (k // width) + 0.5,
                                          uv[u, 0, 0] * width, uv[u, 0, 1] * height, uv[u, 1, 0] * width,
                                          uv[u, 1, 1] * height, uv[u, 2, 0] * width, uv[u, 2, 1] * height)
        for c in range(3):
            position[q, c] = (w0 * np.float64(positions[t, 0, c]) + w1 * np.float64(positions[t, 1, c])
                              + w2 * np.float64(positions[t, 2, c]))
        nx = w0 * np.float64(normals[t, 0, 0]) + w1 * np.float64(normals[t, 1, 0]) + w2 * np.float64(normals[t, 2, 0])
        ny = w0 * np.float64(normals[t, 0, 1]) + w1 * np.float64(normals[t, 1, 1]) + w2 * np.float64(normals[t, 2, 1])
        nz = w0 * np.float64(normals[t, 0, 2]) + w1 * np.float64(normals[t, 1, 2]) + w2 * np.float64(normals[t, 2, 2])
        if np.sqrt(nx * nx + ny * ny + nz * nz) < 1e-8:
            # In the scene's own precision, as the face normal always was.
            ax, ay, az = positions[t, 1, 0] - positions[t, 0, 0], positions[t, 1, 1] - positions[t, 0, 1], \
                positions[t, 1, 2] - positions[t, 0, 2]
            bx, by, bz = positions[t, 2, 0] - positions[t, 0, 0], positions[t, 2, 1] - positions[t, 0, 1], \
                positions[t, 2, 2] - positions[t, 0, 2]
            nx, ny, nz = np.float64(ay * bz - az * by), np.float64(az * bx - ax * bz), np.float64(ax * by - ay * bx)
        length = max(np.sqrt(nx * nx + ny * ny + nz * nz), 1e-30)
        normal[q, 0], normal[q, 1], normal[q, 2] = nx / length, ny / length, nz / length


def surface_points(texels: TexelSet, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Every texel's position and normal found again from its pixel and triangle, as `rasterise`
    found them (the same kernel on the same float64 values: equal bit for bit), before texel
    validity moved any."""
    position = np.empty((len(texels), 3))
    normal = np.empty((len(texels), 3))
    uv = scene.uvs.astype(np.float64)
    for lm in texels.lightmaps:
        sl = lm.texels
        tri = np.ascontiguousarray(texels.triangle[sl])
        _surface(np.ascontiguousarray(texels.pixel[sl]), tri, tri, uv, lm.width, lm.height, scene.positions,
                 scene.normals, position[sl], normal[sl])
    return position, normal


@contextlib.contextmanager
def geometry_set_aside(texels: TexelSet, scene: Scene):
    """While the block runs, `texels` has no positions or normals (None): 48 bytes a texel the
    work in between does not read (tracing into the texel histogram, OIDN's run). They come back
    equal bit for bit: found again (`surface_points`), with the positions texel validity moved
    kept aside. `scene` must be the one the texels were rasterised from."""
    moved = np.flatnonzero(texels.cuts.moved) if texels.cuts is not None else np.zeros(0, np.int64)
    kept = texels.position[moved]
    texels.position = texels.normal = None
    try:
        yield texels
    finally:
        texels.position, texels.normal = surface_points(texels, scene)
        texels.position[moved] = kept


def _areas(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Each triangle's world area and lightmap UV area."""
    world_area = 0.5 * np.linalg.norm(np.cross(scene.positions[:, 1] - scene.positions[:, 0],
                                               scene.positions[:, 2] - scene.positions[:, 0]), axis=1)
    uv = scene.uvs.astype(np.float64)
    uv_area = 0.5 * np.abs((uv[:, 1, 0] - uv[:, 0, 0]) * (uv[:, 2, 1] - uv[:, 0, 1])
                           - (uv[:, 1, 1] - uv[:, 0, 1]) * (uv[:, 2, 0] - uv[:, 0, 0]))
    return world_area, uv_area


def _texel_size(world_area, uv_area, sl: slice, res: int) -> float:
    obj_uv = uv_area[sl].sum() * res * res
    return float(np.sqrt(world_area[sl].sum() / obj_uv)) if obj_uv > 0 else 0.0


def texel_sizes(scene: Scene, names, resolution: int) -> dict:
    """{object name: metres per texel} of objects `names` (a resolution of 0: `resolution`), as
    `rasterise` finds them, without rasterising: what the widest disc of a set of objects is."""
    world_area, uv_area = _areas(scene)
    names = set(names)
    return {obj.name: _texel_size(world_area, uv_area, obj.triangles, int(obj.resolution or resolution))
            for obj in scene.objects if obj.name in names}


def images(scene: Scene) -> list[tuple[str, list[int]]]:
    """[(image name, object indices)] of the objects with `bake` set, in scene order: an object
    alone under its own name, or with the others that name the same atlas (BakeObject.image)."""
    groups: dict = {}
    for index, obj in enumerate(scene.objects):
        if obj.bake:
            groups.setdefault(obj.image or obj.name, []).append(index)
    for name, members in groups.items():
        sizes = {int(scene.objects[i].resolution) for i in members}
        if len(sizes) > 1:
            raise BakeError(f"atlas '{name}': its objects have different resolutions {sorted(sizes)}")
    return list(groups.items())


def rasterise(scene: Scene) -> TexelSet:
    """Texels of every object with `bake` set, at its `resolution` (square lightmaps); the objects
    of one atlas into one image, each texel taking the nearest triangle of any of them."""
    parts = []
    lightmaps: list[Lightmap] = []
    offset = 0
    world_area, uv_area = _areas(scene)
    uv = scene.uvs.astype(np.float64)
    groups = images(scene)
    alone = [scene.objects[m[0]] for _, m in groups if not scene.objects[m[0]].image]
    widths = dict(zip((o.name for o in alone), charts_mod.widths_of_objects(  # every object's charts at once
        uv, scene.positions, [(o.first_triangle, o.first_triangle + o.triangle_count) for o in alone],
        [int(o.resolution) for o in alone])))
    for name, members in groups:
        index, obj = members[0], scene.objects[members[0]]
        res = int(obj.resolution)
        if res <= 0:
            raise BakeError(f"object '{obj.name}': lightmap resolution must be positive, got {res}")
        lm = Lightmap(name, index, res, res, offset, 0, 0.0, objects=tuple(members) if obj.image else ())
        sl = lightmap_triangles(scene, lm) if obj.image else obj.triangles
        first = sl if obj.image else int(obj.first_triangle)
        pixel, tri, local, area, centre, doubled = _cover(lm, uv[sl], world_area[sl], res, first)
        found = widths[obj.name] if not obj.image else charts_mod.chart_widths(uv[sl], scene.positions[sl], res)
        lm.charts, lm.chart_width, lm.border = charts_mod.chart_stats(res, pixel, local, found)
        lm.triangle_widths = found[1][found[0]]
        lm.count, lm.texel_size = len(pixel), _texel_size(world_area, uv_area, sl, res)
        if obj.image:
            lm.placement = _placement(scene, members, tri, pixel, res, world_area, uv_area)
            charts_mod.into_placement(lm.placement, [scene.objects[i] for i in members], sl, found, res, pixel,
                                      local, doubled)
        # Positions and normals last, once the pixel grids are gone: the peak is what the TexelSet keeps.
        pos = np.empty((len(pixel), 3))
        nrm = np.empty((len(pixel), 3))
        _surface(pixel, local, tri, np.ascontiguousarray(uv[sl]), res, res, scene.positions, scene.normals, pos, nrm)
        lightmaps.append(lm)
        parts.append([pos, nrm, tri, pixel, area, centre])
        offset += len(pixel)
    if not parts:
        raise BakeError("no object to bake")
    # One field at a time, each object's part let go once copied: a copy of one field at most.
    cat = []
    for f in range(len(parts[0])):
        cat.append(parts[0][f] if len(parts) == 1 else np.concatenate([p[f] for p in parts]))
        for p in parts:
            p[f] = None
    return TexelSet(*cat, lightmaps=lightmaps)


def _cover(lm: Lightmap, uv: np.ndarray, world_area: np.ndarray, res: int, first) -> tuple:
    """Lightmap `lm`'s covered pixels, their triangles (in the scene, and as numbered in `uv`), the
    world area on their squares (float32), whether their centre lies on a triangle and on two; sets its
    overlap and outside shares. `first`: the scene's number of uv's first triangle, or an atlas's
    triangle list. The (res², …) grids live only here (24 bytes a pixel)."""
    best_tri = np.full(res * res, -1, np.int32)
    best_d2 = np.full(res * res, np.inf)
    cover = np.zeros(res * res)
    inside = np.zeros(res * res, np.int32)
    total, within = _rasterise(np.ascontiguousarray(uv), world_area, res, res, best_tri, best_d2, cover, inside)
    pixel = np.flatnonzero(best_tri >= 0).astype(np.int32)
    if pixel.size == 0:
        raise BakeError(f"{'atlas' if lm.objects else 'object'} '{lm.name}': its lightmap UVs cover no texel at "
                        f"{res}x{res} (are the UVs all zero or outside 0..1?)")
    # In an atlas the rasterised triangles are the members' (an index array): back to the scene's.
    local = best_tri[pixel]
    del best_tri
    tri = (local + np.int32(first)) if isinstance(first, int) else first[local].astype(np.int32)
    area = cover[pixel].astype(np.float32)
    del cover
    centre = best_d2[pixel] <= 1e-9
    del best_d2
    held = int(np.count_nonzero(inside))
    lm.overlap = float(np.count_nonzero(inside > 1)) / held if held else 0.0
    lm.outside = max(0.0, 1.0 - within / total) if total > 0 else 0.0
    return pixel, tri, local, area, centre, inside[pixel] > 1


def of_objects(texels: TexelSet, names, scene: Scene | None = None) -> np.ndarray:
    """Per texel, whether its object is one of `names`: by its triangle's object where an atlas may
    hold several (`scene` given), else by its lightmap's name."""
    names = set(names)
    if scene is None:
        return np.repeat([lm.name in names for lm in texels.lightmaps], [lm.count for lm in texels.lightmaps])
    named = np.array([o.name in names for o in scene.objects] + [False])
    return named[scene.object_index()[texels.triangle]]


def _placement(scene: Scene, members, tri, pixel, res, world_area, uv_area) -> dict:
    """Where each object of an atlas lies in it (Lightmap.placement)."""
    out = {}
    owner = np.searchsorted([scene.objects[i].first_triangle for i in members], tri, side="right") - 1
    for k, i in enumerate(members):
        obj = scene.objects[i]
        mine = pixel[owner == k]
        x, y = mine % res, mine // res
        rect = [int(x.min()), int(y.min()), int(x.max()) + 1, int(y.max()) + 1] if mine.size else [0, 0, 0, 0]
        out[obj.name] = {"texels": int(mine.size), "rect": rect,
                         "texel_size": _texel_size(world_area, uv_area, obj.triangles, res)}
    return out


def geometric_normals(scene: Scene, triangle: np.ndarray, towards: np.ndarray) -> np.ndarray:
    """Unit face normals of `triangle`, flipped to the side of the shading normals `towards`."""
    out = np.empty((len(triangle), 3))
    _face_normals(scene.positions, np.ascontiguousarray(triangle), np.ascontiguousarray(towards, np.float64), out)
    return out


@numba.njit(cache=True, parallel=True)
def _face_normals(positions, triangle, towards, out):
    """geometric_normals per texel on every core, the corners read where they lie: no (N, 3, 3)
    gather, no per-triangle table (in numpy, millions of texels took 0.3 s)."""
    for i in numba.prange(triangle.shape[0]):
        t = triangle[i]
        ax, ay, az = np.float64(positions[t, 0, 0]), np.float64(positions[t, 0, 1]), np.float64(positions[t, 0, 2])
        ux, uy, uz = positions[t, 1, 0] - ax, positions[t, 1, 1] - ay, positions[t, 1, 2] - az
        vx, vy, vz = positions[t, 2, 0] - ax, positions[t, 2, 1] - ay, positions[t, 2, 2] - az
        gx, gy, gz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
        ln = max(np.sqrt(gx * gx + gy * gy + gz * gz), 1e-300)
        gx, gy, gz = gx / ln, gy / ln, gz / ln
        if gx * towards[i, 0] + gy * towards[i, 1] + gz * towards[i, 2] < 0.0:
            gx, gy, gz = -gx, -gy, -gz
        out[i, 0], out[i, 1], out[i, 2] = gx, gy, gz


def pixel_steps(texels: TexelSet, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """(du, dv): per texel, the world vectors of one pixel step along u and along v on its triangle
    (the inverse of the triangle's UV edge matrix); 0 on a triangle with degenerate UVs."""
    # Per triangle and lightmap, then per texel.
    count = len(texels.lightmaps)
    key = texels.triangle.astype(np.int64) * count + texels.per_texel(np.arange(count)).astype(np.int64)
    used, index = np.unique(key, return_inverse=True)
    tri, lm = used // count, used % count
    sides = np.array([[m.width, m.height] for m in texels.lightmaps], np.float64).reshape(-1, 2)
    uv = scene.uvs[tri].astype(np.float64) * sides[lm][:, None, :]
    p = scene.positions[tri].astype(np.float64)
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    det = np.where(np.abs(det) > 1e-30, det, np.inf)
    f1, f2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    du = (f1 * e2[:, 1:2] - f2 * e1[:, 1:2]) / det[:, None]
    dv = (f2 * e1[:, 0:1] - f1 * e2[:, 0:1]) / det[:, None]
    index = index.reshape(-1)
    return du[index], dv[index]


def texel_centres(texels: TexelSet) -> tuple:
    """(cx, cy, sx, sy) float32: each texel's centre in pixels of its lightmap, and that lightmap's
    width and height."""
    sx = texels.per_texel([lm.width for lm in texels.lightmaps]).astype(np.float32)
    sy = texels.per_texel([lm.height for lm in texels.lightmaps]).astype(np.float32)
    width = np.maximum(sx.astype(np.int64), 1)
    pixel = texels.pixel.astype(np.int64)
    cx = (pixel % width).astype(np.float32) + np.float32(0.5)
    cy = (pixel // width).astype(np.float32) + np.float32(0.5)
    return cx, cy, sx, sy


def neighbour_pairs(grid: np.ndarray) -> list:
    """(a, b) views of a 2D `grid` for its pairs of 8-neighbours, each pair once: right, up and the
    two diagonals."""
    return [(grid[:, :-1], grid[:, 1:]), (grid[:-1, :], grid[1:, :]), (grid[:-1, :-1], grid[1:, 1:]),
            (grid[:-1, 1:], grid[1:, :-1])]


def select(texels: TexelSet, mask: np.ndarray) -> TexelSet:
    """The texels where `mask` is set, as a TexelSet of their own: every lightmap keeps its place
    (with the count of its texels kept, maybe 0), so per-lightmap values still broadcast."""
    mask = np.asarray(mask, bool)
    lightmaps, offset = [], 0
    for lm in texels.lightmaps:
        count = int(mask[lm.texels].sum())
        lightmaps.append(replace(lm, offset=offset, count=count))
        offset += count
    return TexelSet(texels.position[mask], texels.normal[mask], texels.triangle[mask], texels.pixel[mask],
                    texels.area[mask], texels.centre_inside[mask], lightmaps,
                    None if texels.cuts is None else texels.cuts.select(mask))


def to_image(values: np.ndarray, lm: Lightmap, pixel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Scatter one lightmap's texel values into an (H, W, C) image (row 0 = bottom) and its mask."""
    c = values.shape[1]
    img = np.zeros((lm.height * lm.width, c), np.float32)
    mask = np.zeros(lm.height * lm.width, bool)
    img[pixel] = values
    mask[pixel] = True
    return img.reshape(lm.height, lm.width, c), mask.reshape(lm.height, lm.width)


def resolution_for_density(positions: np.ndarray, uvs: np.ndarray, texels_per_metre: float,
                           multiple: int = 4, limit: int = 8192) -> int:
    """Lightmap size giving `texels_per_metre` on the surface, given how much of the UV square the
    charts use: the side is √(world area / UV area) · density, rounded up to a multiple of 4."""
    world = 0.5 * np.linalg.norm(np.cross(positions[:, 1] - positions[:, 0], positions[:, 2] - positions[:, 0]),
                                 axis=1).sum()
    uv = uvs.astype(np.float64)
    uv_area = 0.5 * np.abs((uv[:, 1, 0] - uv[:, 0, 0]) * (uv[:, 2, 1] - uv[:, 0, 1])
                           - (uv[:, 1, 1] - uv[:, 0, 1]) * (uv[:, 2, 0] - uv[:, 0, 0])).sum()
    if world <= 0 or uv_area <= 0:
        return multiple
    side = np.sqrt(world / uv_area) * float(texels_per_metre)
    return int(min(limit, max(multiple, multiple * np.ceil(side / multiple))))


def tangent_clearance(texels: TexelSet, positions: np.ndarray, reach: np.ndarray, lift: np.ndarray,
                      directions: int = 8, threads: int = 0) -> np.ndarray:
    """How far each texel's surface runs in its tangent plane before other geometry: the nearest
    hit of `directions` rays cast along the tangent plane, `lift` above the surface (so the
    surface itself is not hit), up to `reach`. Nothing within reach gives `reach`.

    Most texels have nothing but their own surface within reach: a compiled, conservative test
    (does any triangle cross the lifted disc?) finds the others, and only they cast rays, spread
    over `threads` threads (0: numba's count). The result is the same as casting every ray."""
    best = reach.astype(np.float64).copy()
    origin = texels.position + texels.normal * lift[:, None]
    todo = np.flatnonzero(discs_meet_triangles(positions, origin, texels.normal, reach))
    if todo.size == 0:
        return best
    caster = RayCaster(positions)
    chunk = 1 << 15

    def run(a):
        idx = todo[a:a + chunk]
        n = texels.normal[idx]
        helper = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        t = np.cross(n, helper)
        t /= np.linalg.norm(t, axis=1)[:, None]
        s = np.cross(n, t)
        o = np.ascontiguousarray(np.tile(origin[idx], (directions, 1)), np.float32)
        angle = 2.0 * np.pi * np.arange(directions) / directions
        d = (np.cos(angle)[:, None, None] * t + np.sin(angle)[:, None, None] * s).reshape(-1, 3)
        far = np.tile(reach[idx].astype(np.float32), directions)
        dist, prim, _ = caster.intersect(o, np.ascontiguousarray(d, np.float32), far)
        dist = np.where(prim >= 0, dist, np.inf).reshape(directions, -1)
        best[idx] = np.minimum(best[idx], dist.min(axis=0))

    with ThreadPoolExecutor(int(threads) or numba.get_num_threads()) as pool:
        list(pool.map(run, range(0, todo.size, chunk)))
    return best
