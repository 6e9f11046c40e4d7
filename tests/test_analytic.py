"""Irradiance against closed-form answers (docs/design.md, Ground truths), for every estimator."""
import numpy as np
import pytest

from detp_bake.run.bake import BakeSettings, compute
from detp_bake.estimators import EstimatorSettings
from detp_bake.scene import PointLight, SunLight
from synthetic import grid, make_scene, uv_sphere

# Photon map: k = 2000 gives about 2 % texel noise. DETP family: a disc radius in metres, small
# enough that its blur over r (proximity bias, ~(r/2R)² on curved surfaces) stays well under 1 %.
# The brute-force oracle gets fewer texels so it stays quick (it is exact against the others anyway),
# and so does the texel histogram, whose noise is that of the photons landing on one texel.
ESTIMATORS = ["photon_map", "detp", "sphere_cache", "disc_index", "texel_histogram"]
COARSE = ("detp", "texel_histogram")


def _bake(scene, name, photons, radius, bounces=0, seed=0):
    settings = EstimatorSettings(k=2000) if name == "photon_map" else EstimatorSettings(radius=radius)
    return compute(scene, BakeSettings(estimator=name, photons=photons, bounces=bounces, seed=seed, direct="photons",
                                       estimator_settings=settings))


@pytest.mark.parametrize("name", ESTIMATORS)
def test_point_light_over_a_plane(name):
    """E(ρ) = I·h/(h²+ρ²)^{3/2}, I = P/(4π); value E/π within 3 % over interior texels."""
    h, power = 1.0, 100.0
    res = 16 if name in COARSE else 32
    sc = make_scene([("Plane", grid(4.0, 4.0, 8), 0.0, True)],
                    [PointLight("Lamp", np.array([0.0, 0.0, h]), np.full(3, power))], resolution=res)
    r = _bake(sc, name, 2_000_000, radius=0.1)
    x = r.texels.position
    rho2 = x[:, 0] ** 2 + x[:, 1] ** 2
    expected = power / (4 * np.pi) * h / (h * h + rho2) ** 1.5 / np.pi
    interior = rho2 < 1.0
    rel = r.value[interior] / expected[interior, None] - 1.0
    assert abs(rel.mean()) < 0.01
    assert np.abs(rel).mean() < 0.03
    assert np.allclose(r.value[:, 0], r.value[:, 2])  # white light stays white


@pytest.mark.parametrize("name", ESTIMATORS)
def test_sun_on_a_plane_is_flat(name):
    """A sun of strength S straight down: E/π = S/π everywhere on the interior, within 2 %."""
    s = 3.0
    sc = make_scene([("Plate", grid(2.0, 2.0, 4), 0.0, True)],
                    [SunLight("Sun", np.array([0.0, 0.0, -1.0]), np.full(3, s))],
                    resolution=16 if name in COARSE else 32)
    r = _bake(sc, name, 1_000_000, radius=0.1)
    x = r.texels.position
    interior = (np.abs(x[:, 0]) < 0.8) & (np.abs(x[:, 1]) < 0.8)
    rel = r.value[interior, 0] / (s / np.pi) - 1.0
    assert abs(rel.mean()) < 0.01
    assert np.abs(rel).mean() < 0.02


@pytest.mark.parametrize("name", ESTIMATORS)
def test_closed_sphere_indirect_is_uniform_and_exact(name):
    """Point source Φ at the centre of a closed sphere of albedo ρ: direct Φ/(4πR²), and with B
    bounces the indirect part is ρΦ/(4πR²)·Σ_{k<B} ρ^k, uniform over the sphere. For DETP this is
    the concave-surface check: landings end short of the tangent plane and must still count."""
    radius, rho, power, bounces = 1.0, 0.5, 100.0, 4
    res = 24 if name in COARSE else 48
    sc = make_scene([("Sphere", uv_sphere(radius, 24, 48, inward=True), rho, True)],
                    [PointLight("Lamp", np.zeros(3), np.full(3, power))], resolution=res)
    direct = power / (4 * np.pi * radius ** 2)
    indirect = rho * direct * sum(rho ** k for k in range(bounces))
    full = _bake(sc, name, 1_000_000, radius=0.12, bounces=bounces)
    only_direct = _bake(sc, name, 1_000_000, radius=0.12, bounces=0, seed=1)
    measured = (full.value[:, 0] - only_direct.value[:, 0]) * np.pi
    area = full.texels.area
    mean = np.sum(measured * area) / np.sum(area)
    assert abs(mean / indirect - 1.0) < 0.03
    assert abs(np.sum(only_direct.value[:, 0] * np.pi * area) / np.sum(area) / direct - 1.0) < 0.03
    # Uniform: the texel-to-texel spread is noise, not a trend from pole to equator.
    z = full.texels.position[:, 2]
    assert abs(np.corrcoef(z, measured)[0, 1]) < 0.2
    assert abs(np.mean(measured[np.abs(z) > 0.7]) / np.mean(measured[np.abs(z) < 0.3]) - 1) < 0.05
