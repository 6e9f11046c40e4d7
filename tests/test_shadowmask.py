"""--shadowmask: per-texel visibility of named lights from the shadow rays (run/directional.py,
transport/direct.py): 1 in the open, 0 in the umbra, the edge where the geometry puts it; the
lightmap without the masked light's direct light plus the light times the mask is the full one."""
import numpy as np
import pytest

from detp_bake.errors import BakeError
from detp_bake.lightmap import images
from detp_bake.run.bake import BakeSettings, bake, compute
from detp_bake.scene import PointLight, SunLight
from synthetic import box, grid, make_scene

S, TILT, HALF, HEIGHT, RES, SIZE = 3.0, np.radians(30), 0.4, 0.8, 32, 4.0


def _scene(lights=()):
    """A sun (light travelling towards +y, 30° off vertical) and a box on a 4 m plate, bounces on."""
    sun = SunLight("Sun", np.array([0.0, np.sin(TILT), -np.cos(TILT)]), np.full(3, S))
    return make_scene([("Plate", grid(SIZE, SIZE, 4), 0.5, True),
                       ("Box", box((-HALF, -HALF, 0), (HALF, HALF, HEIGHT)), 0.5, False)],
                      [sun, *lights], resolution=RES, bounces=2)


def _outside(x, y):
    """Distance from (x, y) to the umbra, the box's footprint swept by its top's shadow (negative inside)."""
    y_hi = HALF + HEIGHT * np.tan(TILT)
    dx = np.abs(x) - HALF
    dy = np.maximum(-HALF - y, y - y_hi)
    out = np.hypot(np.maximum(dx, 0), np.maximum(dy, 0))
    return np.where((dx <= 0) & (dy <= 0), np.maximum(dx, dy), out)


def test_mask_is_one_in_the_open_zero_in_the_umbra_within_a_texel_of_the_edge():
    result = compute(_scene(), BakeSettings(photons=100_000, denoise=False, shadowmask=("Sun",)))
    t = result.texels
    rows = result.texels.lightmaps[0].texels
    mask = result.shadowmask_images["Plate"].reshape(-1, 4)[t.pixel[rows]]
    d = _outside(t.position[rows, 0], t.position[rows, 1])
    texel = SIZE / RES
    assert np.all(mask[d > texel, 0] == 1.0)
    assert np.all(mask[d < -texel, 0] == 0.0)
    assert np.all(mask[:, 1:] == 1.0)  # unused channels
    edge = np.abs(d) <= texel
    assert np.all((mask[edge, 0] >= 0) & (mask[edge, 0] <= 1)) and 0 < mask[edge, 0].mean() < 1
    assert result.report()["shadowmask"]["lights"] == ["Sun"]


@pytest.mark.parametrize("denoise", [False, True])
def test_lightmap_without_the_sun_plus_sun_times_mask_is_the_full_lightmap(denoise):
    """Same photons and shadow rays: the sun's direct light S·cosθ/π × mask adds back exactly what
    subtract mode left out (the bounced light stays in both)."""
    lamp = PointLight("Lamp", np.array([1.0, -1.0, 1.5]), np.full(3, 40.0))
    sc = _scene([lamp])
    settings = dict(photons=200_000, denoise=denoise, seed=4)
    full = compute(sc, BakeSettings(**settings))
    part = compute(sc, BakeSettings(**settings, shadowmask=("Sun",)))
    over = compute(sc, BakeSettings(**settings, shadowmask=("Sun",), shadowmask_mode="overlay"))
    sun = S * np.cos(TILT) / np.pi
    m = full.masks["Plate"]
    rebuilt = part.images["Plate"] + sun * part.shadowmask_images["Plate"][..., :1]
    # float32 rounding apart (denoised: OIDN sees the indirect part minus a different direct part)
    assert np.allclose(rebuilt[m], full.images["Plate"][m], rtol=1e-5, atol=1e-5)
    assert np.array_equal(over.images["Plate"], full.images["Plate"])
    assert np.array_equal(over.shadowmask_images["Plate"], part.shadowmask_images["Plate"])
    assert part.images["Plate"][m].mean() < 0.5 * full.images["Plate"][m].mean()


def test_the_shadowmask_file(tmp_path):
    lamp = PointLight("Lamp", np.array([1.0, -1.0, 1.5]), np.full(3, 40.0))
    result = bake(_scene([lamp]), BakeSettings(photons=50_000, denoise=False, shadowmask=("Lamp", "Sun"),
                                               directional="sh"), tmp_path)
    files = [f.rsplit("/", 1)[1] for f in result.files["Plate"]]
    assert files == ["Plate.texel_histogram.exr", "Plate.texel_histogram.L1.exr", "Plate.texel_histogram.L1x.exr",
                     "Plate.texel_histogram.L1y.exr", "Plate.texel_histogram.L1z.exr",
                     "Plate.texel_histogram.shadowmask.exr"]
    written = images.read_image(tmp_path / files[-1])
    assert written.shape[2] == 4 and np.array_equal(written, result.shadowmask_images["Plate"])
    assert result.report()["shadowmask"]["lights"] == ["Lamp", "Sun"]


def test_bad_shadowmask_settings_are_refused_by_name():
    sc = _scene()
    with pytest.raises(BakeError, match="light 'Moon' is not in the scene"):
        compute(sc, BakeSettings(shadowmask=("Moon",)))
    with pytest.raises(BakeError, match="shadowmask.*at most 4"):
        BakeSettings(shadowmask=("a", "b", "c", "d", "e")).validate()
    with pytest.raises(BakeError, match="shadowmask.*direct='sampled'"):
        compute(sc, BakeSettings(shadowmask=("Sun",), direct="photons"))


def test_the_command_line_list_and_comma_separated_text_give_the_same_settings():
    """The core reads a list of names or one comma-separated text (options.Option.core); the
    panel's per-light toggles are tested in test_addon.py."""
    from detp_bake import cli, options
    line = cli.settings_from_args(cli.build_parser().parse_args(
        ["bake", "x.blend", "--out", "o", "--shadowmask", "Sun", "Lamp", "--shadowmask-mode", "overlay",
         "--directional", "sh"]))
    panel = BakeSettings.from_choices({"shadowmask": " Sun, Lamp ,", "shadowmask_mode": "overlay",
                                       "directional": "sh"})
    assert line == panel and line.shadowmask == ("Sun", "Lamp")
    assert options.default("shadowmask") == () == cli.settings_from_args(
        cli.build_parser().parse_args(["bake", "x.blend", "--out", "o"])).shadowmask
