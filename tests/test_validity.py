"""Texel validity (validity.py): no light where none can arrive.

A sealed room stands on a ground plane with a sun and a sky outside (synthetic.sealed_room): the
ground inside gets no light at all, and every estimator, denoised or not, must say so. Before texel
validity the default bake read up to 4.7 % of the sunlit ground on the inside rim (OIDN smoothing
across the wall, and landings on the outer strip of a rim texel's square), and the photon map read
2.5 % deep inside (its nearest hits all lie outside).
"""
import numpy as np
import pytest

from detp_bake.lightmap import denoise, texels as texels_mod, validity
from detp_bake.run.bake import BakeSettings, compute
from detp_bake.rays import RayCaster
from detp_bake.scene import SunLight
from synthetic import box, grid, joined, make_scene, sealed_room

SUN = 3.0
TOWARDS = np.array([-0.3, 0.4, -0.87]) / np.linalg.norm([-0.3, 0.4, -0.87])  # from the south-east
SKY = (0.3, 0.4, 0.6)
OFFSET = (0.15, -0.08)


def _sun(angle=0.0):
    return SunLight("Sun", TOWARDS, np.full(3, SUN), angle=angle)


def _ground_xy(res, size=16.0):
    """World x and y of each ground texel's centre, (res, res) each, row 0 at y = −size/2."""
    xs = (np.arange(res) + 0.5) / res * size - size / 2
    return np.meshgrid(xs, xs)


def _inside(res, half=1.0):
    x, y = _ground_xy(res)
    return (np.abs(x - OFFSET[0]) < half) & (np.abs(y - OFFSET[1]) < half)


def _lit(value):
    return SUN * -TOWARDS[2] / np.pi  # E/π of the sun on open ground


@pytest.mark.parametrize("estimator,photons", [("texel_histogram", 1_000_000), ("disc_index", 300_000),
                                               ("photon_map", 300_000), ("detp", 100_000),
                                               ("sphere_cache", 100_000)])
def test_a_sealed_room_is_dark_inside(estimator, photons):
    """Default settings (OIDN on): every ground texel whose centre lies inside the room reads 0,
    while the ground outside is lit by the sun, the sky and the walls."""
    scene = sealed_room([_sun(np.radians(0.5))], world=SKY)
    r = compute(scene, BakeSettings(estimator=estimator, photons=photons))
    img = r.images["Ground"].mean(axis=2)
    inside = _inside(img.shape[0])
    lit = _lit(img)
    x, y = _ground_xy(img.shape[0])
    south = (y < -3.0)
    print(f"{estimator}: inside max {img[inside].max() / lit:.2e} of the sun's, south ground "
          f"{img[south].mean() / lit:.3f}; denoised {r.report()['denoised']}")
    assert r.report()["denoised"]
    assert img[inside].max() <= 1e-4 * lit
    open_sky = 1.0 + np.pi * np.mean(SKY) / (SUN * -TOWARDS[2])  # sun and sky on open ground
    assert open_sky - 0.01 < img[south].mean() / lit < open_sky + 0.03  # and a little bounce


def test_a_texel_under_a_wall_takes_its_side():
    """Texel centres under the south wall, nearer its sunlit outer face, read the open ground's sun
    (all their shadow rays used to start inside the wall: 0); those under the west wall, nearer its
    inner face, read the room's 0. No bounce, no sky, a sharp sun: both exact."""
    scene = sealed_room([_sun()], bounces=0)
    r = compute(scene, BakeSettings(denoise=False, photons=1000))
    img = r.images["Ground"].mean(axis=2)
    x, y = _ground_xy(img.shape[0])
    south = OFFSET[1] - 1.0 - 0.06  # the south wall's outer face
    under_south = (y > south) & (y < OFFSET[1] - 1.0) & (x > -0.4) & (x < 0.9)
    under_west = (x > OFFSET[0] - 1.06) & (x < OFFSET[0] - 1.0) & (np.abs(y - OFFSET[1]) < 0.9)
    assert under_south.sum() >= 4 and under_west.sum() >= 6
    assert r.texels.cuts.moved.sum() >= under_south.sum() + under_west.sum()
    np.testing.assert_allclose(img[under_south], _lit(img), rtol=1e-3)
    assert img[under_west].max() == 0.0


def _plate_with(meshes, res=32):
    """A 4 m ground plate (baked) with `meshes` standing on it, recentred, rasterised, cut."""
    scene = make_scene([("Ground", grid(4.0, 4.0, 4), 0.5, True), ("Props", joined(*meshes), 0.5, False)], [],
                       resolution=res)
    scene, _ = scene.recentred()
    texels = texels_mod.rasterise(scene)
    caster = RayCaster(scene.positions)
    before = texels.position.copy()
    texels.cuts = validity.find_cuts(texels, scene, caster)
    return scene, texels, caster, before


def test_cuts_under_a_box_and_beside_a_one_sided_wall():
    """A box 0.5 m wide on the plate moves the texel centres under its rim out of it (those deep under
    it stay: nothing within their reach); a one-sided wall (a single quad standing on the plate) moves
    nothing, but cuts the texels it crosses, with the cut's normal towards each texel's side."""
    wall = grid(2.0, 1.0, 1)
    wall = (wall[0][:, :, [0, 2, 1]] + np.array([0.0, 0.0, 0.5]) + np.array([0.0, 0.5303, 0.0]),
            wall[1][:, :, [0, 2, 1]], wall[2])  # the plane x-z at y = 0.53, from z = 0 to 1
    cube = box((-1.41, -1.41, 0.0), (-0.91, -0.91, 0.5))
    scene, texels, caster, before = _plate_with([cube, wall])
    cuts = texels.cuts
    size = texels.lightmaps[0].texel_size  # 0.125 m
    moved = np.flatnonzero(np.linalg.norm(texels.position - before, axis=1) > 1e-9)
    assert np.array_equal(np.flatnonzero(cuts.moved), moved) and len(moved) > 0
    p = before[moved]
    # every moved centre lay under the box's rim, and now lies just outside it
    assert np.all((p[:, 0] > -1.41) & (p[:, 0] < -0.91) & (p[:, 1] > -1.41) & (p[:, 1] < -0.91))
    q = texels.position[moved]
    outside_box = (q[:, 0] < -1.41) | (q[:, 0] > -0.91) | (q[:, 1] < -1.41) | (q[:, 1] > -0.91)
    assert np.all(outside_box)
    # near the one-sided wall: cut, not moved, normal towards the texel's side
    by_wall = np.flatnonzero((np.abs(before[:, 1] - 0.5303) < 0.7 * size) & (np.abs(before[:, 0]) < 0.8))
    assert by_wall.size >= 10
    assert not np.isin(by_wall, moved).any()
    rows = cuts.of[by_wall]
    assert np.all(rows >= 0)
    side = np.sign(before[by_wall, 1] - 0.5303)
    np.testing.assert_allclose(cuts.normal[rows, 0, 1], side, atol=1e-6)
    assert np.all((cuts.share[rows] > 0.0) & (cuts.share[rows] < 1.0))
    # far from everything: no cut
    open_ground = np.flatnonzero((np.abs(before[:, 0] - 1.2) < 0.3) & (np.abs(before[:, 1] + 1.2) < 0.3))
    assert np.all(cuts.of[open_ground] == -1)
    # the wall splits the plate's texels into two regions where it stands, and no more
    labels = validity.regions(texels, texels.lightmaps[0], cuts, caster, scene)
    assert labels.max() >= 1


def test_regions_of_every_lightmap_at_once_are_each_ones_own():
    """validity.all_regions on a baked plate and a baked box standing on it (both cut where they
    meet) and a box that touches nothing: each lightmap with a cut labelled as `regions` labels it
    alone, the lightmaps without one left out."""
    scene = make_scene([("Ground", grid(4.0, 4.0, 4), 0.5, True),
                        ("Box", box((-0.5, -0.5, 0.0), (0.5, 0.5, 1.0)), 0.5, True),
                        ("Far", box((5.0, 5.0, 3.0), (5.5, 5.5, 3.5)), 0.5, True)], [], resolution=32)
    texels = texels_mod.rasterise(scene)
    caster = RayCaster(scene.positions)
    cuts = texels.cuts = validity.find_cuts(texels, scene, caster)
    every = validity.all_regions(texels, cuts, caster, scene, threads=2)
    assert list(every) == ["Ground", "Box"]
    for lm in texels.lightmaps[:2]:
        alone = validity.regions(texels, lm, cuts, caster, scene)
        np.testing.assert_array_equal(every[lm.name], alone)
        assert every[lm.name].dtype == np.int32
        assert (every[lm.name].reshape(-1)[texels.pixel[lm.texels]] >= 0).all()  # every texel labelled
    assert every["Ground"].max() == 1  # the ground under the box apart from the ground round it


def test_a_cut_keeps_the_exact_share_of_its_square():
    """The texel histogram divides the landings on a cut texel's side by the area on that side: the
    share is the square's area on the side of the cut line, exactly. A 6 × 6 grid of points on the
    texel's own triangle read 5/6 for the row the wall crosses at 0.758 of a texel, and at most its
    floor of 1/36 where the triangle covered the square's far part only (docs/real_levels.md)."""
    wall = grid(2.0, 1.0, 1)
    wall = (wall[0][:, :, [0, 2, 1]] + np.array([0.0, 0.0, 0.5]) + np.array([0.0, 0.5303, 0.0]),
            wall[1][:, :, [0, 2, 1]], wall[2])  # the plane x-z at y = 0.53, from z = 0 to 1
    scene, texels, caster, before = _plate_with([wall])
    size = texels.lightmaps[0].texel_size  # 0.125 m: the row from y = 0.5 to 0.625 straddles the wall
    row = np.flatnonzero((np.abs(before[:, 1] - 0.5625) < 1e-6) & (np.abs(before[:, 0]) < 0.9))
    near = np.flatnonzero((np.abs(before[:, 1] - 0.4375) < 1e-6) & (np.abs(before[:, 0]) < 0.9))
    assert row.size >= 10 and np.all(texels.cuts.of[row] >= 0) and np.all(texels.cuts.of[near] >= 0)
    np.testing.assert_allclose(texels.cuts.share[texels.cuts.of[row]], (0.625 - 0.5303) / size, rtol=1e-6)
    np.testing.assert_allclose(texels.cuts.share[texels.cuts.of[near]], 1.0)  # cut beyond its square
    assert not texels.cuts.covered.any()


def test_a_box_standing_on_the_ground_has_a_dark_bottom():
    """A box's bottom face lies on the ground face to face: no light reaches it, and Cycles' shadow
    rays (which skip only their own triangle) meet the ground at once there. Shadow rays that start
    a small offset off the bottom face started under the ground and read the open sky below it (E/π
    = L): on the Smart UV level (benchmarks/levels.py) that was 94 % of our +18 % over Cycles' direct
    light on chart-border texels (docs/real_levels.md)."""
    parts = [("Ground", grid(4.0, 4.0, 4), 0.5, False), ("Box", box((-0.5, -0.5, 0.0), (0.5, 0.5, 1.0)), 0.5, True)]
    scene = make_scene(parts, [_sun()], world=SKY, resolution=32)
    r = compute(scene, BakeSettings(denoise=False, photons=1000))
    nz = r.texels.normal[:, 2]
    bottom = nz < -0.9
    assert bottom.sum() >= 20
    assert np.array_equal(r.texels.cuts.covered, bottom)
    assert r.value[bottom].max() == 0.0
    sides = (np.abs(nz) < 0.1) & r.texels.centre_inside
    assert r.value[sides].min() > 0.4 * min(SKY)  # the sides see the sky above the ground (E/π: L/2)


def test_regions_keep_the_denoiser_from_crossing_a_wall():
    """A noisy lit half and a black half of one chart: denoised as one image, OIDN carries light
    into the black half; as two regions, the black half stays 0 and the lit half keeps its mean."""
    rng = np.random.default_rng(1)
    img = np.zeros((64, 64, 3), np.float32)
    img[:, 32:] = 1.0 + 0.3 * rng.standard_normal((64, 32, 1)).astype(np.float32)
    img = np.maximum(img, 0.0)
    mask = np.ones((64, 64), bool)
    regions = np.where(np.arange(64)[None, :] < 32, 1, 0).repeat(64, axis=0).astype(np.int32)
    one = denoise.denoise_lightmap(img, mask, margin=0)
    two = denoise.denoise_lightmap(img, mask, margin=0, regions=regions)
    print(f"black half: one image {one[:, :32].max():.3f}, regions {two[:, :32].max():.3f}")
    assert one[:, :32].max() > 0.01
    assert two[:, :32].max() == 0.0
    np.testing.assert_allclose(two[:, 32:].mean(), img[:, 32:].mean(), rtol=1e-4)
    runs = denoise.region_runs(regions, mask)
    assert len(runs) == 2 and runs[0][1][:, 32:].all() and not runs[0][1][:, :32].any()
    assert runs[1][0] == (slice(0, 64), slice(0, 32 + denoise.FILL_RINGS)) and runs[1][1][:, :32].all()
    # a sliver under the wall, touching both sides: no run for the network, its mean
    regions[10:12, 31:33] = 2
    runs = denoise.region_runs(regions, mask)
    assert len(runs) == 3 and not runs[2][2] and runs[2][1].sum() == 4
    kept = denoise.denoise_lightmap(img, mask, margin=0, regions=regions)
    np.testing.assert_allclose(kept[10:12, 31:33], np.broadcast_to(img[10:12, 31:33].mean(axis=(0, 1)), (2, 2, 3)),
                               rtol=1e-6)


def test_texel_geometry_set_aside_comes_back_bit_for_bit():
    """While a bake traces into the texel histogram (and while OIDN denoises a big lightmap) the
    texels' positions and normals are set aside and found again after: the same bits, the
    positions texel validity moved out from under a box included."""
    cube = box((-1.41, -1.41, 0.0), (-0.91, -0.91, 0.5))
    scene, texels, _, before = _plate_with([cube], res=48)
    assert texels.cuts.moved.any()
    position, normal = texels.position.copy(), texels.normal.copy()
    assert not np.array_equal(position, before)  # some were moved
    with texels_mod.geometry_set_aside(texels, scene):
        assert texels.position is None and texels.normal is None
    assert np.array_equal(texels.position, position) and np.array_equal(texels.normal, normal)
