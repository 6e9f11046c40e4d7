"""Chart-aware OIDN denoising (detp_bake.lightmap.denoise) on analytic irradiance fields with known noise.

Noise model: a photon count's noise, σ(E) = level · √(E · Ē), the same draw in all three channels
(one light, one set of photons), 0 in the gutter as a bake leaves it. Fixed seeds throughout.
"""
import sys

import numpy as np
import pyoidn
import pytest

from detp_bake.lightmap import denoise
from detp_bake.errors import BakeError

TINT = np.array([1.0, 0.85, 0.7], np.float32)
LEVEL = 0.1  # relative noise at the mean irradiance


def _point_light(n):
    """E/π (up to a constant) of a point light 0.35 above a unit square, plus an ambient term."""
    j, i = np.mgrid[0:n, 0:n]
    x, y, h = (i + 0.5) / n, (j + 0.5) / n, 0.35
    e = 0.15 + 2.0 * h ** 3 / ((x - 0.3) ** 2 + (y - 0.6) ** 2 + h * h) ** 1.5
    return (e[..., None] * TINT).astype(np.float32)


def _charts(n):
    """Three charts with gutters between them: a wide rectangle, a disc and a square."""
    g = n // 32
    m = np.zeros((n, n), bool)
    m[g:n // 2 - g, g:n - g] = True
    j, i = np.mgrid[0:n, 0:n]
    m |= (i - 0.3 * n) ** 2 + (j - 0.75 * n) ** 2 < (0.18 * n) ** 2
    m[n // 2 + g:n - g, n // 2 + 2 * g:n - g] = True
    return m


def _noisy(truth, mask, rng, level=LEVEL, disc=False):
    z = rng.standard_normal(truth.shape[:2])
    if disc:  # shared crossings: a 3x3 box (the 1.5-texel disc), rescaled to the same σ
        p = np.pad(z, 1, mode="reflect")
        h, w = z.shape
        z = sum(p[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
                for dy in (-1, 0, 1) for dx in (-1, 0, 1)) / 3.0
    lum = truth[..., 0]
    sigma = level * np.sqrt(lum * lum[mask].mean())
    img = np.maximum(truth * (1 + sigma / lum * z)[..., None], 0.0)
    return np.where(mask[..., None], img, 0.0).astype(np.float32)


def _rel_rmse(a, truth, mask):
    return float(np.sqrt(np.mean((a[mask] - truth[mask]) ** 2)) / truth[mask].mean())


def _mean_error(a, raw, mask):
    return np.abs(a[mask].mean(axis=0, dtype=np.float64) / raw[mask].mean(axis=0, dtype=np.float64)
                  - 1)


UP = np.broadcast_to(np.array([0, 0, 1], np.float32), (128, 128, 3))


def test_white_noise_over_sharp_direct_light_is_denoised_best_apart():
    """Sharp direct light (a checkerboard of lit and shadowed squares, noiseless) plus a smooth
    indirect part with 20 % white noise: OIDN keeps the noise near every edge of the sum, and
    smooths the indirect part alone far better (the bake denoises a texel histogram's bake so)."""
    n = 128
    mask = _charts(n)
    j, i = np.mgrid[0:n, 0:n]
    lit = ((i // 16 + j // 16) % 2 == 0) & mask
    direct = (np.where(lit, 1.0, 0.05)[..., None] * np.ones(3) * mask[..., None]).astype(np.float32)
    indirect = 0.3 * _point_light(n)
    noisy = _noisy(indirect, mask, np.random.default_rng(0), level=0.2)
    truth = direct + indirect
    together = _rel_rmse(denoise.denoise_lightmap(direct + noisy, mask, margin=0), truth, mask)
    apart = _rel_rmse(denoise.denoise_lightmap(direct, mask, margin=0)
                      + denoise.denoise_lightmap(noisy, mask, margin=0), truth, mask)
    assert apart < 0.7 * together, (apart, together)  # measured 2.4 % against 4.1 %


@pytest.mark.parametrize("kwargs", [{}, {"filter": "RT"}, {"normal": UP}],
                         ids=["RTLightmap", "RT", "RT+normal"])
def test_white_noise_is_cut_several_times_and_the_chart_mean_kept(kwargs):
    truth, mask = _point_light(128), _charts(128)
    raw = _noisy(truth, mask, np.random.default_rng(1))
    out = denoise.denoise_lightmap(raw, mask, **kwargs)
    assert out.shape == raw.shape and out.dtype == np.float32
    before, after = _rel_rmse(raw, truth, mask), _rel_rmse(out, truth, mask)
    assert before == pytest.approx(LEVEL, rel=0.1)
    assert after < before / 3  # measured: 10 % -> 1.5-1.9 %
    assert (_mean_error(out, raw, mask) < 0.005).all()


def _mean_shift(raw, denoised, mask):
    """Relative change of each channel's mean over covered texels, (denoised − raw) / raw."""
    r = raw[mask].mean(axis=0, dtype=np.float64)
    return (denoised[mask].mean(axis=0, dtype=np.float64) - r) / r


def test_oidn_itself_moves_the_mean_little_which_keep_energy_then_removes():
    truth, mask = _point_light(128), _charts(128)
    raw = _noisy(truth, mask, np.random.default_rng(2))
    free = denoise.denoise_lightmap(raw, mask, keep_energy=False)
    kept = denoise.denoise_lightmap(raw, mask)
    shift = _mean_shift(raw, free, mask)
    assert (np.abs(shift) < 0.005).all()  # measured ~0.1 %
    assert np.abs(_mean_shift(raw, kept, mask)).max() < 1e-5
    # keep_energy is one factor per channel: the shape is the same.
    ratio = kept[mask] / free[mask]
    assert np.allclose(ratio, ratio.mean(axis=0, dtype=np.float64), rtol=1e-5)


def test_disc_correlated_noise_is_not_made_worse():
    """OIDN reads noise shared over 1.5-texel discs as signal (docs/design.md, Denoising): it removes little
    of it, but it must not add error or move the energy."""
    truth, mask = _point_light(128), _charts(128)
    raw = _noisy(truth, mask, np.random.default_rng(3), disc=True)
    out = denoise.denoise_lightmap(raw, mask)
    assert _rel_rmse(out, truth, mask) < 1.05 * _rel_rmse(raw, truth, mask)
    assert (_mean_error(out, raw, mask) < 0.005).all()


# Two charts side by side with an 8-texel gutter between them; chart A's irradiance rises towards
# the gutter, chart B falls away from it, so A's border sits in the middle of a gradient.
H = W = 128
A_COLS, B_COLS, ROWS = (4, 60), (68, 124), (4, 124)


def _two_charts():
    x = (np.arange(W) + 0.5) / W
    e = np.where(x < 0.5, 0.3 + 1.2 * x, 2.0 - 1.2 * x)
    truth = (np.repeat(e[None, :], H, 0)[..., None] * TINT).astype(np.float32)
    mask = np.zeros((H, W), bool)
    mask[ROWS[0]:ROWS[1], A_COLS[0]:A_COLS[1]] = True
    mask[ROWS[0]:ROWS[1], B_COLS[0]:B_COLS[1]] = True
    return truth, mask


@pytest.mark.parametrize("gutter", [0.0, 50.0, np.nan], ids=["zero", "garbage", "nan"])
@pytest.mark.parametrize("flt", ["RTLightmap", "RT"])
def test_no_seam_at_chart_borders_whatever_the_gutter_held(gutter, flt):
    truth, mask = _two_charts()
    rng = np.random.default_rng(4)
    noisy = truth * (1 + LEVEL * rng.standard_normal((H, W)))[..., None]
    img = np.where(mask[..., None], noisy, gutter).astype(np.float32)
    out = denoise.denoise_lightmap(img, mask, filter=flt)

    rows = slice(ROWS[0] + 4, ROWS[1] - 4)  # away from the charts' corners
    n_rows = rows.stop - rows.start
    # Mean relative error along one column: the raw noise alone gives it σ = LEVEL / √n_rows.
    tol = 3 * LEVEL / np.sqrt(n_rows)

    def bias(a, col):
        return float(np.mean((a[rows, col] - truth[rows, col]) / truth[rows, col]))

    border_a, border_b = A_COLS[1] - 1, B_COLS[0]
    for col in (border_a, border_a - 1, border_b, border_b + 1):
        assert abs(bias(out, col)) < tol, (col, bias(out, col), tol)
    # The check can tell: OIDN on the raw image, gutter as it was, is pulled towards the gutter.
    if np.isfinite(gutter):
        kw = {"hdr": True} if flt == "RT" else {}
        naive = pyoidn.denoise(img, filter_type=flt, **kw)
        assert abs(bias(naive, border_a)) > tol
    # The gutter is refilled from the denoised texels: its first ring is their neighbour mean.
    ring = out[rows, border_a + 1]
    expect = (out[rows.start - 1:rows.stop - 1, border_a] + out[rows, border_a]
              + out[rows.start + 1:rows.stop + 1, border_a]) / 3
    assert np.allclose(ring, expect, rtol=1e-5)
    assert np.isfinite(out).all() and (out[ROWS[0]:ROWS[1], border_a:border_b + 1] > 0).all()


@pytest.mark.parametrize("flt", [None, "RT"])
def test_black_lightmap_stays_black_and_gutter_garbage_is_not_read(flt):
    mask = _charts(64)
    img = np.where(mask[..., None], np.zeros(3), np.nan).astype(np.float32)
    out = denoise.denoise_lightmap(img, mask, filter=flt)
    assert not np.isnan(out).any()
    assert (out == 0).all()
    assert (denoise.denoise_lightmap(np.zeros((8, 8, 3), np.float32), np.zeros((8, 8), bool))
            == 0).all()


@pytest.mark.parametrize("flt", [None, "RT"])
def test_awkward_lightmaps_never_give_nan(flt):
    rng = np.random.default_rng(5)
    mask = _charts(64)
    lit = _noisy(_point_light(64), mask, rng)
    half = lit.copy()
    half[:, :32] = 0  # a chart half in full shadow
    one = np.zeros((64, 64), bool)
    one[20, 30] = True  # a single covered texel
    cases = [(lit * 1e-30, mask), (lit * 1e6, mask), (half, mask), (lit, one),
             (lit, np.ones((64, 64), bool)), (lit - 0.05, mask)]  # the last one dips below 0
    for img, m in cases:
        out = denoise.denoise_lightmap(img.astype(np.float32), m, filter=flt)
        assert np.isfinite(out).all() and (out >= 0).all()
        assert out[m].any()


def test_bad_input_is_a_bake_error_naming_it():
    mask = _charts(32)
    img = np.ones((32, 32, 3), np.float32)
    bad = img.copy()
    bad[mask.nonzero()[0][0], mask.nonzero()[1][0]] = np.nan
    with pytest.raises(BakeError, match="NaN"):
        denoise.denoise_lightmap(bad, mask)
    with pytest.raises(BakeError, match="mask"):
        denoise.denoise_lightmap(img, mask[:16])
    with pytest.raises(BakeError, match="filter"):
        denoise.denoise_lightmap(img, mask, filter="NLM")
    with pytest.raises(BakeError, match="RTLightmap"):
        denoise.denoise_lightmap(img, mask, normal=img, filter="RTLightmap")
    with pytest.raises(BakeError, match="albedo"):
        denoise.denoise_lightmap(img, mask, albedo=img[:, :16])


def test_missing_pyoidn_is_a_bake_error_naming_the_package(monkeypatch):
    # A None entry in sys.modules makes `import pyoidn` fail as it does where it is not installed.
    monkeypatch.setitem(sys.modules, "pyoidn", None)
    assert not denoise.available()
    with pytest.raises(BakeError, match="pyoidn"):
        denoise.denoise_lightmap(np.ones((8, 8, 3), np.float32), np.ones((8, 8), bool))


def test_sharp_lights_are_not_denoised():
    """Point and sun light (finishing.Finishing keeps their part as the shadow rays give it): with nothing
    else to denoise (no bounce, no sky), the denoised lightmap is the raw one (to float32 rounding);
    add a sky and only the sky's part moves."""
    from detp_bake.run.bake import BakeSettings, compute
    from detp_bake.scene import PointLight, SunLight
    from synthetic import box, grid, joined, make_scene

    lights = [SunLight("Sun", np.array([0.3, -0.2, -0.93]), np.full(3, 3.0), angle=np.radians(0.5)),
              PointLight("Lamp", np.array([0.5, 0.5, 1.0]), np.full(3, 40.0), radius=0.05)]
    props = joined(box((-0.3, -0.3, 0.0), (0.3, 0.3, 0.4)), box((0.6, -0.8, 0.0), (0.66, -0.74, 1.5)))
    parts = [("Floor", grid(3.0, 3.0, 6), 0.5, True), ("Props", props, 0.5, False)]
    r = compute(make_scene(parts, lights, resolution=48), BakeSettings(photons=1000, bounces=0, keep_raw=True))
    assert r.direct["sharp_kept"] and r.report()["denoised"]
    np.testing.assert_allclose(r.images["Floor"], r.raw_images["Floor"], rtol=1e-6, atol=1e-6)
    sky = compute(make_scene(parts, lights, world=(0.3, 0.4, 0.5), resolution=48),
                  BakeSettings(photons=1000, bounces=0, keep_raw=True))
    moved = np.abs(sky.images["Floor"] - sky.raw_images["Floor"])[sky.masks["Floor"]]
    assert 0 < moved.max() < 0.3 * np.pi * 0.4 / np.pi  # the sky's noise smoothed, never more than its own light


def test_big_lightmaps_denoise_soft_and_indirect_light_in_one_run(monkeypatch):
    """From finishing.ONE_PASS_FROM pixels the sky's light and the indirect light go through OIDN together:
    one run instead of two (the sun's light is kept, not denoised); the energy is the same."""
    from detp_bake.run import finishing
    from detp_bake.run.bake import BakeSettings, compute
    from detp_bake.scene import SunLight
    from synthetic import box, grid, make_scene

    sun = SunLight("Sun", np.array([0.3, -0.2, -0.93]), np.full(3, 3.0), angle=np.radians(0.5))
    parts = [("Floor", grid(3.0, 3.0, 6), 0.5, True), ("Box", box((-0.3, -0.3, 0.0), (0.3, 0.3, 0.4)), 0.5, False)]
    runs = []
    real = denoise._run_filter
    monkeypatch.setattr(denoise, "_run_filter", lambda *a, **k: runs.append(a[0].shape) or real(*a, **k))
    means = {}
    for one_pass in (10 ** 9, 32 * 32):
        monkeypatch.setattr(finishing, "ONE_PASS_FROM", one_pass)
        runs.clear()
        r = compute(make_scene(parts, [sun], world=(0.3, 0.4, 0.5), resolution=32, bounces=2),
                    BakeSettings(photons=200_000))
        means[one_pass] = r.images["Floor"][r.masks["Floor"]].mean()
        assert len(runs) == (2 if one_pass > 32 * 32 else 1), runs
    a, b = means.values()
    assert abs(a / b - 1) < 0.003


def test_tiles_give_the_whole_image(monkeypatch):
    """A lightmap wider than denoise.TILE is denoised in overlapping tiles on OIDN's 16-texel grid at
    the whole image's exposure, over its own scratch image: the same result as OIDN on the whole
    image (1e-5 of the mean apart here; tiles off the grid moved it by 0.2 % RMS), a tile whose
    core holds no covered texel is not run, and the caller's image, given as its own, is reused."""
    rng = np.random.default_rng(7)
    truth = _point_light(640)[:600]
    mask = np.ones(truth.shape[:2], bool)
    mask[:, 300:306] = False  # a gutter between two charts, across a tile's core
    mask[:272, :272] = False  # the first tile's core: empty
    raw = _noisy(truth, mask, rng)
    kwargs = {"filter": "RTLightmap", "margin": 0}
    monkeypatch.setattr(denoise, "WIDE_UNTIL", 0)  # TILE for every size
    assert len(denoise._spans(600)) == 3 and len(denoise._spans(640)) == 3  # nine tiles
    runs = []
    real = denoise._execute
    monkeypatch.setattr(denoise, "_execute", lambda *a: runs.append(a[2].shape) or real(*a))
    tiled = denoise.denoise_lightmap(raw, mask, **kwargs)
    assert len(runs) == 8  # the empty one left out
    monkeypatch.setattr(denoise, "TILE", 4096)
    whole = denoise.denoise_lightmap(raw, mask, **kwargs)
    assert _rel_rmse(whole, truth, mask) < 0.5 * LEVEL  # it did denoise
    assert np.abs(tiled - whole)[mask].max() <= 1e-4 * whole[mask].mean()  # the exposure: 3e-6 apart
    monkeypatch.setattr(denoise, "TILE", 464)
    own = raw.copy()
    out = denoise.denoise_lightmap(own, mask, own=True, **kwargs)
    assert np.array_equal(out, tiled) and np.shares_memory(out, own)


def test_wide_tiles_up_to_1024():
    """Images up to 1024² get tiles of up to WIDE_TILE² (2 × 2 at 1024²: 1.5 times the image's
    pixels through OIDN, against 2.6 for 4 × 4 tiles of 464²); larger ones keep TILE."""
    assert denoise.tile_for(1024 * 1024) == denoise.WIDE_TILE
    assert len(denoise._spans(1024, denoise.tile_for(1024 * 1024))) == 2
    assert denoise.tile_for(640 * 640) >= 640  # whole
    assert denoise.tile_for(2048 * 2048) == denoise.TILE and len(denoise._spans(2048, denoise.TILE)) == 8


def test_masked_means_match_numpy():
    """The compiled means keep_energy uses: numpy's weighted and plain means of the covered
    texels, and the plain mean where the weights sum to nothing."""
    rng = np.random.default_rng(3)
    img = rng.random((40, 50, 3), dtype=np.float32)
    mask = rng.random((40, 50)) < 0.6
    w = rng.random((40, 50), dtype=np.float32)
    np.testing.assert_allclose(denoise._masked_mean(img, mask, w, True),
                               np.average(img[mask], axis=0, weights=w[mask].astype(np.float64)), rtol=1e-12)
    np.testing.assert_allclose(denoise._masked_mean(img, mask, np.zeros_like(w), True), img[mask].mean(axis=0),
                               rtol=1e-6)
    np.testing.assert_allclose(denoise._masked_mean(img, mask, w, False), img[mask].mean(axis=0), rtol=1e-6)
