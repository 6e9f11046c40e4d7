"""The viewer's SH shading through a glTF normalTexture (docs/viewer.md): a wall whose normal map is
an image of horizontal ridges (half of each ridge tilted up and left, half down and right: both
tangent-frame axes matter, and a sign lost in either swaps a side), lit by a low sun only,
baked with `--directional sh --gltf`. The page shades the lightmap with the map's normal as n'
(tangent frame from screen-space derivatives), Blender renders Apply's SH nodes from the same
camera; the ridges' sides facing the sun must be brighter than the flat wall and the others
darker, on both, and the two must agree per side. Pixels are sorted by the ridge pattern the test
drew, projected through the camera."""
import json

import numpy as np
import pytest

from detp_bake.lightmap import encoding
from test_gltf import _cli
from test_viewer import EXPOSURE, SIZE, _browser_missing, _linear, _render_in_blender, _Server, _shot

S, ALBEDO, OFF_NORMAL = 3.0, 0.8, np.radians(65.0)  # sun strength, base colour, sun's angle to the wall's normal
# Towards the sun: 65° off the wall's normal (−y), from the left and 30° above the horizon.
TOWARDS = np.cos(OFF_NORMAL) * np.array([0.0, -1.0, 0.0]) + \
    np.sin(OFF_NORMAL) * np.array([-np.cos(np.radians(30)), 0.0, np.sin(np.radians(30))])
RIDGES, TILT = 4, np.radians(20.0)  # ridges along the wall's height; each side's tilt from the wall
DISTANCE, HALF_FOV = 3.2, 18.0 / 50.0  # camera to wall (m); tan of half the view (36 mm sensor, 50 mm lens)
# What the page and Blender show of the flat wall (linear, after the exposure), and of each side.
FLAT = ALBEDO * S * np.cos(OFF_NORMAL) / np.pi * 2.0 ** EXPOSURE


def _tilt(v):
    """+1 where the map tilts the normal up and left (+v, −u: towards the sun), −1 down and right."""
    return np.where(np.mod(v * RIDGES, 1.0) < 0.5, 1.0, -1.0)


def _normal_map(path):
    """64² tangent-space normals, PNG rows top first (v = 1 at the top)."""
    v = 1.0 - (np.arange(64) + 0.5) / 64
    y = np.sin(TILT) / np.sqrt(2) * _tilt(v)
    rgb = np.stack([-y, y, np.full(64, np.cos(TILT))], axis=-1) * 0.5 + 0.5
    pixels = np.broadcast_to(np.round(rgb * 255).astype(np.uint8)[:, None, :], (64, 64, 3))
    path.write_bytes(encoding.png_bytes(np.ascontiguousarray(pixels)))


def _scene(bpy, normal_png, path):
    """A 2 m wall facing −y, the image through Normal Map into a Lambertian BSDF, a low sun, a
    perspective camera square on to it."""
    import mathutils
    from blender_helpers import lambert, plane_object
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    mat = lambert(bpy, "Ridges", base=(ALBEDO,) * 3)
    nt = mat.node_tree
    bsdf = next(n for n in nt.nodes if n.type == "BSDF_PRINCIPLED")
    uv, tex, normal_map = (nt.nodes.new(t) for t in ("ShaderNodeUVMap", "ShaderNodeTexImage", "ShaderNodeNormalMap"))
    uv.uv_map = normal_map.uv_map = "UVMap"  # the bake adds a lightmap UV layer; the map stays on this one
    tex.image = bpy.data.images.load(str(normal_png))
    tex.image.colorspace_settings.name = "Non-Color"
    nt.links.new(uv.outputs["UV"], tex.inputs["Vector"])
    nt.links.new(tex.outputs["Color"], normal_map.inputs["Color"])
    nt.links.new(normal_map.outputs["Normal"], bsdf.inputs["Normal"])
    plane_object(bpy, "Wall", 2.0, (0, 0, 0), rotation=(np.pi / 2, 0, 0), material=mat)
    light = bpy.data.lights.new("Sun", "SUN")
    light.energy, light.angle = S, 0.0
    sun = bpy.data.objects.new("Sun", light)
    sun.rotation_euler = mathutils.Vector(TOWARDS).to_track_quat("Z", "Y").to_euler()
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    camera.data.lens, camera.data.sensor_width = 50.0, 36.0
    camera.location, camera.rotation_euler = (0, -DISTANCE, 0), (np.pi / 2, 0, 0)
    for obj in (sun, camera):
        scene.collection.objects.link(obj)
    scene.camera = camera
    scene.render.resolution_x = scene.render.resolution_y = SIZE  # the glTF camera's aspectRatio 1
    bpy.ops.wm.save_as_mainfile(filepath=str(path))


def _sides():
    """(lit, shadowed) pixel masks, rows top first: each ridge side's middle (a sixth of a ridge
    kept clear of its edges, where texture and pixel filters blend the sides), on the wall."""
    centre = (np.arange(SIZE) + 0.5) / SIZE * 2.0 - 1.0
    x = centre[None, :] * DISTANCE * HALF_FOV
    z = -centre[:, None] * DISTANCE * HALF_FOV
    v = (z + 1.0) / 2.0
    phase = np.mod(v * RIDGES, 0.5)
    inside = (np.abs(x) < 0.9) & (np.abs(z) < 0.9) & (phase > 0.15) & (phase < 0.35)
    up = _tilt(v) > 0  # the sun is above the horizon and to the left: those sides face it
    return inside & up, inside & ~up


@pytest.mark.blender
def test_the_viewer_shades_the_normal_texture_like_blenders_sh_nodes(bpy, tmp_path):
    why = _browser_missing()
    if why:
        pytest.skip(why)
    _normal_map(tmp_path / "ridges.png")
    _scene(bpy, tmp_path / "ridges.png", tmp_path / "wall.blend")
    out, baked, glb = tmp_path / "out", tmp_path / "baked.blend", tmp_path / "wall.glb"
    _cli("bake", str(tmp_path / "wall.blend"), "--directional", "sh", "--photons", "20000", "--resolution", "32",
         "--out", str(out), "--save", str(baked), "--gltf", str(glb))
    doc = json.loads(glb.read_bytes()[20:20 + int.from_bytes(glb.read_bytes()[12:16], "little")])
    assert [m.get("normalTexture") is not None for m in doc["materials"]] == [True]

    report = json.loads((out / "report.json").read_text())
    _render_in_blender(bpy, baked, report, tmp_path / "blender.png")
    with _Server(tmp_path) as base:
        result = _shot(f"{base}/viewer/index.html?model=/model/{glb.name}&exposure={EXPOSURE}&shot=1",
                       tmp_path / "web.png", SIZE)
    assert result["ready"] and not result["errors"], result
    assert not [m for m in result["console"] if m["type"] in ("error", "warning")], result["console"]
    assert result["info"]["sh"] == 1 and result["info"]["normalMapped"] == 1, result["info"]

    web, blender = _linear(tmp_path / "web.png")[..., 0], _linear(tmp_path / "blender.png")[..., 0]
    lit, dark = _sides()
    assert lit.sum() > 200 and dark.sum() > 200
    for name, side, sign in (("lit", lit, 1), ("shadowed", dark, -1)):
        ours, theirs = web[side].mean(), blender[side].mean()
        print(f"{name}: viewer {ours:.4f}, Blender {theirs:.4f}, flat {FLAT:.4f}")
        assert sign * (ours / FLAT - 1) > 0.15 and sign * (theirs / FLAT - 1) > 0.15, name
        assert abs(ours / theirs - 1) < 0.10, name
