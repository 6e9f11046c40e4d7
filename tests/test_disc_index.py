"""The disc index's own machinery: its tree holds every disc once inside conservative boxes and
cones, and its estimate equals the brute-force oracle's on wide discs, on indirect-only photons and
when binning overflows, the same on any thread count."""
import numba
import numpy as np
import pytest

from detp_bake.estimators import Context, EstimatorSettings, create, disc_index
from detp_bake.bvh import AXIS, CONE, HI, LO, build
from detp_bake.estimators.discs import make_discs
from test_detp_exact import random_case, run, split


def _real_case(radius_texels, resolution=20, photons=200_000):
    """A plate and a ball with rasterised charts, photons traced with indirect_only (the segments
    after the first bounce, as a sampled-direct bake feeds them), discs cut by tangent clearance,
    slabs cut to their own surface's rise (flat on the plate, curved on the ball)."""
    from detp_bake.lightmap import texels as texels_mod
    from detp_bake.estimators.discs import SLAB, disc_radius
    from detp_bake.estimators.rise import own_surface_rise
    from detp_bake.transport.photons import PhotonTracer
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
    rise = own_surface_rise(texels, sc, radius)
    context = Context(scene_radius=tracer.escape_radius, expected_segments=10_000, clearance=clearance, rise=rise)
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
    monkeypatch.setattr(disc_index, "MIN_CLUSTER", 16)
    monkeypatch.setattr(disc_index, "CLUSTERS_PER_THREAD", 1000)
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
    from detp_bake.lightmap import texels as texels_mod
    from detp_bake.rays import RayCaster
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


def _lattice_case(seed, n_segments=6000, noise=0.0):
    """Texels of three flat lightmaps (one tilted, one with holes, one with 1e-13 noise, all moved
    in their plane by `noise` texels more) and segments aimed at their discs' rims: ending on the
    plane, through it, in and just past the slab, grazing, arriving from behind."""
    from detp_bake.transport.photons import PhotonBatch
    from detp_bake.lightmap.texels import Lightmap, TexelSet

    rng = np.random.default_rng(seed)
    size, texel = 40, 0.05
    frames = [((0.0, 0.0, 0.0), (1, 0, 0), (0, 1, 0)),
              ((0.3, -0.2, 0.5), (0.8, 0.6, 0.0), (-0.36, 0.48, 0.8)),
              ((-1.5, 0.4, 0.2), (0, 0, 1), (1, 0, 0))]
    pos, nrm, pix, lms = [], [], [], []
    for k, (origin, u, v) in enumerate(frames):
        u, v = np.asarray(u, float) / np.linalg.norm(u), np.asarray(v, float) / np.linalg.norm(v)
        i, j = np.meshgrid(np.arange(size), np.arange(size), indexing="xy")
        i, j = i.ravel(), j.ravel()
        keep = np.ones(len(i), bool) if k != 2 else rng.random(len(i)) > 0.2
        i, j = i[keep], j[keep]
        p = np.asarray(origin) + ((i + 0.5) * texel)[:, None] * u + ((j + 0.5) * texel)[:, None] * v
        if k == 1:
            p = p + rng.normal(scale=1e-13, size=p.shape)
        shift = rng.normal(scale=noise * texel, size=(len(p), 2))
        p = p + shift[:, :1] * u + shift[:, 1:] * v
        pos.append(p)
        nrm.append(np.tile(np.cross(u, v), (len(p), 1)))
        pix.append(j * size + i)
        lms.append(Lightmap(f"plane{k}", k, size, size, sum(len(x) for x in pos[:-1]), len(p), texel))
    pos, nrm, pix = np.concatenate(pos), np.concatenate(nrm), np.concatenate(pix)
    n = len(pos)
    texels = TexelSet(pos, nrm, np.zeros(n, np.int32), pix, np.full(n, texel ** 2), np.ones(n, bool), lms)
    # Targets near disc rims (radius 1.5 or 4 texels) and anywhere; segments arrive from random sides.
    c = rng.integers(0, n, n_segments)
    inplane = rng.normal(size=(n_segments, 3))
    inplane -= (inplane * nrm[c]).sum(1)[:, None] * nrm[c]
    inplane /= np.linalg.norm(inplane, axis=1)[:, None]
    rim = texel * rng.choice([1.5, 4.0, 0.7, 2.3], n_segments) * (1 + rng.choice([0, 1e-15, -1e-15, 1e-9], n_segments))
    target = pos[c] + rim[:, None] * inplane
    # On the plane, through it, within the slab of 1.5- or 4-texel discs, or just past it.
    slab = 0.25 * texel * rng.choice([1.5, 4.0], n_segments)
    height = rng.choice([0.0, 0.0, 1e-12, -0.5, 0.3, 1.0, 1.3], n_segments) * slab
    target += height[:, None] * nrm[c]
    w = rng.normal(size=(n_segments, 3))
    w -= 1.2 * np.abs((w * nrm[c]).sum(1))[:, None] * nrm[c]  # mostly arriving from the front
    graze = rng.random(n_segments) < 0.1
    w[graze] = inplane[graze] - rng.choice([1e-3, 1e-7, 1e-11], graze.sum())[:, None] * nrm[c][graze]
    w /= np.linalg.norm(w, axis=1)[:, None]
    length = rng.uniform(0.05, 2.0, n_segments)
    o = target - w * length[:, None]
    flux = rng.uniform(0.1, 1.0, (n_segments, 3))
    batch = PhotonBatch(n_segments, o.astype(np.float32), w.astype(np.float32), length.astype(np.float32),
                        flux.astype(np.float32), *(np.zeros((0, 3), np.float32),) * 4, np.zeros(0, np.int32))
    return texels, batch


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("radius_texels", [1.5, 4.0])
@pytest.mark.parametrize("kernel", ["constant", "epanechnikov"])
@pytest.mark.parametrize("noise", [0.0, 1e-3])
def test_lattice_patches_find_the_oracles_crossings(seed, radius_texels, kernel, noise, monkeypatch):
    """With noise, the patches' lattice tolerance is widened to take the noisy lattices in: then
    the margins, not rounding alone, decide which discs near a rim get the exact test (without
    them, this test fails). One texel in ten has its disc cut short, as tangent clearance does, and
    one in five a slab of its own (a surface that rises in front of it)."""
    from detp_bake.estimators import patches

    if noise:
        monkeypatch.setattr(patches, "LATTICE_TOL", 0.1)
    texels, batch = _lattice_case(seed, noise=noise)
    rng = np.random.default_rng(seed)
    clearance = np.where(rng.random(len(texels)) < 0.1, rng.uniform(0.3, 0.9, len(texels)) * radius_texels * 0.05,
                         np.inf)
    rise = np.where(rng.random(len(texels)) < 0.2, rng.uniform(0.0, 0.3, len(texels)) * radius_texels * 0.05, 0.0)
    settings = EstimatorSettings(radius_texels=radius_texels, kernel=kernel)
    context = Context(scene_radius=3.0, expected_segments=10_000, clearance=clearance, rise=rise)
    ref = _estimate("detp", texels, [batch], settings, context)
    got = _estimate("disc_index", texels, split(batch, 3), settings, context)
    assert got.counters["patches"] >= 3 and got.counters["patch_visits"] > 1000
    assert got.counters["crossings"] == ref.counters["crossings"] > 1000
    assert np.allclose(got.irradiance, ref.irradiance, rtol=1e-9, atol=0)
    monkeypatch.setattr(disc_index, "PATCHES", False)
    loose = _estimate("disc_index", texels, split(batch, 3), settings, context)
    assert loose.counters["patches"] == 0
    assert np.array_equal(loose.irradiance, got.irradiance)  # the same additions in the same order
