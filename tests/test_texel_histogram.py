"""The texel histogram against an oracle that finds each landing's texel from its world position
alone (a plane whose UVs map x, y linearly), and its sums through take/absorb."""
import numpy as np

from detp_bake.lightmap import texels as texels_mod
from detp_bake.estimators import Context, EstimatorSettings, create
from detp_bake.transport.photons import PhotonTracer
from detp_bake.scene import PointLight
from synthetic import grid, make_scene

RES = 8
SIZE = 2.0


def _case(photons=100_000, bounces=0, indirect_only=False, batch_size=200_000):
    """A 2 m floor facing up, lit by a lamp above it, and a 2 m ceiling over the lamp that also
    faces up: photons reach the ceiling only from behind, where it has no lightmap side."""
    sc = make_scene([("Floor", grid(SIZE, SIZE, 4), 0.5, True), ("Ceiling", grid(SIZE, SIZE, 4, z=1.0), 0.5, True)],
                    [PointLight("Lamp", np.array([0.3, -0.2, 0.5]), np.full(3, 20.0))], resolution=RES,
                    bounces=bounces)
    tracer = PhotonTracer(sc, photons, bounces, seed=3, batch_size=batch_size, indirect_only=indirect_only)
    batches = list(tracer.batches())
    texels = texels_mod.rasterise(sc)
    est = create("texel_histogram", texels, EstimatorSettings(), context=Context(scene=sc))
    return sc, texels, batches, est


def _oracle(texels, batches):
    """Per floor pixel, Σ flux / texel area over the landings that arrive from above at z = 0."""
    want = np.zeros((RES * RES, 3))
    for b in batches:
        p, d, f = (np.asarray(a, np.float64) for a in (b.hit_position, b.hit_dir, b.hit_flux))
        on = (np.abs(p[:, 2]) < 1e-6) & (d[:, 2] < 0)
        i = np.clip(np.floor((p[on, 0] + SIZE / 2) / SIZE * RES), 0, RES - 1).astype(int)
        j = np.clip(np.floor((p[on, 1] + SIZE / 2) / SIZE * RES), 0, RES - 1).astype(int)
        np.add.at(want, j * RES + i, f[on])
    return want / (SIZE / RES) ** 2


def test_each_landing_goes_to_its_own_texel_from_the_front_only():
    sc, texels, batches, est = _case()
    for b in batches:
        est.add(b)
    out = est.finish()
    floor, ceiling = texels.lightmaps
    assert floor.count == RES * RES and np.allclose(texels.area[floor.texels], (SIZE / RES) ** 2)
    want = _oracle(texels, batches)[texels.pixel[floor.texels]]
    got = out.irradiance[floor.texels]
    assert want.sum() > 0
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12 * want.max())
    # The ceiling is reached from behind only: nothing lands on its lit side.
    assert np.all(out.irradiance[ceiling.texels] == 0.0)
    assert out.counters["counted"] == sum(int(((np.abs(b.hit_position[:, 2]) < 1e-6) & (b.hit_dir[:, 2] < 0)).sum())
                                         for b in batches)


def test_take_and_absorb_give_the_same_sums():
    """Sums taken per batch and absorbed in batch order (a cluster's way) equal one run's."""
    sc, texels, batches, est = _case(photons=60_000, bounces=2, indirect_only=True, batch_size=20_000)
    assert len(batches) >= 2
    for b in batches:
        est.add(b)
    whole = est.finish().irradiance
    est.reset()
    parts = []
    for b in batches:
        est.add(b)
        parts.append(est.take())
    assert not est.acc.any()
    for s in parts:
        est.absorb(s)
    np.testing.assert_allclose(est.finish().irradiance, whole, rtol=1e-12)
    assert whole[texels.lightmaps[0].texels].sum() > 0  # bounced light reaches the floor


def test_cut_out_surfaces_count_every_arrival():
    """A floor that stops half the light (opacity 0.5) lets half its photons through: each landing
    counts twice, so the flux through the floor is the lamp's share of the solid angle,
    P·Ω/(4π) with Ω = 4·asin(a²/(a² + h²)) for a square of half-side a under it at height h."""
    from detp_bake.run.bake import BakeSettings, compute
    power, h, a = 20.0, 1.0, SIZE / 2
    sc = make_scene([("Floor", grid(SIZE, SIZE, 4), 0.5, True)],
                    [PointLight("Lamp", np.array([0.0, 0.0, h]), np.full(3, power))], resolution=RES)
    sc.opacity = np.full(sc.triangle_count, 0.5, np.float32)
    r = compute(sc, BakeSettings(estimator="texel_histogram", photons=400_000, bounces=0, direct="photons",
                                 denoise=False))
    flux = np.sum(r.value[:, 0] * np.pi * r.texels.area)
    expected = power * 4 * np.arcsin(a * a / (a * a + h * h)) / (4 * np.pi)
    assert abs(flux / expected - 1.0) < 0.02, (flux, expected)
    assert r.counters["counted"] < 0.6 * 400_000 * np.arcsin(0.5) * 4 / (4 * np.pi)  # half of them passed
    # Without OIDN its white noise stays: the bake says so.
    assert any("without denoising" in w for w in r.warnings)


def test_a_default_bake_denoises_its_direct_and_indirect_parts_apart_and_keeps_the_energy():
    from detp_bake.run.bake import BakeSettings, compute
    sc = make_scene([("Floor", grid(SIZE, SIZE, 4), 0.8, True),
                     ("Ceiling", grid(SIZE, SIZE, 4, z=1.0, flip=True), 0.8, True)],
                    [PointLight("Lamp", np.array([0.3, -0.2, 0.5]), np.full(3, 20.0))], resolution=16, bounces=2)
    r = compute(sc, BakeSettings(photons=100_000))
    assert r.settings.estimator == "texel_histogram" and r.direct["denoised_apart"]
    for name, img in r.images.items():
        m = r.masks[name]
        raw = r.raw_images[name][m].mean(axis=0, dtype=np.float64)
        assert np.allclose(img[m].mean(axis=0, dtype=np.float64), raw, rtol=0.005), name
        assert np.std(img[m][:, 0]) < np.std(r.raw_images[name][m][:, 0])  # and it did smooth
    assert not compute(sc, BakeSettings(photons=20_000, estimator="disc_index")).direct["denoised_apart"]


def test_smooth_shading_counts_by_the_shading_normal_as_cycles_does():
    """A flat plate whose shading normals lean 30° from its face, under a sun straight down: Cycles
    takes the cosine to the shading normal, E = S·cos 30°, though S W/m² land on the face."""
    from detp_bake.run.bake import BakeSettings, compute
    from detp_bake.scene import SunLight
    s, lean = 3.0, np.radians(30.0)
    pos, nrm, uv = grid(SIZE, SIZE, 4)
    nrm[:] = [0.0, np.sin(lean), np.cos(lean)]
    sc = make_scene([("Plate", (pos, nrm, uv), 0.0, True)],
                    [SunLight("Sun", np.array([0.0, 0.0, -1.0]), np.full(3, s))], resolution=RES)
    r = compute(sc, BakeSettings(estimator="texel_histogram", photons=400_000, bounces=0, direct="photons",
                                 denoise=False))
    mean = np.sum(r.value[:, 0] * r.texels.area) / r.texels.area.sum() * np.pi
    assert abs(mean / (s * np.cos(lean)) - 1.0) < 0.01, mean


def test_block_sums_are_reused_only_once_nobody_holds_them():
    """texel_histogram._Spares: a block's sums handed over come back, cleared, for a later block
    once the bake has let them go; never while anything still holds them (the bake's totals)."""
    from detp_bake.estimators.texel_histogram import _Spares
    spares = _Spares()
    held = np.ones((5, 3))
    spares.hand(held)
    untouched = np.zeros((5, 3))
    assert spares.reuse(untouched) is untouched  # `held` is still held here
    given = np.ones((5, 3))
    spares.hand(given)
    ident = id(given)
    del given  # the bake added it into its totals and let it go
    back = spares.reuse(untouched)
    assert id(back) == ident and not back.any()
    assert held.all()  # never cleared
