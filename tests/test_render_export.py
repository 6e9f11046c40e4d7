"""What F12 renders is what we bake (issue 8, geometry and lights): the exporter reads Blender's
render evaluation (instances, curves, render-only modifiers and levels, render visibility, ray
visibility), negative lights subtract, and broken light settings stop the bake with a message.
Each Blender case is one small scene compared with Cycles' own bake in the same process."""
import numpy as np
import pytest

from detp_bake.bake import BakeSettings, compute
from detp_bake.errors import BakeError
from detp_bake.estimators import EstimatorSettings
from detp_bake.scene import PointLight, SunLight
from synthetic import grid, make_scene


# --------------------------------------------------------------------------- core: negative lights

@pytest.mark.parametrize("direct", ["photons", "sampled"])
def test_negative_light_subtracts_analytically(direct):
    """A point light of power P and one of −P/2 elsewhere: E = E₁ − E₂ at every texel, with the
    photons of the negative light carrying negative flux (or its shadow rays negative irradiance)."""
    h, p = 1.0, 100.0
    a, b = np.array([-0.6, 0.0, h]), np.array([0.7, 0.2, h])
    sc = make_scene([("Plane", grid(4.0, 4.0, 8), 0.0, True)],
                    [PointLight("Plus", a, np.full(3, p)), PointLight("Minus", b, np.full(3, -p / 2))],
                    resolution=32)
    r = compute(sc, BakeSettings(photons=2_000_000, bounces=0, direct=direct, denoise=False,
                                 estimator_settings=EstimatorSettings(radius=0.1)))
    x = r.texels.position

    def e(pos, power):
        d2 = np.sum((x - pos) ** 2, axis=1)
        return power / (4 * np.pi) * h / d2 ** 1.5 / np.pi

    expected = e(a, p) + e(b, -p / 2)
    interior = (np.abs(x[:, 0]) < 1.2) & (np.abs(x[:, 1]) < 1.2)
    ours = r.value[interior, 0]
    assert ours.min() < 0.0  # under the negative light the difference is negative, as in Cycles
    scale = np.abs(expected[interior]).mean()
    assert abs(ours.mean() - expected[interior].mean()) < 0.02 * scale
    assert np.abs(ours - expected[interior]).mean() < 0.06 * scale


def test_photon_counts_follow_absolute_flux():
    from detp_bake import lights
    sc = make_scene([("Plane", grid(2.0, 2.0, 2), 0.5, True)],
                    [PointLight("Plus", np.array([0, 0, 1.0]), np.full(3, 30.0)),
                     PointLight("Minus", np.array([0.5, 0, 1.0]), np.full(3, -10.0))])
    em = lights.build_emitters(sc)
    assert [e.name for e in em] == ["Plus", "Minus"] and em[1].flux[0] < 0
    assert list(lights.allocate(em, 1000)) == [750, 250]


@pytest.mark.parametrize("light, message", [
    (PointLight("Lamp", np.zeros(3), np.full(3, np.inf)), "light 'Lamp': power is infinite"),
    (PointLight("Lamp", np.zeros(3), np.array([np.nan, 1, 1])), "light 'Lamp': power is not a number"),
    (PointLight("Lamp", np.zeros(3), np.full(3, 3.4e38)), "light 'Lamp': power 3.4e\\+38 W is absurd"),
    (PointLight("Lamp", np.zeros(3), np.ones(3), radius=np.inf), "light 'Lamp': radius is infinite"),
    (SunLight("Sun", np.array([0, 0, -1.0]), np.ones(3), angle=np.nan), "light 'Sun': angle is not a number"),
    (SunLight("Sun", np.zeros(3), np.ones(3)), "light 'Sun': its direction is zero"),
])
def test_broken_light_is_a_clear_error_before_any_work(light, message):
    sc = make_scene([("Plane", grid(2.0, 2.0, 2), 0.5, True)], [light])
    with pytest.raises(BakeError, match=message):
        compute(sc, BakeSettings(photons=1000))
