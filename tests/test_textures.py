"""Textured albedo and cut-out surfaces in the core: lookups as Blender's Image Texture node does
them, colour that bounces, and light through alpha, checked against closed forms."""
import numpy as np
import pytest

from detp_bake.run.bake import BakeSettings, compute
from detp_bake.estimators import EstimatorSettings
from detp_bake.transport.photons import PhotonTracer
from detp_bake.scene import PointLight, SunLight
from detp_bake.transport.textures import CLIP, CLOSEST, EXTEND, LINEAR, REPEAT, Textures, sample, srgb_to_linear
from synthetic import grid, make_scene, uv_sphere


def test_lookups_follow_the_image_texture_node():
    img = np.zeros((2, 4, 4), np.float32)
    img[..., 0] = [[0, 1, 2, 3], [4, 5, 6, 7]]  # row 0 is the bottom row, as Blender's pixels
    img[..., 3] = 1.0
    tex = Textures.pack([img, img, img, img], [REPEAT, EXTEND, CLIP, REPEAT], [LINEAR, LINEAR, LINEAR, CLOSEST])
    # Texel centres are exact; halfway between two centres is their mean.
    s, t = np.array([0.125, 0.25, 0.125]), np.array([0.25, 0.25, 0.5])
    assert np.allclose(sample(tex.pixels, tex.info, 0, s, t)[:, 0], [0.0, 0.5, 2.0])
    # Repeat wraps (the left edge mixes the last column in), Extend clamps, Clip is black outside.
    edge = np.array([0.0]), np.array([0.25])
    assert np.isclose(sample(tex.pixels, tex.info, 0, *edge)[0, 0], 1.5)
    assert np.isclose(sample(tex.pixels, tex.info, 1, *edge)[0, 0], 0.0)
    assert np.isclose(sample(tex.pixels, tex.info, 1, np.array([1.3]), np.array([0.25]))[0, 0], 3.0)
    assert sample(tex.pixels, tex.info, 2, np.array([1.3]), np.array([0.25]))[0, 0] == 0.0
    assert np.isclose(sample(tex.pixels, tex.info, 0, np.array([1.125]), np.array([0.75]))[0, 0], 4.0)
    assert np.isclose(sample(tex.pixels, tex.info, 3, np.array([0.49]), np.array([0.9]))[0, 0], 5.0)


def test_srgb_decoding():
    assert np.allclose(srgb_to_linear(np.array([0.0, 0.04045, 0.5, 1.0])), [0.0, 0.04045 / 12.92, 0.21404, 1.0],
                       atol=1e-5)


def _textured_sphere(texture, tint=(1.0, 1.0, 1.0)):
    pos, nrm, uv = uv_sphere(1.0, 24, 48, inward=True)
    sc = make_scene([("Sphere", (pos, nrm, uv), tint, True)],
                    [PointLight("Lamp", np.zeros(3), np.full(3, 100.0))], resolution=32)
    sc.textures = Textures.pack([texture])
    sc.tex_uvs = uv.copy()
    sc.albedo_texture = np.zeros(sc.triangle_count, np.int32)
    return sc


def test_textured_albedo_bounces_its_mean_colour_in_a_closed_sphere():
    """In a closed sphere every surface element sees every other alike, so after each bounce the
    irradiance is uniform and scales by the area-mean albedo ρ̄ per channel: with 4 bounces the
    mean E is Φ/(4πR²)·Σ_{k≤4} ρ̄^k. A fine red/grey checker texture × a tint gives ρ̄ per channel."""
    checker = np.zeros((64, 64, 4), np.float32)
    ii, jj = np.meshgrid(np.arange(64), np.arange(64))
    odd = (ii // 4 + jj // 4) % 2 == 1
    checker[odd] = (0.9, 0.2, 0.2, 1.0)
    checker[~odd] = (0.3, 0.3, 0.3, 1.0)
    tint = np.array([1.0, 0.8, 1.0])
    sc = _textured_sphere(checker, tint)
    # The mean albedo over the sphere's area, read from the texture at the triangles' UVs.
    rho = tint * np.array([0.6, 0.25, 0.25])
    r = compute(sc, BakeSettings(photons=1_000_000, bounces=4, estimator_settings=EstimatorSettings(radius=0.15)))
    area = r.texels.area
    mean = (r.value * np.pi * area[:, None]).sum(axis=0) / area.sum()
    expected = 100.0 / (4 * np.pi) * np.array([sum(p ** k for k in range(5)) for p in rho])
    # The checker's area mean on the sphere is within a per cent of the texel mean (UV stretch).
    assert np.allclose(mean, expected, rtol=0.02)
    assert mean[0] / mean[1] > 1.3  # red bleeds: the indirect part is red


def test_constant_texture_equals_the_same_constant_albedo():
    flat = np.full((4, 4, 4), 0.5, np.float32)
    textured = _textured_sphere(flat, (0.8, 0.8, 0.8))
    plain = make_scene([("Sphere", uv_sphere(1.0, 24, 48, inward=True), 0.4, True)],
                       [PointLight("Lamp", np.zeros(3), np.full(3, 100.0))], resolution=32)
    settings = BakeSettings(photons=200_000, bounces=3, seed=5, denoise=False)
    assert np.allclose(compute(textured, settings).value, compute(plain, settings).value, rtol=1e-5)


def _card_scene(opacity=None, alpha_image=None):
    """A sun straight down on a floor, a 1 m card 0.5 m above it."""
    floor = grid(3.0, 3.0, 6)
    card = grid(1.0, 1.0, 2, z=0.5)
    sc = make_scene([("Floor", floor, 0.0, True), ("Card", card, 0.0, False)],
                    [SunLight("Sun", np.array([0.0, 0.0, -1.0]), np.full(3, 2.0))], resolution=48)
    n = sc.triangle_count
    sc.opacity = np.ones(n, np.float32)
    cards = sc.object_named("Card").triangles
    if opacity is not None:
        sc.opacity[cards] = opacity
    if alpha_image is not None:
        sc.textures = Textures.pack([alpha_image], [EXTEND], [CLOSEST])
        sc.tex_uvs = np.concatenate([floor[2], card[2]])
        sc.opacity_texture = np.full(n, -1, np.int32)
        sc.opacity_texture[cards] = 0
    return sc


@pytest.mark.parametrize("direct", ["sampled", "photons"])
def test_a_card_of_opacity_a_lets_one_minus_a_through(direct):
    sc = _card_scene(opacity=0.3)
    r = compute(sc, BakeSettings(photons=1_000_000, bounces=0, direct=direct, denoise=False,
                                 estimator_settings=EstimatorSettings(radius=0.05)))
    x = r.texels.position
    under = (np.abs(x[:, 0]) < 0.4) & (np.abs(x[:, 1]) < 0.4)
    open_floor = (np.abs(x[:, 0]) > 0.6) | (np.abs(x[:, 1]) > 0.6)
    full = 2.0 / np.pi
    assert np.isclose(r.value[open_floor, 0].mean(), full, rtol=0.01)
    assert np.isclose(r.value[under, 0].mean() / full, 0.7, atol=0.015)
    if direct == "photons":
        assert r.stats.alpha_passes > 0


@pytest.mark.parametrize("direct", ["sampled", "photons"])
def test_alpha_texture_holes_let_light_through_and_leaves_do_not(direct):
    """The card's alpha texture is a hole on its left half (alpha 0) and a leaf on its right (alpha 1)."""
    alpha = np.ones((2, 2, 4), np.float32)
    alpha[:, 0, 3] = 0.0
    sc = _card_scene(alpha_image=alpha)
    r = compute(sc, BakeSettings(photons=1_000_000, bounces=0, direct=direct, denoise=False,
                                 estimator_settings=EstimatorSettings(radius=0.05)))
    x = r.texels.position
    band = np.abs(x[:, 1]) < 0.4
    hole = band & (x[:, 0] > -0.4) & (x[:, 0] < -0.1)
    leaf = band & (x[:, 0] > 0.1) & (x[:, 0] < 0.4)
    full = 2.0 / np.pi
    assert np.isclose(r.value[hole, 0].mean(), full, rtol=0.02)
    assert r.value[leaf, 0].mean() < 0.02 * full


def test_flux_balances_through_cut_outs():
    sc = _card_scene(opacity=0.5)
    sc.albedo[:] = 0.6
    tracer = PhotonTracer(sc, 200_000, bounces=1024, seed=2)
    for _ in tracer.batches():
        pass
    st = tracer.stats
    assert st.alpha_passes > 0 and st.alpha_cut == 0
    assert np.allclose(st.absorbed + st.escaped, st.emitted, rtol=0.01)
