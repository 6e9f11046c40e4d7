"""UV charts of a lightmap: how many, how wide in texels, how much of the lightmap is chart border.

A chart is a set of triangles joined by shared corners, a corner shared when both its UV and its
position agree (charts packed side by side in UV touch, but are not joined). Chart borders are where a lightmap is
weakest: a border texel covers a sliver of surface (few photons land on it), its neighbours across
the border belong to other surfaces (the denoiser sees fragments, not an image), and bilinear
filtering reads the gutter beside it. Smart UV Project on a detailed mesh gives thousands of charts
a few texels wide, where most texels are border texels; the bake warns (`warning`) and names the
fixes: merged charts at the lightmap's texel density (xatlas), or a higher resolution.
"""
from __future__ import annotations

import numpy as np

from ..components import connected_components

NARROW = 4.0  # median chart width (texels) under which a lightmap is called fragmented
BORDER = 0.5  # ... or this share of border texels


def _corners(uv: np.ndarray, positions: np.ndarray | None = None) -> np.ndarray:
    """(T, 3) ids of the triangles' corners: equal UVs (to 1e-6 of the square) and, when given,
    equal positions (to 1e-6 of the mesh's extent) are one id."""
    key = np.round(np.asarray(uv, np.float64).reshape(-1, 2) * 1e6)
    if positions is not None:
        p = np.asarray(positions, np.float64).reshape(-1, 3)
        lo = p.min(axis=0)
        key = np.concatenate([key, np.round((p - lo) / max(float(np.ptp(p)), 1e-300) * 1e6)], axis=1)
    return _rows(key.astype(np.int64))[0].reshape(-1, 3)


def _rows(key: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What np.unique(key, axis=0, return_inverse, return_index, return_counts) gives, the inverse
    first, by one stable lexsort of the columns: unique on rows sorts them as opaque bytes, about
    twenty times slower (25 s against about 1 s for the 3M corners of a million triangles)."""
    order = np.lexsort(key.T[::-1])
    ordered = key[order]
    new = np.ones(len(key), bool)
    new[1:] = np.any(ordered[1:] != ordered[:-1], axis=1)
    del ordered
    starts = np.flatnonzero(new)
    inverse = np.empty(len(key), np.int64)
    inverse[order] = np.cumsum(new) - 1
    return inverse, order[starts], np.diff(np.append(starts, len(key)))


def chart_of_triangles(uv: np.ndarray, positions: np.ndarray | None = None,
                       corner: np.ndarray | None = None) -> tuple[int, np.ndarray]:
    """(chart count, (T,) chart of each triangle) for (T, 3, 2) UVs and, when given, (T, 3, 3)
    positions: triangles sharing a corner are one chart. `corner`: their `_corners`, if known."""
    t = len(uv)
    if t == 0:
        return 0, np.zeros(0, np.int64)
    corner = (_corners(uv, positions) if corner is None else corner).reshape(-1)
    tri = np.repeat(np.arange(t), 3)
    n = t + int(corner.max()) + 1
    count, label = connected_components(n, tri, t + corner)
    chart = label[:t]
    _, chart = np.unique(chart, return_inverse=True)
    return int(chart.max()) + 1, chart.reshape(-1)


def chart_widths(uv: np.ndarray, positions: np.ndarray, res: int) -> tuple[np.ndarray, np.ndarray]:
    """((T,) chart of each triangle, (C,) each chart's width in texels at `res`² texels) for one
    object's (T, 3, 2) UVs and (T, 3, 3) corners. Width: 4·area / perimeter in UV (a square's side,
    a disc's diameter, twice a thin strip's width)."""
    u = np.asarray(uv, np.float64)
    corner = _corners(u, positions)
    count, chart = chart_of_triangles(uv, positions, corner)
    return chart, _uv_widths(u, corner, chart, count) * res


def _uv_widths(u: np.ndarray, corner: np.ndarray, chart: np.ndarray, count: int) -> np.ndarray:
    """(count,) each chart's width in UV units, 4·area / perimeter, from the triangles' float64 UVs
    (T, 3, 2), corner ids (T, 3) and charts (T,)."""
    area = 0.5 * np.abs((u[:, 1, 0] - u[:, 0, 0]) * (u[:, 2, 1] - u[:, 0, 1])
                        - (u[:, 1, 1] - u[:, 0, 1]) * (u[:, 2, 0] - u[:, 0, 0]))
    edges = np.sort(np.stack([corner[:, [0, 1]], corner[:, [1, 2]], corner[:, [2, 0]]], axis=1), axis=2).reshape(-1, 2)
    length = np.linalg.norm(np.stack([u[:, 1] - u[:, 0], u[:, 2] - u[:, 1], u[:, 0] - u[:, 2]], axis=1),
                            axis=2).reshape(-1)
    _, first, times = _rows(edges)
    outer = first[times == 1]  # an edge no other triangle shares lies on its chart's outline
    perimeter = np.bincount(np.repeat(chart, 3)[outer], weights=length[outer], minlength=count)
    return 4.0 * np.bincount(chart, weights=area, minlength=count) / np.maximum(perimeter, 1e-300)


def widths_of_objects(uv: np.ndarray, positions: np.ndarray, bounds, res) -> list:
    """[(chart of each triangle, each chart's width in texels)] of objects whose triangles are
    `uv[a:b]`, `positions[a:b]` for each (a, b) of `bounds` (in order, not overlapping), at
    `res[k]`² texels: what `chart_widths` gives object by object, the same numbers, in one pass
    (a level of 1,500 crates: 1,500 passes of a few small arrays each took seconds). An object's
    corners are keyed with its index first, so no two objects share a corner and each object's
    corners, edges and charts keep the order they have alone."""
    bounds = np.asarray(bounds, np.int64).reshape(-1, 2)
    if len(bounds) == 0:
        return []
    counts = bounds[:, 1] - bounds[:, 0]
    if not counts.any():
        return [(np.zeros(0, np.int64), np.zeros(0)) for _ in counts]
    tri = np.concatenate([np.arange(a, b) for a, b in bounds]) if len(bounds) > 1 else np.arange(*bounds[0])
    obj = np.repeat(np.arange(len(bounds)), counts)
    u = np.asarray(uv[tri], np.float64)
    p = np.asarray(positions[tri], np.float64).reshape(-1, 3)
    starts = 3 * (np.cumsum(counts) - counts)
    lo = np.minimum.reduceat(p, starts[counts > 0], axis=0)
    span = np.maximum.reduceat(p, starts[counts > 0], axis=0).max(axis=1) - lo.min(axis=1)
    at = np.repeat(np.cumsum(counts > 0) - 1, 3 * counts)
    key = np.concatenate([np.repeat(obj, 3)[:, None].astype(np.float64), np.round(u.reshape(-1, 2) * 1e6),
                          np.round((p - lo[at]) / np.maximum(span, 1e-300)[at, None] * 1e6)], axis=1)
    corner = _rows(key.astype(np.int64))[0].reshape(-1, 3)
    del key
    _, chart = chart_of_triangles(u, None, corner)
    _, chart = np.unique(obj * (int(chart.max(initial=0)) + 1) + chart, return_inverse=True)
    chart = chart.reshape(-1)
    count = int(chart.max(initial=-1)) + 1
    width = _uv_widths(u, corner, chart, count)
    tstart = np.cumsum(counts) - counts
    full = counts > 0
    first_chart = np.append(np.minimum.reduceat(chart, tstart[full]), count)  # each object's charts: a run
    out, k = [], 0
    for a, n, r in zip(tstart, counts, res):
        if n == 0:
            out.append((np.zeros(0, np.int64), np.zeros(0)))
            continue
        c0, c1 = first_chart[k], first_chart[k + 1]
        out.append((chart[a:a + n] - c0, width[c0:c1] * r))
        k += 1
    return out


def _border(owner: np.ndarray, res: int) -> np.ndarray:
    """(res, res) bool: covered texels with a 4-neighbour of another chart (or none); `owner` the
    (res²,) chart of each texel, −1 where none."""
    grid = np.pad(owner.reshape(res, res), 1, constant_values=-1)
    mine = grid[1:-1, 1:-1]
    border = np.zeros_like(mine, bool)
    for other in (grid[:-2, 1:-1], grid[2:, 1:-1], grid[1:-1, :-2], grid[1:-1, 2:]):
        border |= other != mine
    return border & (mine >= 0)


def chart_stats(res: int, pixel: np.ndarray, texel_tri: np.ndarray, widths) -> tuple[int, float, float]:
    """(charts, median chart width in texels, share of border texels) of one object's lightmap of
    `res`² texels: `pixel` its covered texels, `texel_tri` their triangles (indices into its own
    triangles) and `widths` (chart of each triangle, each chart's width) as `chart_widths` or
    `widths_of_objects` give them."""
    chart, width = widths
    if len(width) == 0 or len(pixel) == 0:
        return len(width), 0.0, 0.0
    owner = np.full(res * res, -1, np.int64)
    owner[pixel] = chart[texel_tri]
    return len(width), float(np.median(width)), float(_border(owner, res).sum()) / len(pixel)


def into_placement(placement: dict, objects, triangles, widths, res: int, pixel, texel_tri, doubled) -> None:
    """Each atlas object's own charts (chart_stats of its charts alone, border texels as the atlas
    has them) and the share of its texels under two or more faces, into its `placement` entry
    (texels.Lightmap.placement): the warnings name objects, not the atlas. `objects` the atlas's
    BakeObjects, `triangles` the scene's triangles of the atlas, `widths` their `chart_widths`,
    `doubled` per covered texel."""
    chart, width = widths
    if len(triangles) == 0 or len(pixel) == 0:
        return
    member = np.searchsorted([o.first_triangle for o in objects], triangles, side="right") - 1
    owner = np.full(res * res, -1, np.int64)
    owner[pixel] = chart[texel_tri]
    on_border = _border(owner, res).reshape(-1)[pixel]
    of_texel = member[texel_tri]
    of_chart = np.zeros(len(width), np.int64)
    of_chart[chart] = member
    for k, obj in enumerate(objects):
        mine, texels = of_chart == k, of_texel == k
        placement[obj.name]["charts"] = {
            "count": int(mine.sum()), "median_width": round(float(np.median(width[mine])), 2) if mine.any() else 0.0,
            "border": round(float(on_border[texels].mean()), 4) if texels.any() else 0.0}
        placement[obj.name]["overlap"] = round(float(doubled[texels].mean()), 4) if texels.any() else 0.0


def fragmented(count: int, width: float, border: float) -> bool:
    return count > 0 and (width < NARROW or border > BORDER)


def warning(lm) -> str | None:
    """The warning for a fragmented lightmap (a Lightmap of texels.py), or None; an atlas's names
    its fragmented objects, not the atlas."""
    if lm.placement:
        return _atlas_warning(lm)
    if not fragmented(lm.charts, lm.chart_width, lm.border):
        return None
    suggest = int(min(16384, 2 ** np.ceil(np.log2(lm.width * max(NARROW / max(lm.chart_width, 1e-3), 1.0)))))
    return (f"object '{lm.name}': its lightmap UVs are {lm.charts:,} charts with a median width of "
            f"{lm.chart_width:.1f} texels at {lm.width}x{lm.height}, and {100 * lm.border:.0f} % of its texels lie "
            "on a chart's border (few photons, fragments for the denoiser, seams): unwrap it with Unwrap Lightmap UVs "
            f"(xatlas: merged charts at the lightmap's texel density) or raise its resolution to about {suggest} "
            "(--resolution)")


def _atlas_warning(lm) -> str | None:
    """The objects of an atlas whose own charts are fragmented, worst first."""
    bad = [(name, c) for name, place in lm.placement.items() for c in [place.get("charts")]
           if c and fragmented(c["count"], c["median_width"], c["border"])]
    if not bad:
        return None
    bad.sort(key=lambda nc: nc[1]["median_width"])
    named = ", ".join(f"'{n}' ({c['count']:,} charts, median {c['median_width']:.1f} texels wide, "
                      f"{100 * c['border']:.0f} % of its texels on a border)" for n, c in bad[:6])
    more = f" and {len(bad) - 6} more" if len(bad) > 6 else ""
    widest = min(c["median_width"] for _, c in bad)
    density = 1.0 / lm.texel_size if lm.texel_size > 0 else 0.0
    suggest = f"{density * max(NARROW / max(widest, 1e-3), 1.0):.3g}"
    return (f"{'objects' if len(bad) > 1 else 'object'} {named}{more} in atlas '{lm.name}': "
            f"{'their' if len(bad) > 1 else 'its'} lightmap UVs are fragmented (few photons, fragments for the "
            "denoiser, seams): select them and click Unwrap Lightmap UVs › xatlas in the Lightmap panel (or remove "
            "their lightmap UV layer: the bake then makes xatlas charts), or raise the texel density to about "
            f"{suggest} (--texel-density)")
