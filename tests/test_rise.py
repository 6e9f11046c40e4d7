"""The DETP slab's measure of a texel's own surface (estimators/rise.py): flat pieces get none,
curved ones what their curvature needs, and another piece in front counts for nothing."""
from types import SimpleNamespace

import numpy as np

from detp_bake.estimators import EstimatorSettings
from detp_bake.estimators.discs import CLEARANCE_FLOOR, make_discs
from detp_bake.estimators.rise import own_surface_rise, piece_extent, welded_pieces
from detp_bake.scene import PointLight
from detp_bake.lightmap.texels import rasterise
from synthetic import grid, make_scene, uv_sphere

LAMP = [PointLight("Lamp", np.zeros(3), np.full(3, 1.0))]


def test_pieces_are_the_welded_components():
    a = grid(1.0, 1.0, 3)[0]
    b = grid(1.0, 1.0, 2, z=0.005)[0]
    both = np.concatenate([a, b])
    scene = make_scene([("Both", (both, np.zeros_like(both), np.zeros(both.shape[:2] + (2,))), 0.5, True)], LAMP)
    one_lightmap = SimpleNamespace(lightmaps=[SimpleNamespace(members=(0,))])  # all welded_pieces reads
    label = welded_pieces(one_lightmap, scene)[0][0]
    assert len(set(label[:len(a)])) == 1 and len(set(label[len(a):])) == 1
    assert label[0] != label[-1]


def test_flat_plates_have_no_rise_even_with_a_plate_in_front():
    upper, lower = grid(1.0, 1.0, 4, z=0.005), grid(1.0, 1.0, 4, z=0.0)
    # One object holding both plates: two pieces, so the upper one is not the lower one's surface.
    both = (np.concatenate([upper[0], lower[0]]), np.concatenate([upper[1], lower[1]]),
            np.concatenate([upper[2], lower[2]]))
    sc = make_scene([("Plates", both, 0.5, True)], LAMP, resolution=32)
    texels = rasterise(sc)
    radius = np.full(len(texels), 3.0 / 32 * np.sqrt(2.0))
    rise = own_surface_rise(texels, sc, radius)
    assert np.isfinite(rise).all()
    assert np.abs(rise).max() < 1e-6


def test_inside_a_sphere_the_rise_is_what_the_curvature_gives():
    """Inside a sphere of radius R the surface stands ρ²/(2R) in front of the tangent plane at ρ:
    r²/(2R) at the rim, up to the facets' own tilt."""
    big, r = 1.0, 0.12
    sc = make_scene([("Sphere", uv_sphere(big, 24, 48, inward=True), 0.5, True)], LAMP, resolution=96)
    texels = rasterise(sc)
    rise = own_surface_rise(texels, sc, np.full(len(texels), r))
    assert np.isfinite(rise).mean() > 0.99
    ratio = rise[np.isfinite(rise)] / (r * r / (2 * big))
    assert 0.8 < np.median(ratio) < 1.5
    assert np.quantile(ratio, 0.05) > 0.5


def test_texels_sparser_than_the_disc_keep_the_full_slab():
    """On a piece of more than SMALL_PIECE vertices, too few texels say nothing: inf."""
    sc = make_scene([("Plate", grid(1.0, 1.0, 8), 0.5, True)], LAMP, resolution=4)
    texels = rasterise(sc)
    rise = own_surface_rise(texels, sc, np.full(len(texels), 0.05))  # texels are 0.25 m apart
    assert np.isinf(rise).all()


def test_a_leaf_smaller_than_its_disc_is_measured_from_its_vertices():
    """A leaf card of a texel or two has no texel of its own around its disc: its vertices say
    it is flat (a folded one rises by its fold)."""
    flat = grid(0.1, 0.05, 1, z=1.0)
    folded = grid(0.1, 0.05, 2, z=2.0)
    folded[0][:, :, 2] += np.where(np.abs(folded[0][:, :, 0]) > 0.04, 0.01, 0.0)  # edges bent up 1 cm
    sc = make_scene([("Flat", flat, 0.5, True), ("Folded", folded, 0.5, True)], LAMP, resolution=2)
    texels = rasterise(sc)
    rise = own_surface_rise(texels, sc, np.full(len(texels), 0.3))
    flat_lm, folded_lm = texels.lightmaps
    assert np.allclose(rise[flat_lm.texels], 0.0, atol=1e-7)
    assert np.all(rise[folded_lm.texels] > 0.004)


def test_piece_extent_is_the_equal_area_radius_of_each_welded_piece():
    """One object holding a 0.1 m card and a 2 m plate: each texel gets sqrt(A/π) of its own piece."""
    card, plate = grid(0.1, 0.1, 2, z=0.5), grid(2.0, 2.0, 4, z=0.0)
    card, plate = (*card[:2], 0.4 * card[2]), (*plate[:2], 0.5 + 0.5 * plate[2])  # side by side in UV
    both = tuple(np.concatenate([a, b]) for a, b in zip(card, plate))
    sc = make_scene([("Both", both, 0.5, True)], LAMP, resolution=32)
    texels = rasterise(sc)
    extent = piece_extent(texels, sc)
    on_card = texels.position[:, 2] > 0.25
    assert on_card.any() and (~on_card).any()
    assert np.allclose(extent[on_card], np.sqrt(0.01 / np.pi), rtol=1e-5)
    assert np.allclose(extent[~on_card], np.sqrt(4.0 / np.pi), rtol=1e-5)


def test_a_disc_is_no_wider_than_its_piece_and_clearance_cuts_what_is_left():
    """The cap (the leaf's size) comes first; tangent clearance then cuts the capped disc, down to
    a quarter of the *capped* radius. A floor taken from the setting's radius let the crowns' discs
    reach past the leaves beside them (+1.5 % on the patio's crowns, benchmarks/objects.py)."""
    sc = make_scene([("Card", grid(0.1, 0.1, 2), 0.5, True)], LAMP, resolution=8)
    texels = rasterise(sc)
    n = len(texels)
    settings = EstimatorSettings(radius=0.1)
    extent = np.full(n, 0.04)
    free = make_discs(texels, settings, 1.0, clearance=np.full(n, 1.0), extent=extent)
    assert np.allclose(free.radius, 0.04)
    cut = make_discs(texels, settings, 1.0, clearance=np.full(n, 0.001), extent=extent)
    assert np.allclose(cut.radius, CLEARANCE_FLOOR * 0.04)
    tiny = make_discs(texels, settings, 1.0, extent=np.full(n, 1e-4))  # no disc under a quarter of the setting
    assert np.allclose(tiny.radius, CLEARANCE_FLOOR * 0.1)
    assert np.allclose(make_discs(texels, settings, 1.0).radius, 0.1)  # no extent: the setting
