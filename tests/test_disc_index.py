"""The disc index's own machinery: its tree holds every disc once inside conservative boxes and
cones, and its estimate equals the brute-force oracle's on wide discs, on indirect-only photons and
when binning overflows, the same on any thread count."""
import numba
import numpy as np
import pytest

from detp_bake.estimators import Context, EstimatorSettings, create, disc_index
from detp_bake.estimators.bvh import AXIS, CONE, HI, LO, build
from detp_bake.estimators.discs import make_discs
from test_detp_exact import random_case, run, split


def _real_case(radius_texels, resolution=20, photons=200_000):
    """A plate and a ball with rasterised charts, photons traced with indirect_only (the segments
    after the first bounce, as a sampled-direct bake feeds them), discs cut by tangent clearance."""
    from detp_bake import texels as texels_mod
    from detp_bake.estimators.discs import SLAB, disc_radius
    from detp_bake.photons import PhotonTracer
    from detp_bake.scene import PointLight
    from synthetic import grid, make_scene, uv_sphere

    ball = uv_sphere(0.4, 8, 16)
    ball = (ball[0] + [0.0, 0.0, 0.45], ball[1], ball[2])
    sc = make_scene([("Plate", grid(2.0, 2.0, 3), 0.7, True), ("Ball", ball, 0.8, True)],
                    [PointLight("Lamp", np.array([0.5, 0.3, 1.5]), np.full(3, 50.0))], resolution=resolution,
                    bounces=3)
    tracer = PhotonTracer(sc, photons, 3, seed=5, indirect_only=True)
    batches = list(tracer.batches())
    texels = texels_mod.rasterise(sc)
    settings = EstimatorSettings(radius_texels=radius_texels)
    radius = disc_radius(texels, settings)
    clearance = texels_mod.tangent_clearance(texels, sc.positions, radius, 0.5 * SLAB * radius)
    context = Context(scene_radius=tracer.escape_radius, expected_segments=10_000, clearance=clearance)
    return texels, batches, settings, context


def _estimate(name, texels, batches, settings, context):
    est = create(name, texels, settings, context=context)
    for b in batches:
        est.add(b)
    return est.finish()


def test_tree_holds_every_disc_once_inside_its_leaf_box_and_cone():
    texels, _ = random_case(0, n_discs=900)
    d = make_discs(texels, EstimatorSettings(radius=0.08), 3.0)
    tree, disc, _ = build(d.centre, d.normal, d.radius, d.slab, d.eps, leaf=4, cluster=64)
    assert np.array_equal(np.sort(tree.order), np.arange(len(d)))
    leaves = np.flatnonzero(tree.left < 0)
    covered = np.zeros(len(d), int)
    lo, hi = d.bounds()
    rng = np.random.default_rng(0)
    w = rng.normal(size=(2000, 3))
    w /= np.linalg.norm(w, axis=1)[:, None]
    for k in leaves:
        j = tree.order[tree.first[k]:tree.first[k] + tree.count[k]]
        covered[j] += 1
        box = tree.node[k].astype(np.float64)
        assert np.all(box[LO:LO + 3] <= lo[j]) and np.all(box[HI:HI + 3] >= hi[j])
        skipped = w @ box[AXIS:AXIS + 3] >= box[CONE]
        assert np.all(w[skipped] @ d.normal[j].T >= 0.0)  # every disc faces away from a skipped direction
    assert np.all(covered == 1)
    # Clusters partition the discs too.
    held = np.zeros(len(d), int)
    for c in tree.clusters:
        held[tree.first[c]:tree.first[c] + tree.count[c]] += 1
    assert np.all(held == 1) and len(tree.clusters) > 1
    # Inner boxes hold their children's.
    inner = np.flatnonzero(tree.left >= 0)
    for child in (tree.left[inner], tree.left[inner] + 1):
        assert np.all(tree.node[inner, LO:LO + 3] <= tree.node[child, LO:LO + 3])
        assert np.all(tree.node[inner, HI:HI + 3] >= tree.node[child, HI:HI + 3])


@pytest.mark.parametrize("radius_texels", [1.5, 4.0])
def test_wide_discs_on_indirect_photons_equal_brute_force(radius_texels):
    texels, batches, settings, context = _real_case(radius_texels)
    assert sum(b.segment_count for b in batches) > 10_000
    ref = _estimate("detp", texels, batches, settings, context)
    got = _estimate("disc_index", texels, batches, settings, context)
    assert got.counters["crossings"] == ref.counters["crossings"] > 0
    assert np.allclose(got.irradiance, ref.irradiance, rtol=1e-9, atol=0)


def test_same_estimate_on_any_thread_count_and_when_binning_overflows(monkeypatch):
    texels, batch = random_case(2)
    batches = split(batch, 3)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = run("disc_index", texels, batches, radius=0.08)
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        many = run("disc_index", texels, batches, radius=0.08)
    finally:
        numba.set_num_threads(before)
    assert np.array_equal(one.irradiance, many.irradiance)
    # Small clusters and bins of one pair per segment: many clusters, and every chunk overflows once.
    monkeypatch.setattr(disc_index, "CLUSTER", 16)
    monkeypatch.setattr(disc_index, "BIN_CHUNK", 64)
    est = create("disc_index", texels, EstimatorSettings(radius=0.08), context=Context(scene_radius=3.0))
    est.bin_slots = 1
    for b in batches:
        est.add(b)
    small = est.finish()
    assert small.counters["clusters"] > 10 and est.bin_slots > 1
    assert small.counters["crossings"] == one.counters["crossings"]
    assert np.array_equal(small.irradiance, one.irradiance)  # the clusters do not change the sums


def test_tangent_clearance_casts_rays_only_where_they_can_hit_and_gets_the_same_answer():
    """The compiled pre-test skips texels whose lifted disc meets no triangle: the result equals
    casting all eight rays from every texel (a plate with a ball resting on it and a wall)."""
    from detp_bake import texels as texels_mod
    from detp_bake.photons import RayCaster
    from detp_bake.scene import PointLight
    from synthetic import grid, make_scene, uv_sphere

    ball = uv_sphere(0.4, 8, 16)
    ball = (ball[0] + [0.3, 0.0, 0.4], ball[1], ball[2])
    wall = grid(2.0, 1.0, 2)
    wall = (wall[0][..., [2, 0, 1]] + [0.9, 0.0, 0.5], wall[1][..., [2, 0, 1]], wall[2])
    sc = make_scene([("Plate", grid(2.0, 2.0, 3), 0.7, True), ("Ball", ball, 0.8, True), ("Wall", wall, 0.5, True)],
                    [PointLight("Lamp", np.array([0.0, 0.0, 1.5]), np.full(3, 10.0))], resolution=32)
    texels = texels_mod.rasterise(sc)
    reach = np.full(len(texels), 0.15)
    lift = 0.02 * np.ones(len(texels))
    got = texels_mod.tangent_clearance(texels, sc.positions, reach, lift)
    # Every ray from every texel, as the pass did before the pre-test.
    n = texels.normal
    helper = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t = np.cross(n, helper)
    t /= np.linalg.norm(t, axis=1)[:, None]
    s = np.cross(n, t)
    origin = np.ascontiguousarray(texels.position + n * lift[:, None], np.float32)
    caster = RayCaster(sc.positions)
    ref = reach.copy()
    for k in range(8):
        a = 2.0 * np.pi * k / 8
        far = reach.astype(np.float32)
        dist, prim, _ = caster.intersect(origin, np.ascontiguousarray(np.cos(a) * t + np.sin(a) * s, np.float32), far)
        ref[prim >= 0] = np.minimum(ref[prim >= 0], dist[prim >= 0])
    assert np.array_equal(got, ref)
    assert 0.05 < np.mean(ref < reach) < 0.8  # some texels are cut, most are not
