"""Chart statistics of a lightmap (charts.py) and the warning for a fragmented unwrap."""
import numpy as np

from detp_bake.lightmap import charts, texels as texels_mod
from detp_bake.run.bake import BakeSettings, compute
from detp_bake.scene import SunLight
from synthetic import grid, make_scene


def _quads_apart(n, shrink):
    """An n×n grid plane whose quads are each their own UV chart, shrunk round its centre."""
    pos, nrm, uv = grid(2.0, 2.0, n)
    centre = uv.reshape(-1, 6, 2).mean(axis=1).repeat(2, axis=0)[:, None, :]
    return pos, nrm, centre + shrink * (uv - centre)


def test_chart_statistics_of_known_charts():
    """One chart filling the lightmap: 1 chart as wide as the lightmap, border texels only round the
    edge. 64 quads apart, each 0.7 of an eighth of the lightmap: 64 charts 5.6 texels wide at 64²."""
    one = texels_mod.rasterise(make_scene([("One", grid(2.0, 2.0, 8), 0.5, True)], [], resolution=64)).lightmaps[0]
    assert (one.charts, one.chart_width) == (1, 64.0)
    np.testing.assert_allclose(one.border, (64 * 4 - 4) / 64 ** 2)
    apart = texels_mod.rasterise(make_scene([("Apart", _quads_apart(8, 0.7), 0.5, True)], [],
                                            resolution=64)).lightmaps[0]
    assert apart.charts == 64
    np.testing.assert_allclose(apart.chart_width, 64 / 8 * 0.7, rtol=1e-9)
    assert 0.3 < apart.border < 0.6
    count, chart = charts.chart_of_triangles(_quads_apart(2, 0.5)[2])
    assert count == 4 and list(chart) == [0, 0, 1, 1, 2, 2, 3, 3]


def test_a_fragmented_unwrap_is_warned_about_and_a_clean_one_is_not():
    sun = SunLight("Sun", np.array([0.0, 0.0, -1.0]), np.full(3, 3.0))
    scene = make_scene([("Clean", grid(2.0, 2.0, 8), 0.5, True), ("Shards", _quads_apart(16, 0.6), 0.5, True)],
                       [sun], resolution=32)
    r = compute(scene, BakeSettings(photons=20_000, denoise=False, bounces=0))
    said = [w for w in r.warnings if "charts" in w]
    print(said)
    assert len(said) == 1 and said[0].startswith("object 'Shards': its lightmap UVs are 256 charts with a median "
                                                 "width of 1.2 texels at 32x32")
    assert "Unwrap Lightmap UVs" in said[0] and "raise its resolution to about 128" in said[0]
    shards = next(o for o in r.report()["objects"] if o["name"] == "Shards")
    assert shards["charts"]["count"] == 256 and shards["charts"]["median_width"] == 1.2
    assert shards["charts"]["border"] > 0.9


def test_in_an_atlas_the_chart_warning_names_the_fragmented_objects_not_the_atlas():
    """Two objects in one atlas, one cut in shards: the warning names 'Shards' (its own charts and
    border share) and what to click, never 'atlas_0' as an object; report.json gives each its own."""
    sun = SunLight("Sun", np.array([0.0, 0.0, -1.0]), np.full(3, 3.0))
    clean_pos, clean_nrm, clean_uv = grid(2.0, 2.0, 8)
    shard_pos, shard_nrm, shard_uv = _quads_apart(16, 0.6)
    clean_uv = clean_uv * [0.5, 1.0]  # left half of the atlas
    shard_uv = shard_uv * [0.5, 1.0] + [0.5, 0.0]  # right half
    scene = make_scene([("Clean", (clean_pos, clean_nrm, clean_uv), 0.5, True),
                        ("Shards", (shard_pos + [3.0, 0, 0], shard_nrm, shard_uv), 0.5, True)], [sun], resolution=64)
    for obj in scene.objects:
        obj.image = "atlas_0"
    r = compute(scene, BakeSettings(photons=20_000, denoise=False, bounces=0))
    said = [w for w in r.warnings if "charts" in w]
    assert len(said) == 1 and said[0].startswith("object 'Shards' (256 charts, median 1.6 texels wide, ")  # 1.2 × 2.4 texels
    assert "in atlas 'atlas_0'" in said[0] and "'Clean'" not in said[0] and "object 'atlas_0'" not in said[0]
    assert "Unwrap Lightmap UVs › xatlas" in said[0] and "--texel-density" in said[0]
    entries = {o["name"]: o["charts"] for o in r.report()["objects"]}
    assert entries["Clean"]["count"] == 1 and entries["Shards"]["count"] == 256
    assert entries["Shards"]["border"] > 0.9 > 0.2 > entries["Clean"]["border"]


def test_every_objects_charts_at_once_are_each_objects_alone():
    """widths_of_objects gives, for a run of objects, each one's charts and widths exactly as
    chart_widths gives them alone (the same charts, the same floats), objects of no triangles
    included; two objects whose corners coincide are not joined."""
    rng = np.random.default_rng(5)
    parts, bounds, res, at = [], [], [], 0
    for n in (12, 0, 40, 1, 12):
        uv = rng.random((n, 3, 2))
        if n >= 12:  # triangles that share corners: charts of several triangles
            uv[1::2, 0] = uv[0::2, 1][: len(uv[1::2])]
            uv[1::2, 1] = uv[0::2, 2][: len(uv[1::2])]
        pos = rng.random((n, 3, 3)) * (1 + at)
        if n >= 12:
            pos[1::2, 0] = pos[0::2, 1][: len(pos[1::2])]
            pos[1::2, 1] = pos[0::2, 2][: len(pos[1::2])]
        parts.append((uv, pos))
        bounds.append((at, at + n))
        res.append(16 * (1 + len(res)))
        at += n
    parts[-1] = parts[0]  # the same corners as the first object: still apart
    uv = np.concatenate([p[0] for p in parts])
    pos = np.concatenate([p[1] for p in parts])
    got = charts.widths_of_objects(uv, pos, bounds, res)
    for (a, b), r, (chart, width) in zip(bounds, res, got):
        if a == b:
            assert len(chart) == 0 and len(width) == 0
            continue
        alone_chart, alone_width = charts.chart_widths(uv[a:b], pos[a:b], r)
        assert np.array_equal(chart, alone_chart) and np.array_equal(width, alone_width)
    assert len(got[1][1]) == 0 and len(got[2][1]) > 1
