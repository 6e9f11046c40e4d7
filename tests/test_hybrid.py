"""The hybrid estimator: on every frame of a small animated scene, the sums of the brute-force
oracle, with the static discs indexed once for the whole range."""
import numpy as np
import pytest

from detp_bake.run.bake import BakeSettings, compute
from detp_bake.estimators import EstimatorSettings, FrameState
from detp_bake.scene import PointLight
from synthetic import grid, make_scene, uv_sphere

# The ball's centre per frame: clear of the plate, elsewhere, and sunk 1 cm into it (so the
# plate's discs around the contact are cut shorter that frame and go to the sphere cache).
CENTRES = [(0.5, 0.0, 0.7), (-0.4, 0.3, 0.6), (0.1, -0.2, 0.29)]


def scene_at(frame, bounces=2):
    plate = grid(2.0, 2.0, 3)
    back = grid(2.0, 1.2, 2, z=-1.0)  # a wall at y = 1 facing the plate
    back = (back[0][..., [0, 2, 1]] + [0.0, 2.0, 0.6], back[1][..., [0, 2, 1]] * [1, -1, 1], back[2])
    ground = grid(4.0, 4.0, 1, z=-0.3)  # not baked; it holds the scene's bounds (and the discs' ε) still
    ball = uv_sphere(0.3, 8, 16)
    ball = (ball[0] + CENTRES[frame], ball[1], ball[2])
    return make_scene([("Plate", plate, 0.6, True), ("Back", back, 0.5, True), ("Ball", ball, 0.8, True),
                       ("Ground", ground, 0.3, False)],
                      [PointLight("Lamp", np.array([0.3, -0.4, 1.6]), np.full(3, 60.0))], resolution=24,
                      bounces=bounces)


def settings(name, **kw):
    return BakeSettings(estimator=name, photons=20_000, seed=3, denoise=False, batch_size=7_000,
                        estimator_settings=EstimatorSettings(radius_texels=1.5), **kw)


@pytest.mark.parametrize("direct, moving", [("photons", "sphere_cache"), ("sampled", "disc_index")])
def test_hybrid_equals_brute_force_on_every_frame(direct, moving):
    state = FrameState(moving=frozenset({"Ball"}))
    rerouted = []
    for frame in range(len(CENTRES)):
        # Frame ranges estimate every texel (sites.py): the oracle does too.
        ref = compute(scene_at(frame), settings("detp", direct=direct, indirect_spacing=1 if direct == "sampled" else 0))
        hybrid = settings("hybrid", direct=direct)
        hybrid.estimator_settings.hybrid_moving = moving
        got = compute(scene_at(frame), hybrid, frame_state=state)
        c = got.counters
        assert c["index_reused"] == (frame > 0)  # the static discs are indexed once
        assert c["moving_texels"] == ref.texels.lightmaps[2].count
        assert c["static_texels"] == sum(lm.count for lm in ref.texels.lightmaps[:2])
        rerouted.append(c["rerouted_texels"])
        assert 0 < c["moving_segments_near"] < c["segments"]  # only segments near the ball reach the cache
        if c["rerouted_texels"] == 0:
            assert c["crossings"] == ref.counters["crossings"] > 1000
        assert np.allclose(got.value, ref.value, rtol=1e-6, atol=0)
    assert rerouted[0] == rerouted[1] == 0 < rerouted[2]


def test_hybrid_without_frames_is_the_disc_index():
    sc = scene_at(0)
    ref = compute(sc, settings("disc_index", direct="photons"))
    got = compute(scene_at(0), settings("hybrid", direct="photons"))
    assert got.counters["moving_texels"] == 0 and got.counters["static_texels"] == len(ref.texels)
    assert np.array_equal(got.value, ref.value)


def test_an_unknown_moving_estimator_is_named_before_tracing():
    from detp_bake.errors import BakeError
    bad = settings("hybrid")
    bad.estimator_settings.hybrid_moving = "photon_map"
    with pytest.raises(BakeError, match="hybrid_moving"):
        compute(scene_at(0), bad, frame_state=FrameState(moving=frozenset({"Ball"})))
