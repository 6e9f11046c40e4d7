"""The viewer lights a moving object with DETP_light_probes (viewer/detp_probes.js): the ball of
tests/probe_scene.py rolled (?roll=) into the sun half of the probe grid and into the shade half,
shown by headless Chromium (SwiftShader WebGL); every pixel well inside the ball against
base colour × sh9.irradiance of the probes at the ball's centre, at that pixel's normal.

Tolerance, in 8-bit sRGB levels: the PNG's rounding (0.5), float16 coefficients (under 0.1 %, a
quarter of a level at most), the sphere's interpolated vertex normals against the true ones (64 × 32
segments: under 0.5°, under half a level where the sun's gradient is steepest): 1.5 levels
(measured: 0.73 in the sun, 0.50 in shade, 0.25 on average)."""
import math

import numpy as np
import pytest

import probe_scene
from detp_bake.probes import lookup, sh9
from test_viewer import _browser_missing, _Server, _shot

SIZE = 160
TO_GLTF = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
LEVELS = 1.5


def _srgb(linear):
    linear = np.clip(linear, 0.0, 1.0)
    return 255.0 * np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)


def _expected(ball_gltf, fov):
    """(mask, sRGB levels) of the pixels whose ray meets the ball within 0.8 of its radius from its
    centre's line of sight: the camera sits at CAMERA looking along −z in glTF's axes."""
    cam = np.array(probe_scene.CAMERA) @ TO_GLTF.T
    t = math.tan(fov / 2)
    c = (np.arange(SIZE) + 0.5) / SIZE * 2.0 - 1.0
    x, y = np.meshgrid(c, -c)
    d = np.stack([x * t, y * t, -np.ones_like(x)], axis=-1)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    oc = cam - ball_gltf
    b = d @ oc
    disc = b * b - (oc @ oc - 1.0)
    closest = np.sqrt(np.maximum(oc @ oc - b * b, 0.0))  # ray's distance from the centre
    mask = (disc > 0) & (closest < 0.8)
    hit = cam + d * (-b - np.sqrt(np.maximum(disc, 0)))[..., None]
    normal_gltf = hit - ball_gltf
    centre_blender = TO_GLTF.T @ ball_gltf
    sh = lookup.at([probe_scene.probes()], centre_blender)[0]
    linear = np.asarray(probe_scene.BASE) * sh9.irradiance(sh, normal_gltf @ TO_GLTF)  # n in Blender's axes
    return mask, _srgb(linear)


def test_a_rolling_ball_is_lit_by_the_probes_in_sun_and_shade(bpy, tmp_path):
    why = _browser_missing()
    if why:
        pytest.skip(why)
    import OpenImageIO as oiio
    from detp_bake.blender import gltf
    scene, _ = probe_scene.build(bpy, tmp_path / "bake")
    fov = 2 * math.atan(scene.camera.data.sensor_width / 2 / scene.camera.data.lens)
    gltf.export_gltf(scene, tmp_path / "bake", tmp_path / "probes.glb", log=lambda m: None)
    means = {}
    with _Server(tmp_path) as base:
        for name, phase, x in (("sun", 0.25, -2.0), ("shade", 0.75, 2.0)):
            png = tmp_path / f"{name}.png"
            result = _shot(f"{base}/viewer/index.html?model=/model/probes.glb&roll={phase}&shot=1", png, SIZE)
            assert result["ready"] and not result["errors"], result
            assert not [m for m in result["console"] if m["type"] in ("error", "warning")], result["console"]
            assert result["info"]["probeLit"] == 1 and result["info"]["probeGrids"] == 1, result["info"]
            got = np.asarray(oiio.ImageBuf(str(png)).get_pixels(oiio.FLOAT))[..., :3] * 255.0
            ball = np.array([x, probe_scene.BALL[2], -probe_scene.BALL[1]])  # rolled along x, glTF axes
            mask, want = _expected(ball, fov)
            assert mask.sum() > 500
            gap = np.abs(got[mask] - want[mask])
            assert gap.max() <= LEVELS, f"{name}: {gap.max():.1f} levels off (mean {gap.mean():.2f})"
            means[name] = got[mask].mean()
    assert means["sun"] > 2.0 * means["shade"], means
