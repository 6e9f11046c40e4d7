"""Texel rasterisation and dilation, checked against geometry computed by hand."""
import numpy as np

from detp_bake.lightmap import dilation, texels
from detp_bake.scene import PointLight
from synthetic import grid, make_scene


def _plane_scene(res, n=4):
    return make_scene([("Plane", grid(2.0, 2.0, n), 0.5, True)],
                      [PointLight("L", np.array([0, 0, 1.0]), np.full(3, 1.0))], resolution=res)


def test_full_square_chart_covers_every_texel_at_its_centre():
    tx = texels.rasterise(_plane_scene(32))
    lm = tx.lightmaps[0]
    assert lm.count == 32 * 32
    i, j = tx.pixel % 32, tx.pixel // 32
    # UV (u, v) = ((i+½)/32, (j+½)/32) maps to x = 2u − 1, y = 2v − 1 on the plane.
    assert np.allclose(tx.position[:, 0], 2 * (i + 0.5) / 32 - 1)
    assert np.allclose(tx.position[:, 1], 2 * (j + 0.5) / 32 - 1)
    assert np.allclose(tx.normal, [0, 0, 1])
    assert np.isclose(lm.texel_size, 2.0 / 32)
    assert np.allclose(tx.area, (2.0 / 32) ** 2)


def test_partly_covered_texels_are_kept_and_clamped_onto_the_surface():
    sc = _plane_scene(16, n=1)
    sc.uvs = 0.1 + 0.8 * sc.uvs  # the chart spans texel coordinates [1.6, 14.4]: its edges cut texels
    tx = texels.rasterise(sc)
    i, j = tx.pixel % 16, tx.pixel // 16
    assert i.min() == 1 and i.max() == 14 and j.min() == 1 and j.max() == 14
    # Coverage areas add up to the plane's area exactly; border texels count only their share: 0.4
    # of a whole texel along an edge (from 1.6 to 2), 0.16 in a corner.
    side = 2.0 / (0.8 * 16)  # a whole texel's width on the 2 m plane
    assert np.isclose(tx.area.sum(), 4.0)
    edge = (i == 1) & (j > 1) & (j < 14)
    np.testing.assert_allclose(tx.area[edge], 0.4 * side * side, rtol=1e-5)
    np.testing.assert_allclose(tx.area[(i == 1) & (j == 1)], 0.16 * side * side, rtol=1e-5)
    np.testing.assert_allclose(tx.area[(i > 1) & (i < 14) & (j > 1) & (j < 14)], side * side, rtol=1e-5)
    assert np.abs(tx.position[:, :2]).max() <= 1.0 + 1e-12  # never off the plane


def test_dilation_fills_the_gutter_with_neighbour_means():
    img = np.zeros((8, 8, 1), np.float32)
    mask = np.zeros((8, 8), bool)
    img[3:5, 3:5] = 2.0
    mask[3:5, 3:5] = True
    out = dilation.dilate(img, mask, 1)
    assert np.all(out[2:6, 2:6] == 2.0)
    assert out[0, 0] == 0 and out[1, 1] == 0
    assert np.all(dilation.dilate(img, mask, 16) == 2.0)
