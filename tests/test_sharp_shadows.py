"""Sharp direct light stays sharp through the denoiser (finishing.Finishing: the part of point, spot and sun
lights is kept as the shadow rays give it; only area lights, emissive meshes, the sky and the
indirect light are denoised), against Cycles' own bake in the same process.

A pole 6 cm square stands on a ground plane of 6.25 cm texels under a sun, a sky and an area light:
the sun's shadow is about one texel wide, and the area light and the sky are noisy round the pole.
"""
import math

import numpy as np
import pytest

from blender_helpers import export, lambert, plane_object, sky_world
from detp_bake import blender
from detp_bake.run.bake import BakeSettings, compute

RES = 64  # 4 m ground: 6.25 cm texels
SUN = 3.0
SKY = (0.2, 0.25, 0.35)
LAMP = 400.0  # W, a 1.5 m square area light over the ground: soft light the denoiser must smooth


@pytest.fixture
def pole_scene(empty_blend, bpy):
    scene = empty_blend
    sky_world(bpy, scene, SKY)
    grey = lambert(bpy, "Grey", base=(0.5, 0.5, 0.5))
    plane_object(bpy, "Ground", 4.0, (0.0, 0.0, 0.0), material=grey)
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.03, 0.0, 1.0))
    pole = bpy.context.active_object
    pole.name = "Pole"
    pole.scale = (0.06, 0.06, 2.0)
    pole.data.materials.append(grey)
    light = bpy.data.lights.new("Sun", "SUN")
    light.energy = SUN
    light.angle = math.radians(0.5)
    sun = bpy.data.objects.new("Sun", light)
    sun.rotation_euler = (math.radians(40.0), 0.0, 0.0)  # the shadow falls along +y
    scene.collection.objects.link(sun)
    lamp = bpy.data.lights.new("Lamp", "AREA")
    lamp.energy = LAMP
    lamp.size = 1.5
    area = bpy.data.objects.new("Lamp", lamp)
    area.location = (-0.6, 0.4, 2.5)
    scene.collection.objects.link(area)
    return scene


def _profile(img):
    """Mean across the strip y = 0.3 … 1.4 m of each column of texels (x), the pole's shadow in the middle."""
    rows = slice(int((2.0 + 0.3) / 4.0 * RES), int((2.0 + 1.4) / 4.0 * RES))
    return img[rows].mean(axis=(0, 2))


def test_a_thin_shadow_keeps_its_contrast(pole_scene, bpy):
    sc = export(bpy, objects=["Ground"], resolution=RES)
    ours = compute(sc, BakeSettings(photons=2_000_000, seed=3))
    assert ours.direct["sharp_kept"] and ours.report()["denoised"]
    ref = blender.cycles_bake(bpy.context.scene, ["Ground"], resolution=RES, samples=256)
    a, b = _profile(ours.images["Ground"]), _profile(ref["Ground"])
    lit = np.concatenate([b[4:20], b[-20:-4]]).mean()  # the open ground, away from the plane's edges
    print("Cycles", np.round(b / lit, 3), "\nours", np.round(a / lit, 3))
    dark = int(np.argmin(b))
    print("ours", np.round(a[dark - 3:dark + 4] / lit, 3), "\nCycles", np.round(b[dark - 3:dark + 4] / lit, 3))
    # Cycles' shadow is about one texel: the darkest column reads well under the open ground
    assert b[dark] < 0.75 * lit
    # ours keeps that contrast, column by column across the shadow, within 2 % of the open ground
    np.testing.assert_allclose(a[dark - 2:dark + 3] / lit, b[dark - 2:dark + 3] / lit, atol=0.02)
    assert abs(np.concatenate([a[4:20], a[-20:-4]]).mean() / lit - 1.0) < 0.02
