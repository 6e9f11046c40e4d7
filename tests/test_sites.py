"""Sites (indirect light estimated on every second texel): blending is exact for linear light, never
crosses to another surface, and the default bake keeps Cycles' numbers."""
from dataclasses import replace

import numpy as np
import pytest

from detp_bake.lightmap import sites, texels
from detp_bake.run.bake import BakeSettings, compute
from detp_bake.errors import BakeError
from detp_bake.estimators.discs import disc_radius
from detp_bake.estimators import EstimatorSettings
from detp_bake.scene import AreaLight, PointLight
from synthetic import grid, make_scene


def _plane(res=32):
    return make_scene([("Plane", grid(2.0, 2.0, 4), 0.5, True)],
                      [PointLight("L", np.array([0, 0, 1.0]), np.full(3, 1.0))], resolution=res)


@pytest.mark.parametrize("spacing", [2, 3])
def test_blending_reproduces_linear_light_at_every_texel(spacing):
    tx = texels.rasterise(_plane(32))
    s = sites.choose(tx, spacing)
    # A quarter (a ninth) of the texels, plus the two outermost rings: border texels are no corners.
    lattice = (-(-32 // spacing)) ** 2
    assert lattice <= len(s.index) <= lattice + 32 ** 2 - 28 ** 2
    assert len(s.index) < 0.55 * len(tx)
    light = np.stack([1.0 + 0.3 * tx.position[:, 0] - 0.2 * tx.position[:, 1],
                      2.0 - tx.position[:, 1], np.full(len(tx), 0.5)], axis=1)
    out = s.expand(s.of_sites(light))
    assert np.allclose(out, light, rtol=0, atol=1e-12)
    # Whatever the light does in a chart's border texels (a concave corner, a cut disc), it does not
    # reach the texels beside them: border texels are sites, never corners.
    i, j = tx.pixel % 32, tx.pixel // 32
    border = (i == 0) | (j == 0) | (i == 31) | (j == 31)
    bent = light.copy()
    bent[border] *= np.random.default_rng(1).uniform(0.2, 0.8, (int(border.sum()), 1))
    assert np.allclose(s.expand(s.of_sites(bent)), bent, rtol=0, atol=1e-12)
    # A bump is not linear: texels between sites then differ, so the check above can fail.
    bump = np.exp(-20 * (tx.position[:, :2] ** 2).sum(1))[:, None]
    assert np.abs(s.expand(s.of_sites(bump)) - bump).max() > 1e-3


def test_no_blending_across_surfaces_that_meet_in_uv_space():
    # One object, two charts side by side in UV: a floor and, far from it, a wall facing +X.
    fp, fn, fu = grid(2.0, 2.0, 2)
    wp, wn, wu = grid(2.0, 2.0, 2)
    wp = wp[..., [2, 0, 1]] + np.array([10.0, 0.0, 0.0])
    wn = np.broadcast_to([1.0, 0.0, 0.0], wn.shape).copy()
    fu = fu * [0.5, 1.0]
    wu = wu * [0.5, 1.0] + [0.5, 0.0]
    parts = [("Room", (np.concatenate([fp, wp]), np.concatenate([fn, wn]), np.concatenate([fu, wu])), 0.5, True)]
    sc = make_scene(parts, [PointLight("L", np.array([0, 0, 1.0]), np.full(3, 1.0))], resolution=33)
    tx = texels.rasterise(sc)
    s = sites.choose(tx, 2)
    on_wall = tx.position[:, 0] > 5.0
    light = np.where(on_wall, 5.0, 1.0)[:, None]
    assert np.array_equal(s.expand(s.of_sites(light)), light)
    assert len(s.index) < 0.6 * len(tx)


def test_sites_keep_their_lattice_and_disc_radius():
    tx = texels.rasterise(_plane(32))
    s = sites.choose(tx, 2)
    at = s.texels
    lm = at.lightmaps[0]
    assert lm.count == len(at) and lm.width == 16
    assert len(np.unique(at.pixel)) == len(at)  # no two sites on one pixel
    i, j = tx.pixel[s.index] % 32, tx.pixel[s.index] // 32
    lattice = (i % 2 == 0) & (j % 2 == 0)
    assert np.array_equal(at.pixel[lattice], (j[lattice] // 2) * 16 + i[lattice] // 2)
    assert (at.pixel[~lattice] >= 16 * 16).all()
    es = EstimatorSettings(radius_texels=3.0)
    assert np.allclose(disc_radius(at, es), disc_radius(tx, es)[s.index])


def _box_room(res):
    """A closed white room lit by an area light under its ceiling: indirect light everywhere."""
    parts = [("Floor", grid(4.0, 4.0, 8), 0.8, True),
             ("Ceiling", grid(4.0, 4.0, 8, z=3.0, flip=True), 0.8, True)]
    for k, (axis, sign) in enumerate(((0, 1), (0, -1), (1, 1), (1, -1))):
        p, n, u = grid(4.0, 3.0, 8, z=0.0)
        q = np.empty_like(p)
        q[..., axis] = -2.0 * sign  # the plane's normal +Z turned to face the room's middle
        q[..., 1 - axis] = p[..., 0]
        q[..., 2] = p[..., 1] + 1.5
        nrm = np.zeros(3)
        nrm[axis] = sign
        tri_n = np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0])
        flip = (tri_n @ nrm) < 0
        q[flip] = q[flip][:, [0, 2, 1]]
        u = u.copy()
        u[flip] = u[flip][:, [0, 2, 1]]
        parts.append((f"Wall{k}", (q, np.broadcast_to(nrm, q.shape).copy(), u), 0.8, True))
    m = np.eye(4)
    m[:3, 3] = [0.0, 0.0, 2.9]  # facing down (local -Z)
    light = AreaLight("Panel", m, "SQUARE", 1.0, 1.0, np.full(3, 200.0))
    return make_scene(parts, [light], resolution=res, bounces=4)


def test_spacing_two_keeps_the_mean_of_every_texel_estimate():
    sc = _box_room(32)
    every = compute(sc, BakeSettings(estimator="disc_index", photons=400_000, indirect_spacing=1, denoise=False))
    two = compute(sc, BakeSettings(estimator="disc_index", photons=400_000, indirect_spacing=2, denoise=False))
    assert every.direct["indirect_spacing"] == 1 and two.direct["indirect_spacing"] == 2
    assert two.direct["indirect_sites"] < 0.6 * every.direct["indirect_sites"]
    for name in every.images:
        lm = next(m for m in every.texels.lightmaps if m.name == name)
        a, b = every.value[lm.texels].mean(0), two.value[lm.texels].mean(0)
        assert np.allclose(b, a, rtol=0.01), name


def test_automatic_spacing_goes_by_each_lightmaps_size():
    sc = _box_room(32)
    sc.objects[0].resolution = sites.AUTO_FROM  # the floor's lightmap is large, the others small
    tx = texels.rasterise(sc)
    assert sites.spacings(tx, 0) == [sites.AUTO_SPACING] + [1] * 5
    assert sites.spacings(tx, 3) == [3] * 6
    s = sites.choose(tx, 0)
    floor = tx.lightmaps[0]
    on_floor = s.index < floor.count
    assert on_floor.sum() < 0.5 * floor.count  # sites on the floor only
    assert (~on_floor).sum() == len(tx) - floor.count
    quick = BakeSettings(estimator="disc_index", photons=2000, denoise=False)
    assert compute(sc, quick).direct["indirect_spacing"] == 2
    assert compute(sc, replace(quick, direct="photons")).direct["indirect_spacing"] == 1
    # The texel histogram costs nothing per texel: it always estimates every texel.
    assert compute(sc, replace(quick, estimator="texel_histogram")).direct["indirect_spacing"] == 1


def test_spacing_is_validated():
    with pytest.raises(BakeError, match="indirect_spacing"):
        BakeSettings(indirect_spacing=2, direct="photons").validate()
    with pytest.raises(BakeError, match="indirect_spacing"):
        BakeSettings(indirect_spacing=99).validate()
    BakeSettings(indirect_spacing=3).validate()
