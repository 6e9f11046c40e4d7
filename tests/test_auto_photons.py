"""The default photon count (bake.auto_photons) is there to keep the noise per texel the same whatever
the lightmap's size: more texels, more photons. Measured, not restated: the texel histogram's error
against the closed-form irradiance of a point light over a plane (docs/design.md, Ground truths)."""
import numpy as np

from detp_bake.run import bake as bake_mod, door
from detp_bake.run.bake import BakeSettings, compute
from detp_bake.scene import PointLight
from synthetic import grid, make_scene

H, POWER = 1.0, 100.0


def _plane(resolution):
    light = PointLight("Lamp", np.array([0.0, 0.0, H]), np.full(3, POWER))
    return make_scene([("Floor", grid(2.0, 2.0, 2), 0.5, True)], [light], resolution=resolution)


def _error(resolution, photons=0):
    """Relative RMS error per texel of a bake with every segment counted (no shadow rays, no denoiser)."""
    r = compute(_plane(resolution), BakeSettings(photons=photons, direct="photons", denoise=False, bounces=0))
    x = r.texels.position
    rho2 = x[:, 0] ** 2 + x[:, 1] ** 2
    truth = POWER / (4 * np.pi) * H / (H * H + rho2) ** 1.5 / np.pi
    return float(np.sqrt(np.mean((r.value[:, 0] / truth - 1.0) ** 2))), r


def test_the_automatic_count_keeps_the_noise_per_texel_as_the_lightmap_grows():
    small, r_small = _error(256)
    large, r_large = _error(512)
    assert r_large.stats.photons > 3 * r_small.stats.photons  # it did choose more ...
    assert 0.75 < large / small < 1.33, (small, large)  # ... enough for the same noise per texel
    # One count for both sizes would leave the larger lightmap twice as noisy (4× the texels).
    fixed, _ = _error(512, photons=r_small.stats.photons)
    assert fixed / small > 1.6, (small, fixed)


def test_a_set_count_is_kept_and_the_chosen_one_reported():
    assert bake_mod.auto_photons(_plane(1024), BakeSettings(photons=123_456)) == 123_456
    said = []
    r = compute(_plane(400), BakeSettings(denoise=False), progress=said.append)
    assert r.stats.photons == r.settings.photons == r.report()["settings"]["photons"] > 0
    told = [p.message for p in said if p.phase == "prepare" and p.message.startswith("Photons:")]
    assert len(told) == 1 and f"{r.stats.photons / 1e6:.2f}M" in told[0], told
    quiet = []
    compute(_plane(64), BakeSettings(photons=50_000, denoise=False), progress=quiet.append)
    assert not any(p.message.startswith("Photons:") for p in quiet)


def test_with_shadow_rays_the_count_is_scaled_by_the_surfaces_survival():
    """Photons that bring the indirect light alone always reflect from their first landing
    (transport/scattering.py), which gives the noise of 1/q times as many with the roulette there:
    the automatic count is PHOTONS_PER_TEXEL times the area-weighted max(albedo), here 0.5."""
    from detp_bake.options import PHOTONS_PER_TEXEL
    from detp_bake.transport.scattering import survival
    sc = _plane(1024)
    assert survival(sc.albedo, sc.positions) == 0.5
    assert bake_mod.auto_photons(sc, BakeSettings()) == PHOTONS_PER_TEXEL * 1024 ** 2 // 2
    assert bake_mod.auto_photons(sc, BakeSettings(direct="photons")) == PHOTONS_PER_TEXEL * 1024 ** 2
    # The denoiser's plan counts photons as worth 1/q with the roulette (fragments.starved_lightmaps).
    q = survival(sc.albedo, sc.positions)
    assert door.roulette_share(q, BakeSettings()) == 0.5
    assert door.roulette_share(q, BakeSettings(direct="photons")) == 1.0
    black = make_scene([("Floor", grid(2.0, 2.0, 2), 0.0, True)], [], resolution=8)
    assert door.roulette_share(survival(black.albedo, black.positions), BakeSettings()) == 1.0 / 64
    # Two surfaces of albedo 1 and 0.25, the first three times the other's area: (3 + 0.25) / 4.
    two = make_scene([("A", grid(3.0, 1.0, 2), 1.0, True), ("B", grid(1.0, 1.0, 2), 0.25, True)], [], resolution=8)
    assert np.isclose(survival(two.albedo, two.positions), 0.8125)
