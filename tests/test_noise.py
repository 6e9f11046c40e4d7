"""Noise read off the bake (spread between batches), baking to a noise target or a time limit, and
the batch schedule that makes an early stop unbiased."""
import numpy as np
import pytest

from detp_bake.run.bake import BakeSettings, compute
from detp_bake.estimators import EstimatorSettings
from detp_bake.transport.lights import build_emitters
from detp_bake.scene import PointLight, SunLight
from detp_bake.transport.schedule import BatchSchedule
from synthetic import grid, make_scene, uv_sphere

RADIUS, RHO, POWER, BOUNCES = 1.0, 0.5, 100.0, 4


def _photons_of(schedule, index, start, stop):
    """Photons [start, stop) of batch `index` as float64 (origins, directions, flux)."""
    out = [np.empty((stop - start, 3)) for _ in range(3)]
    schedule.emit(index, start, stop, *out, np.empty(0, np.uint64))
    return tuple(out)


def _sphere():
    sc = make_scene([("Sphere", uv_sphere(RADIUS, 24, 48, inward=True), RHO, True)],
                    [PointLight("Lamp", np.zeros(3), np.full(3, POWER))], resolution=48)
    exact = POWER / (4 * np.pi * RADIUS ** 2) * sum(RHO ** k for k in range(BOUNCES + 1)) / np.pi
    return sc, exact


@pytest.mark.parametrize("name", ["disc_index", "sphere_cache", "texel_histogram"])
def test_reported_noise_matches_the_real_error(name):
    """In a closed sphere (uniform irradiance, exact direct light) the texels' RMS error against the
    closed form is the noise: the batch-spread estimate must agree with it within 25 %."""
    sc, exact = _sphere()
    r = compute(sc, BakeSettings(estimator=name, photons=600_000, bounces=BOUNCES, batch_size=50_000,
                                 estimator_settings=EstimatorSettings(radius=0.08)))
    real = np.sqrt(np.mean((r.value[:, 0] - exact) ** 2)) / exact
    reported = r.noise["Sphere"]
    assert 0.75 < reported / real < 1.25, (reported, real)


def test_target_noise_stops_below_the_target_and_unbiased():
    sc, exact = _sphere()
    settings = BakeSettings(estimator="disc_index", photons=20_000_000, bounces=BOUNCES, batch_size=50_000,
                            target_noise=2.0,
                            estimator_settings=EstimatorSettings(radius=0.08))
    r = compute(sc, settings)
    assert r.stopped_by == "target_noise"
    assert r.noise["Sphere"] * 100 <= 2.0
    assert r.stats.photons < 20_000_000 and r.share < 0.5
    real = np.sqrt(np.mean((r.value[:, 0] - exact) ** 2)) / exact
    assert real < 0.025  # the real error is at the target too
    assert abs(np.mean(r.value[:, 0]) / exact - 1) < 0.01  # the batches so far stand for the whole


def test_time_limit_stops_after_the_first_batch_when_already_spent():
    sc, exact = _sphere()
    r = compute(sc, BakeSettings(estimator="disc_index", photons=5_000_000, bounces=BOUNCES, batch_size=100_000,
                                 time_limit=1e-6,
                                 estimator_settings=EstimatorSettings(radius=0.08)))
    assert r.stopped_by == "time_limit" and r.stats.photons == 100_000
    assert abs(np.mean(r.value[:, 0]) / exact - 1) < 0.02


def test_every_batch_shares_photons_between_lights_by_flux():
    """Two lights, 1:3 in flux: every batch holds both in that ratio, and the flux the batches carry
    adds up to exactly what the lights emit."""
    plane = grid(2.0, 2.0, 2)
    sc = make_scene([("Plane", plane, 0.5, True)],
                    [PointLight("A", np.array([0, 0, 1.0]), np.full(3, 10.0)),
                     SunLight("B", np.array([0, 0, -1.0]), np.full(3, 1.0))])
    emitters = build_emitters(sc)
    schedule = BatchSchedule(emitters, 10_500, seed=1, batch_size=1000)
    assert schedule.count == 11
    carried = np.zeros(3)
    for b in range(schedule.count):
        start, stop = schedule.ids(b)
        _, _, flux = _photons_of(schedule, b, start, stop)
        carried += flux.sum(axis=0)
    assert np.allclose(carried, schedule.emitted_flux, rtol=1e-9)
    start, stop = schedule.ids(3)
    _, _, flux = _photons_of(schedule, 3, start, stop)
    per_light = [flux[:k].sum() for k in (schedule._full[0],)]
    assert np.isclose(per_light[0] / flux.sum(), emitters[0].weight / sum(e.weight for e in emitters), rtol=1e-9)
    assert schedule.share(3) == pytest.approx(3000 / 10_500)


def test_the_threads_setting_reaches_the_compiled_estimators():
    """threads=1 runs numba's parallel loops on one thread for the bake, and leaves the setting
    as it was afterwards; the result is the same bit for bit as on all threads."""
    import numba
    from detp_bake.run import pipeline
    seen = []
    original = pipeline.Pipeline.run

    def spy(*args, **kw):
        seen.append(numba.get_num_threads())
        return original(*args, **kw)
    sc, _ = _sphere()
    before = numba.get_num_threads()
    pipeline.Pipeline.run = spy
    try:
        one = compute(sc, BakeSettings(photons=50_000, bounces=2, threads=1, denoise=False))
        every = compute(sc, BakeSettings(photons=50_000, bounces=2, denoise=False))
    finally:
        pipeline.Pipeline.run = original
    assert seen == [1, before] and numba.get_num_threads() == before
    assert np.array_equal(one.value, every.value)


def test_noise_read_while_tracing_is_the_spread_over_the_bakes_light_so_far():
    """BatchNoise.relative with the indirect sums so far scaled to the whole bake and the direct
    light added (what a bake shows while tracing): per lightmap, the RMS of the block spread's
    standard deviation over the mean of that luminance, as numpy computes it texel by texel."""
    from types import SimpleNamespace
    from detp_bake.lightmap.noise import BatchNoise
    rng = np.random.default_rng(7)
    n, blocks = 300, 5
    truth = rng.uniform(0.2, 2.0, n)
    shares = np.full(blocks, 1.0 / 8)  # 5 of 8 eighths traced
    estimates = truth + rng.normal(0.0, 0.1, (blocks, n))  # each block's estimate of the whole bake
    noise = BatchNoise(n)
    running = np.zeros(n)
    for g in range(blocks):
        running += shares[g] * estimates[g]
        noise.update(np.repeat(running[:, None], 3, axis=1), shares[:g + 1].sum())
    direct = rng.uniform(0.0, 1.0, (n, 3)).astype(np.float32)
    lightmaps = [SimpleNamespace(name="A", offset=0, count=120), SimpleNamespace(name="B", offset=120, count=180)]
    share = shares.sum()
    got = noise.relative(lightmaps, direct, 1.0, 1.0 / share)
    w, x = shares, estimates
    mean = (w[:, None] * x).sum(axis=0) / share
    var = (w[:, None] * (x - mean) ** 2).sum(axis=0) / ((blocks - 1) * share)
    level = (running / share + direct.astype(np.float64).mean(axis=1)).mean()
    for lm in lightmaps:
        sl = slice(lm.offset, lm.offset + lm.count)
        assert got[lm.name] == pytest.approx(np.sqrt(var[sl].mean()) / level, rel=1e-4), lm.name
    assert 0.01 < got["A"] < 0.2
