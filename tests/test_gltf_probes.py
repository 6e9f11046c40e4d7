"""The probes in the .glb (blender/gltf_probes.py, docs/gltf.md DETP_light_probes): the scene's grid
in glTF's axes, its seven RGBA float16 3D textures read back into the SH the bake wrote (turned to
y up), the ball marked on its node with its own material (not the probe frame), the scene left as
it was, and no error from the Khronos validator."""
import json
import shutil
import subprocess

import numpy as np
import pytest

import probe_scene
from blender_helpers import scene_snapshot
from conftest import ROOT
from detp_bake.probes import lookup, sh9
from test_gltf import VALIDATOR, read_glb, view_bytes

TO_GLTF = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])


@pytest.fixture(scope="module")
def exported(bpy, tmp_path_factory):
    from detp_bake.blender import gltf
    tmp = tmp_path_factory.mktemp("gltf_probes")
    scene, _ = probe_scene.build(bpy, tmp / "bake")
    before = scene_snapshot(bpy)
    summary = gltf.export_gltf(scene, tmp / "bake", tmp / "probes.glb", log=lambda m: None)
    after = scene_snapshot(bpy)
    return {"path": tmp / "probes.glb", "summary": summary, "before": before, "after": after}


def _textures(doc, binary, entry):
    rx, ry, rz = entry["resolution"]
    return np.stack([np.frombuffer(view_bytes(doc, binary, v), np.float16).reshape(rz, ry, rx, 4)
                     for v in entry["textures"]])


def test_the_grid_and_its_sh_in_gltf_axes(exported):
    doc, binary = read_glb(exported["path"])
    assert "DETP_light_probes" in doc["extensionsUsed"] and "DETP_light_probes" not in doc.get("extensionsRequired", [])
    ext = doc["scenes"][doc.get("scene", 0)]["extensions"]["DETP_light_probes"]
    (entry,) = ext["grids"]
    g = probe_scene.probes()
    assert entry["resolution"] == [4, 2, 1] and entry["format"] == "RGBA16F"
    assert entry["probes"] == 8 and entry["invalid"] == 0
    matrix = np.array(entry["matrix"]).reshape(4, 4).T
    # Blender's box x ∈ [−4, 4], y ∈ [−2, 2], z ∈ [0, 2] is glTF's x ∈ [−4, 4], y ∈ [0, 2], z ∈ [−2, 2]
    corners = np.array([[-1, -1, -1, 1], [1, 1, 1, 1]]) @ matrix.T
    np.testing.assert_allclose(np.sort(corners[:, :3], axis=0), [[-4, 0, -2], [4, 2, 2]])
    tex = _textures(doc, binary, entry)
    assert tex.shape == (7, 1, 2, 4, 4)
    numbers = tex.transpose(1, 2, 3, 0, 4).reshape(1, 2, 4, 28)
    sh = numbers[..., :27].reshape(1, 2, 4, 9, 3).astype(np.float64)
    np.testing.assert_array_equal(numbers[..., 27], 1.0)  # every cell a valid probe
    want = lookup.rotated(g.coefficients, TO_GLTF)  # cell (x, y) of the glTF textures is the grid's own
    got = sh[0][g.index[:, 1], g.index[:, 0]]
    np.testing.assert_allclose(got, want, rtol=2e-3, atol=2e-4)  # float16: 11 bits
    # the same light: E/π read in glTF's axes at glTF normals equals Blender's at Blender normals
    n = np.array([[0.0, 0.0, 1.0], [0.6, -0.8, 0.0], [-0.4, -0.6, 0.7]])
    n = n / np.linalg.norm(n, axis=1)[:, None]
    np.testing.assert_allclose(sh9.irradiance(got[0], n @ TO_GLTF.T), sh9.irradiance(g.coefficients[0], n),
                               rtol=3e-3, atol=1e-3)


def test_the_ball_is_marked_and_keeps_its_own_material(exported):
    doc, _ = read_glb(exported["path"])
    nodes = {n["name"]: n for n in doc["nodes"]}
    assert nodes["Ball"]["extensions"]["DETP_light_probes"] == {"sample": "origin"}
    assert "DETP_light_probes" not in (nodes["Floor"].get("extensions") or {})
    material = doc["materials"][doc["meshes"][nodes["Ball"]["mesh"]]["primitives"][0]["material"]]
    assert material["name"] == "Paint" and "emissiveFactor" not in material
    np.testing.assert_allclose(material["pbrMetallicRoughness"]["baseColorFactor"][:3], probe_scene.BASE, rtol=1e-6)
    assert exported["summary"]["probes"] == 8 and exported["summary"]["probe_lit"] == ["Ball"]
    assert not any("Ball" in w for w in exported["summary"]["warnings"])  # lit by probes, not a lightmap it lacks
    assert exported["after"] == exported["before"]


def test_the_khronos_validator_finds_no_error(exported):
    node = shutil.which("node")
    if node is None or not VALIDATOR.is_dir():
        pytest.skip("needs node and viewer/node_modules/gltf-validator (npm ci --prefix viewer)")
    proc = subprocess.run([node, str(ROOT / "tests" / "gltf_validate.mjs"), str(exported["path"])],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    issues = json.loads(proc.stdout)["issues"]
    assert issues["numErrors"] == 0, [m for m in issues["messages"] if m["severity"] == 0]
