"""Emission: total flux per light type in Cycles' units, and the photon share-out."""
from pathlib import Path

import numpy as np
import pytest

from detp_bake.transport import lights
from detp_bake.errors import BakeError
from detp_bake.scene import AreaLight, PointLight, SpotLight, SunLight
from synthetic import grid, make_scene


def _drawn_flux(emitter, n=200_000, seed=1):
    rng = np.random.default_rng(seed)
    o, d, f = emitter.sample(n, n, rng)
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-9)
    return o, d, f


def test_point_light_is_isotropic_and_emits_its_power():
    e = lights.point_emitter(PointLight("P", np.zeros(3), np.array([10.0, 20.0, 30.0])))
    o, d, f = _drawn_flux(e)
    assert np.allclose(f.sum(axis=0), [10, 20, 30])
    assert abs(d.mean(axis=0)).max() < 0.01  # no preferred direction


def test_spot_light_keeps_point_intensity_inside_its_cone():
    # Cycles: intensity P/(4π) inside the cone, so a 90° cone emits P·(1 − cos 45°)/2.
    e = lights.spot_emitter(SpotLight("S", np.zeros(3), np.array([0, 0, -1.0]), np.full(3, 100.0),
                                      np.radians(90), 0.0))
    assert np.allclose(e.flux, 100 * (1 - np.cos(np.radians(45))) / 2, rtol=1e-4)
    o, d, f = _drawn_flux(e)
    assert np.allclose(f.sum(axis=0), e.flux, rtol=1e-9)
    assert (d[:, 2] <= -np.cos(np.radians(45)) + 1e-9).all()


def test_spot_blend_follows_cycles_smoothstep():
    c = np.cos(np.radians([0, 20, 24, 27, 29]))
    att = lights.spot_attenuation(c, np.radians(60), 0.5)
    # Measured with Cycles (bpy 4.5 and 5.2): 1, 1, 0.79572, 0.31349, 0.04516.
    assert np.allclose(att, [1, 1, 0.79572, 0.31349, 0.04516], atol=2e-4)


def test_area_light_emits_exactly_its_power_one_sided():
    m = np.eye(4)
    m[:3, 3] = [0, 0, 2]
    e = lights.area_emitter(AreaLight("A", m, "RECTANGLE", 1.0, 0.5, np.full(3, 60.0)))
    o, d, f = _drawn_flux(e)
    assert np.allclose(f.sum(axis=0), 60.0)
    assert (d[:, 2] < 0).all()  # faces local −Z
    assert np.abs(o[:, 0]).max() <= 0.5 and np.abs(o[:, 1]).max() <= 0.25
    assert np.isclose(-d[:, 2].mean(), 2 / 3, atol=0.01)  # cosine-weighted: E[cos θ] = 2/3


def test_sun_flux_covers_the_scene_footprint():
    """Straight down on a 2 m × 2 m plane: the sun sends E × (the plane's area, up to the grid's
    conservative rim) into the scene, not E × the bounding disc."""
    sc = make_scene([("Plane", grid(2, 2, 2), 0.5, True)],
                    [SunLight("Sun", np.array([0, 0, -1.0]), np.full(3, 3.0))])
    e = lights.build_emitters(sc)[0]
    assert np.all(e.flux >= 3.0 * 4.0) and np.allclose(e.flux, 3.0 * 4.0, rtol=0.02)


def test_no_light_is_a_clear_error():
    sc = make_scene([("Plane", grid(2, 2, 2), 0.5, True)], [])
    with pytest.raises(BakeError, match="no light"):
        lights.build_emitters(sc)


def test_allocation_is_proportional_and_complete():
    class E:
        def __init__(self, w):
            self.weight = w
    counts = lights.allocate([E(1.0), E(3.0), E(1e-9)], 1000)
    assert counts.sum() >= 1000 and counts[1] == 750 and counts[2] == 1


def test_sun_photons_start_on_the_footprint_and_nearly_all_hit():
    """A 1 m plate in a scene whose bounds are stretched by a far point light: sun photons start
    on the plate's footprint, so almost all of them land, and the irradiance is unchanged."""
    from detp_bake.run.bake import BakeSettings, compute
    from detp_bake.estimators import EstimatorSettings
    from detp_bake.transport.photons import PhotonTracer
    from synthetic import grid, make_scene
    tilt = np.radians(40)
    sun = SunLight("Sun", np.array([0.0, np.sin(tilt), -np.cos(tilt)]), np.full(3, 2.0))
    far = PointLight("Far", np.array([30.0, 0.0, 5.0]), np.full(3, 1e-6))
    sc = make_scene([("Plate", grid(1.0, 1.0, 2), 0.0, True)], [sun, far], resolution=16)
    tracer = PhotonTracer(sc, 200_000, bounces=0, seed=1)
    for _ in tracer.batches():
        pass
    assert tracer.stats.photons_hit > 0.75 * tracer.stats.photons
    r = compute(sc, BakeSettings(photons=400_000, bounces=0, direct="photons", denoise=False,
                                 estimator_settings=EstimatorSettings(radius=0.1)))
    x = r.texels.position
    interior = (np.abs(x[:, 0]) < 0.35) & (np.abs(x[:, 1]) < 0.35)
    assert np.isclose(r.value[interior, 0].mean() * np.pi, 2.0 * np.cos(tilt), rtol=0.02)


def _every_kind():
    """One emitter per light kind and variant of the merged kernel (lights._emit)."""
    def placed(scale, at):
        c, s = np.cos(0.7), np.sin(0.7)
        m = np.eye(4)
        m[:3, :3] = scale * np.array([[c, 0.0, s], [0.3 * s, c, -0.2], [-s, 0.4, c]])
        m[:3, 3] = at
        return m
    power, axis, centre = np.array([10.0, 20.0, 30.0]), np.array([0.2, -0.3, -1.0]), np.array([0.5, -0.2, 1.0])
    out = {"point": lights.point_emitter(PointLight("P", np.array([0.3, -1.2, 2.0]), power)),
           "sphere": lights.point_emitter(PointLight("P", np.array([0.3, -1.2, 2.0]), power, radius=0.25)),
           "spot": lights.spot_emitter(SpotLight("S", np.ones(3), axis, power, np.radians(70), 0.0)),
           "spot_blend": lights.spot_emitter(SpotLight("S", np.ones(3), -axis, power, np.radians(170), 0.4)),
           "parallel": lights.sun_emitter(SunLight("U", axis, np.full(3, 2.0)), centre, 4.0),
           "parallel_wide": lights.sun_emitter(SunLight("U", -axis[[1, 2, 0]], np.full(3, 2.0), 0.1), centre, 4.0)}
    for shape in ("SQUARE", "RECTANGLE", "DISK", "ELLIPSE"):
        out[shape.lower()] = lights.area_emitter(AreaLight("A", placed(1.7, (0.1, 0.2, 2.5)), shape, 0.8, 0.3, power))
    sc = make_scene([("Plane", grid(2, 2, 3), 0.5, True)], [])
    sc.emission = np.zeros((sc.triangle_count, 3))
    sc.emission[[1, 4, 7]] = [[1.0, 2.0, 3.0], [5.0, 0.5, 0.1], [0.2, 0.2, 0.2]]
    out["mesh"] = lights.mesh_emitter(sc, 1e-3)
    return out


ROWS = np.r_[0:4, 254:260]  # both sides of the first block's end


def _photons(emitter):
    o, d, f = (np.empty((260, 3)) for _ in range(3))
    rng = np.empty(260, np.uint64)
    emitter.emit(np.uint64(0x123456789ABCDEF1), 12345, 260, 1000.0, o, d, f, rng)
    return {"o": o[ROWS], "d": d[ROWS], "f": f[ROWS], "rng": rng[ROWS]}


def test_every_kind_emits_the_photons_of_its_former_kernel():
    """The photons of each light kind as its own kernel drew them before the kinds shared one
    (tests/data/emission.npz, saved then): the same draws in the same order. Equal bit for bit
    where saved; to 1e-12 here, as another CPU may fuse multiply-adds differently."""
    saved = np.load(Path(__file__).parent / "data" / "emission.npz")
    for name, emitter in _every_kind().items():
        for key, value in _photons(emitter).items():
            if key == "rng":
                assert np.array_equal(value, saved[f"{name}_{key}"]), name
            else:
                assert np.allclose(value, saved[f"{name}_{key}"], rtol=1e-12, atol=1e-14), (name, key)
