"""The accelerated DETP estimators find exactly the crossings of the brute-force oracle."""
import numpy as np
import pytest

from detp_bake.estimators import Context, EstimatorSettings, create
from detp_bake.transport.photons import PhotonBatch
from detp_bake.lightmap.texels import Lightmap, TexelSet


def random_case(seed, n_discs=600, n_segments=6000):
    """Discs on a few planes (co-planar overlapping ones included) and on a sphere, at chart-like
    clusters; segments aimed at them, grazing ones, and ones ending exactly on a disc plane."""
    rng = np.random.default_rng(seed)
    k = n_discs // 3
    # 1) co-planar, overlapping discs on z = 0 (facing +z), densely packed
    p1 = np.c_[rng.uniform(-1, 1, (k, 2)), np.zeros(k)]
    n1 = np.tile([0, 0, 1.0], (k, 1))
    # 2) a wall x = 1 facing −x
    p2 = np.c_[np.ones(k), rng.uniform(-1, 1, (k, 2))]
    n2 = np.tile([-1.0, 0, 0], (k, 1))
    # 3) random orientations around a sphere of radius 0.5 at (0, 0, 1), facing inwards
    m = n_discs - 2 * k
    v = rng.normal(size=(m, 3))
    v /= np.linalg.norm(v, axis=1)[:, None]
    p3 = np.array([0, 0, 1.0]) + 0.5 * v
    n3 = -v
    pos = np.concatenate([p1, p2, p3])
    nrm = np.concatenate([n1, n2, n3])
    # Segments: random directions from random origins; a third end exactly on a disc's plane.
    o = rng.uniform(-1.5, 1.5, (n_segments, 3)) + [0, 0, 1]
    target = pos[rng.integers(0, len(pos), n_segments)] + rng.normal(scale=0.05, size=(n_segments, 3))
    w = target - o
    length = np.linalg.norm(w, axis=1)
    w /= length[:, None]
    third = n_segments // 3
    # end exactly on the z = 0 plane for the first third (when they go down)
    down = w[:third, 2] < -0.05
    length[:third][down] = -o[:third, 2][down] / w[:third, 2][down]
    # grazing: almost parallel to z = 0, just above it
    g = slice(third, third + third // 4)
    w[g] = np.c_[rng.normal(size=(third // 4, 2)), np.full(third // 4, -1e-3)]
    w[g] /= np.linalg.norm(w[g], axis=1)[:, None]
    o[g, 2] = rng.uniform(0, 0.01, third // 4)
    length[g] = 3.0
    flux = rng.uniform(0.1, 1.0, (n_segments, 3))
    batch = PhotonBatch(n_segments, o.astype(np.float32), w.astype(np.float32), length.astype(np.float32),
                        flux.astype(np.float32), *(np.zeros((0, 3), np.float32),) * 4, np.zeros(0, np.int32))
    n = len(pos)
    texels = TexelSet(pos, nrm, np.zeros(n, np.int32), np.arange(n), np.full(n, 1e-4), np.ones(n, bool),
                      [Lightmap("discs", 0, n, 1, 0, n, 0.01)])
    return texels, batch


def run(name, texels, batches, **settings):
    est = create(name, texels, EstimatorSettings(**settings), context=Context(scene_radius=3.0,
                                                                               expected_segments=10_000))
    for b in batches:
        est.add(b)
    return est.finish()


def split(batch, parts):
    edges = np.linspace(0, batch.segment_count, parts + 1).astype(int)
    return [PhotonBatch(b - a, batch.seg_origin[a:b], batch.seg_dir[a:b], batch.seg_length[a:b],
                        batch.seg_flux[a:b], *(np.zeros((0, 3), np.float32),) * 4, np.zeros(0, np.int32))
            for a, b in zip(edges[:-1], edges[1:])]


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("radius", [0.02, 0.08, 0.3])
@pytest.mark.parametrize("q", [0.4, 0.65, 0.85])
def test_sphere_cache_equals_brute_force(seed, radius, q):
    texels, batch = random_case(seed)
    ref = run("detp", texels, [batch], radius=radius)
    got = run("sphere_cache", texels, split(batch, 3), radius=radius, q=q)
    assert got.counters["crossings"] == ref.counters["crossings"] > 0
    assert np.allclose(got.irradiance, ref.irradiance, rtol=1e-6, atol=0)


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("radius", [0.02, 0.08, 0.3])
@pytest.mark.parametrize("kernel", ["constant", "epanechnikov"])
def test_disc_index_equals_brute_force(seed, radius, kernel):
    texels, batch = random_case(seed)
    ref = run("detp", texels, [batch], radius=radius, kernel=kernel)
    got = run("disc_index", texels, split(batch, 4), radius=radius, kernel=kernel)
    assert got.counters["crossings"] == ref.counters["crossings"] > 0
    assert np.allclose(got.irradiance, ref.irradiance, rtol=1e-6, atol=0)


def test_segments_ending_on_the_disc_plane_count_and_back_faces_do_not():
    texels, batch = random_case(3, n_discs=30, n_segments=10)
    x = texels.position[0]
    o = np.array([x + [0.3, 0.1, 1.0], x + [0.0, 0.0, -1.0], x + [0.0, 0.0, 1.0]], np.float32)
    w = np.array([[-0.3, -0.1, -1.0], [0, 0, 1.0], [0, 0, -1.0]])
    length = np.linalg.norm(w, axis=1) * [1, 1, 0]
    length[2] = 1.0 - 0.01  # stops 1 cm above the plane: inside the slab when r is large enough
    w = (w / np.linalg.norm(w, axis=1)[:, None]).astype(np.float32)
    length[0] = np.linalg.norm([0.3, 0.1, 1.0])
    length[1] = 2.0
    one = PhotonBatch(3, o, w, length.astype(np.float32), np.ones((3, 3), np.float32),
                      *(np.zeros((0, 3), np.float32),) * 4, np.zeros(0, np.int32))
    r = 0.05
    e = run("detp", texels, [one], radius=r).irradiance[0, 0] * np.pi * r * r
    assert e == pytest.approx(2.0)  # the one ending on the plane and the one 1 cm short; not the back one


def test_all_three_agree_on_a_real_bake_with_chart_borders():
    """Texels from rasterised charts (border texels only partly covered, discs overhanging the
    chart) and photons traced with bounces: the three DETP estimators give the same lightmap."""
    from detp_bake.run.bake import BakeSettings, compute
    from detp_bake.scene import PointLight
    from synthetic import grid, make_scene, uv_sphere

    plate = grid(2.0, 2.0, 3)
    plate[2][:] = 0.1 + 0.35 * plate[2]  # the plate's chart covers a corner of its lightmap only
    ball = uv_sphere(0.4, 8, 16)
    ball = (ball[0] + [0.0, 0.0, 0.6], ball[1], ball[2])
    sc = make_scene([("Plate", plate, 0.6, True), ("Ball", ball, 0.8, True)],
                    [PointLight("Lamp", np.array([0.5, 0.3, 1.5]), np.full(3, 50.0))], resolution=24)
    values = {name: compute(sc, BakeSettings(estimator=name, photons=30_000, bounces=2, seed=4, direct="photons",
                                             estimator_settings=EstimatorSettings(radius_texels=1.5)))
              for name in ("detp", "sphere_cache", "disc_index")}
    ref = values["detp"]
    assert ref.counters["crossings"] > 10_000
    for name in ("sphere_cache", "disc_index"):
        assert values[name].counters["crossings"] == ref.counters["crossings"]
        assert np.allclose(values[name].value, ref.value, rtol=1e-6, atol=0)


def test_brute_force_refuses_hours_of_work_before_tracing():
    from detp_bake.errors import BakeError

    texels, _ = random_case(0, n_discs=30, n_segments=10)
    with pytest.raises(BakeError, match="sphere_cache or disc_index"):
        create("detp", texels, EstimatorSettings(), context=Context(expected_segments=10 ** 10))
