"""Directional lightmaps (--directional sh|dominant, lightmap/sh.py) against the closed forms of
sh.py's docstring: a delta light, a uniform sky over an open plane and over a wall on a black
ground; L0 stays the plain lightmap bit for bit; the L1 file's channels."""
import numpy as np
import pytest

from conftest import CORNELL
from detp_bake.errors import BakeError
from detp_bake.estimators import FrameState
from detp_bake.lightmap import images, sh
from detp_bake.run import directional
from detp_bake.run.bake import BakeSettings, bake, compute, compute_many
from detp_bake.scene import PointLight, SunLight
from synthetic import box, grid, joined, make_scene


def _ratio(result, name):
    """Per covered texel: L0 (n, 3) and L1 (n, 3 colours, 3 axes) as the images hold them."""
    mask = result.masks[name]
    return result.images[name][mask], sh.from_layout(result.l1_images[name][mask])


def _sun(tilt_deg=60.0):
    t = np.radians(tilt_deg)
    return SunLight("Sun", np.array([0.0, np.sin(t), -np.cos(t)]), np.full(3, 3.0)), \
        np.array([0.0, -np.sin(t), np.cos(t)])


def _wall(size=1.0, n=4, gap=0.01):
    """A vertical square facing +x, its foot `gap` above z = 0."""
    p, nrm, uv = grid(size, size, n)
    rot = lambda a: np.stack([a[..., 2], a[..., 1], -a[..., 0]], axis=-1)  # +z → +x, a proper rotation
    p = rot(p)
    p[..., 2] += size / 2 + gap
    return p, rot(nrm), uv


@pytest.mark.parametrize("direct", ["sampled", "photons"])
def test_one_sun_points_at_the_sun_with_a_delta_lights_length(direct):
    """No bounce, no sky: L1/L0 is the unit direction towards the sun (within 1°), |L1| = L0
    (a delta light), and L0 is the plain lightmap bit for bit."""
    sun, towards = _sun()
    sc = make_scene([("Plate", grid(4.0, 4.0, 4), 0.5, True)], [sun], resolution=16)
    settings = BakeSettings(photons=200_000, direct=direct, seed=2)
    plain = compute(sc, settings)
    result = compute(sc, BakeSettings(**{**vars(settings), "directional": "sh"}))
    assert np.array_equal(plain.images["Plate"], result.images["Plate"])
    assert np.array_equal(plain.value, result.value)
    l0, l1 = _ratio(result, "Plate")
    lit = l0[:, 0] > 0.5 * l0[:, 0].max()
    assert lit.mean() > 0.9
    direction = l1[lit] / np.linalg.norm(l1[lit], axis=-1, keepdims=True)
    angle = np.degrees(np.arccos(np.clip(direction @ towards, -1, 1)))
    assert angle.max() < 1.0
    assert np.allclose(np.linalg.norm(l1[lit], axis=-1) / l0[lit], 1.0, atol=2e-3)
    assert result.report()["directional"]["mode"] == "sh"


def test_uniform_sky_over_an_open_plane():
    """A sky of radiance R: L0 = R and L1 = (2/3)·R·n, from 256 cosine-weighted shadow rays a texel
    (the ratio's noise: 0.236/√256 a texel)."""
    sc = make_scene([("Plate", grid(2.0, 2.0, 2), 0.5, True)], [], world=(0.7, 0.7, 0.7), resolution=16)
    result = compute(sc, BakeSettings(photons=100_000, direct_samples=256, denoise=False, directional="sh"))
    l0, l1 = _ratio(result, "Plate")
    assert np.allclose(l0, 0.7, rtol=1e-5)
    ratio = l1[:, 0] / l0[:, :1]
    assert abs(ratio[:, 2].mean() - sh.HEMISPHERE_RATIO) < 0.004
    assert np.abs(ratio[:, 2] - sh.HEMISPHERE_RATIO).max() < 5 * 0.236 / 16
    assert np.abs(ratio[:, :2].mean(axis=0)).max() < 0.006


def test_photon_landings_carry_the_sky_direction_too():
    """With --direct photons the texel histogram's landings alone give L1: the same 2/3 along the
    normal, within the photons' noise."""
    sc = make_scene([("Plate", grid(2.0, 2.0, 2), 0.5, True)], [], world=(0.7, 0.7, 0.7), resolution=8)
    result = compute(sc, BakeSettings(photons=2_000_000, direct="photons", denoise=False, directional="sh"))
    l0, l1 = _ratio(result, "Plate")
    ratio = l1[:, 0].sum(axis=0) / l0[:, 0].sum()
    assert abs(ratio[2] - sh.HEMISPHERE_RATIO) < 0.01
    assert np.abs(ratio[:2]).max() < 0.01


def test_a_wall_under_the_sky_tilts_up():
    """A vertical wall on a wide black ground sees the quarter sphere above the horizon in front:
    L1/L0 = (2/3)x + (4/(3π))z, tilted up by atan(2/π) = 32.48°, |L1|/L0 = 0.7904."""
    ground = grid(400.0, 400.0, 1)
    sc = make_scene([("Wall", _wall(), 0.5, True), ("Ground", ground, 0.0, False)], [], world=(1.0, 1.0, 1.0),
                    resolution=16)
    result = compute(sc, BakeSettings(photons=100_000, direct_samples=256, denoise=False, directional="sh"))
    l0, l1 = _ratio(result, "Wall")
    ratio = (l1[:, 0] / l0[:, :1]).mean(axis=0)
    assert abs(l0[:, 0].mean() - 0.5) < 0.01
    tilt = np.degrees(np.arctan2(ratio[2], ratio[0]))
    assert abs(tilt - np.degrees(sh.WALL_TILT)) < 0.5
    assert abs(np.linalg.norm(ratio) - np.hypot(2 / 3, 4 / (3 * np.pi))) < 0.005
    assert abs(ratio[1]) < 0.005


def test_denoised_l1_stays_physical_and_is_counted():
    """Denoised, L1 keeps |L1| ≤ L0 on every texel (the clamp), and report.json counts what the
    clamp changed; a sun-lit box on a plane with bounces."""
    sun, _ = _sun(40.0)
    sc = make_scene([("Plate", grid(4.0, 4.0, 4), 0.5, True), ("Box", box((-0.4, -0.4, 0), (0.4, 0.4, 0.8)), 0.8, True)],
                    [sun, PointLight("Lamp", np.array([1.0, 1.0, 1.0]), np.full(3, 30.0))], resolution=32, bounces=2)
    result = compute(sc, BakeSettings(photons=300_000, directional="sh"))
    for name in ("Plate", "Box"):
        l0 = result.images[name]
        l1 = sh.from_layout(result.l1_images[name])
        assert np.all(np.linalg.norm(l1, axis=-1) <= np.maximum(l0, 0) * (1 + 1e-5) + 1e-7)
    assert isinstance(result.directional["clamped_texels"], int)


def test_dominant_direction_map():
    """--directional dominant: a unit direction towards the sun and directionality 1 per texel."""
    sun, towards = _sun(30.0)
    sc = make_scene([("Plate", grid(2.0, 2.0, 2), 0.5, True)], [sun], resolution=8)
    result = compute(sc, BakeSettings(photons=100_000, denoise=False, directional="dominant"))
    img = result.l1_images["Plate"][result.masks["Plate"]]
    assert img.shape[1] == 4
    assert np.allclose(img[:, :3], towards, atol=1e-4)
    assert np.allclose(img[:, 3], 1.0, atol=1e-4)
    l0 = result.images["Plate"][result.masks["Plate"]]  # what Apply shades it with: L1 back
    assert np.allclose(sh.from_dominant(l0, img[:, :3], img[:, 3]), l0[:, :, None] * towards, atol=1e-4)
    assert result.report()["directional"]["file_channels"] == ["R", "G", "B", "A"]


def test_the_l1_file_and_its_channels(tmp_path):
    """<name>.<estimator>.L1.exr holds the nine L1 channels by name, after the plain EXR (which
    Apply takes), then the same numbers as one RGB file per axis (L1x, L1y, L1z: what Blender's
    image loader reads); report.json says the layout."""
    sun, _ = _sun()
    sc = make_scene([("Plate", grid(2.0, 2.0, 2), 0.5, True)], [sun], resolution=8)
    result = bake(sc, BakeSettings(photons=50_000, denoise=False, directional="sh"), tmp_path)
    files = result.files["Plate"]
    assert [f.rsplit("/", 1)[1] for f in files] == ["Plate.texel_histogram.exr", "Plate.texel_histogram.L1.exr"] + \
        [f"Plate.texel_histogram.{axis}.exr" for axis in sh.AXIS_FILES]
    import OpenImageIO as oiio
    spec = oiio.ImageInput.open(files[1]).spec()
    assert tuple(spec.channelnames) == sh.L1_CHANNELS
    assert spec.format == oiio.FLOAT
    assert np.array_equal(images.read_image(files[1]), result.l1_images["Plate"])
    for a, path in enumerate(files[2:]):
        assert tuple(oiio.ImageInput.open(path).spec().channelnames) == ("R", "G", "B")
        assert np.array_equal(images.read_image(path), result.l1_images["Plate"][..., 3 * a:3 * a + 3])
    report = result.report()["directional"]
    assert report["channels"] == list(sh.L1_CHANNELS) and report["suffix"] == "L1"
    assert report["axis_files"] == ["L1x", "L1y", "L1z"]


def test_shading_formula_is_exact_for_a_delta_and_a_sky():
    """sh.shade: L0 back for the texel's own normal; a delta light's cosine law and a sky's
    (1 + cos)/2 for a tilted normal."""
    n = np.array([0.0, 0.0, 1.0])
    d = np.array([0.0, np.sin(1.0), np.cos(1.0)])
    tilted = np.array([0.0, np.sin(0.3), np.cos(0.3)])
    l0 = np.full(3, 2.0)
    delta = np.outer(l0, d)
    sky = np.outer(l0, sh.HEMISPHERE_RATIO * n)
    assert np.allclose(sh.shade(l0, delta, n, n), l0)
    assert np.allclose(sh.shade(l0, delta, n, tilted), l0 * (tilted @ d) / (n @ d))
    assert np.allclose(sh.shade(l0, sky, n, tilted), l0 * (1 + tilted @ n) / 2)
    assert np.allclose(sh.shade(l0, sky, n, n), l0)


def test_unsupported_setups_are_refused_by_name():
    with pytest.raises(BakeError, match="directional.*frame ranges"):
        directional.check(BakeSettings(directional="sh"), ["disc_index"], FrameState())
    with pytest.raises(BakeError, match="directional"):
        BakeSettings(directional="bent").validate()


ESTIMATORS = ["texel_histogram", "disc_index", "sphere_cache", "detp", "hybrid", "photon_map"]


def test_every_estimator_gives_the_same_l1_on_the_cornell_box(bpy):
    """The same photons through every estimator (--direct photons: all the light is theirs): each
    object's area-weighted L1/L0 agrees with the texel histogram's within 0.03 (measured: 0.015 at
    most, on the boxes, with 2M photons at 16²), and the sky-free box keeps |L1| ≤ L0 unclamped."""
    from blender_helpers import export
    bpy.ops.wm.open_mainfile(filepath=str(CORNELL))
    sc = export(bpy, resolution=12)
    results = compute_many(sc, BakeSettings(photons=1_000_000, direct="photons", denoise=False, directional="sh",
                                            resolution=12, seed=3), ESTIMATORS)
    ratios = {}
    for est, r in results.items():
        for lm in r.texels.lightmaps:
            pix, area = r.texels.pixel[lm.texels], r.texels.area[lm.texels]
            l0 = r.images[lm.name].reshape(-1, 3)[pix]
            l1 = sh.from_layout(r.l1_images[lm.name].reshape(-1, 9)[pix])
            ratios[est, lm.name] = (l1 * area[:, None, None]).sum(0) / (l0 * area[:, None]).sum(0)[:, None]
    names = [lm.name for lm in results["texel_histogram"].texels.lightmaps]
    assert abs(ratios["texel_histogram", "Floor"][0, 2]) > 0.8  # the floor's light comes from above
    for est in ESTIMATORS[1:]:
        for name in names:
            assert np.abs(ratios[est, name] - ratios["texel_histogram", name]).max() < 0.03, (est, name)


def test_the_memory_estimate_counts_the_l1_channels():
    from detp_bake.run import memory
    sc = make_scene([("Plate", grid(2.0, 2.0, 2), 0.5, True)], [_sun()[0]], resolution=64)
    plain = compute(sc, BakeSettings(photons=20_000, denoise=False)).memory
    directional_ = compute(sc, BakeSettings(photons=20_000, denoise=False, directional="sh")).memory
    assert directional_["parts_mb"]["directional maps"] == round(64 * 64 * memory.DIRECTIONAL_BYTES / 1e6, 1)
    assert "directional maps" not in plain["parts_mb"]
