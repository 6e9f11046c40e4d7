"""A scene shaped like a downloaded one (tests/downloaded_like.py: unused material slots, a material
shared by two objects, an object exported but not baked, an Emission and a node-group material, a
town block with no lightmap UV layer) through `bake --apply --save --gltf`, in atlases and per
object: the .glb is written, valid, lightmapped where the bake reached, and what has no lightmap is
said once; an export where nothing can carry a lightmap fails and leaves no file; the UV layer the
bake makes has xatlas charts that never overlap."""
import json
import os
import shutil
import subprocess
import sys

import pytest

from conftest import ROOT
from detp_bake.cli import main
from test_gltf import VALIDATOR, _primitives, read_glb

BAKED = ["Room", "CrateA", "CrateB", "Glow", "Bust", "Town"]
QUICK = ["--photons", "5000", "--direct-samples", "1", "--no-denoise"]
MODES = {"atlas": ["--lightmaps", "atlas", "--texel-density", "6", "--atlas-size", "256"],
         "object": ["--resolution", "32"]}


def _run(*argv):
    """A child process (a process that baked and then loaded the glTF exporter hangs on exit)."""
    return subprocess.run([sys.executable, *argv], cwd=ROOT, capture_output=True, text=True, timeout=300,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    path = tmp_path_factory.mktemp("downloaded") / "downloaded.blend"
    proc = _run(str(ROOT / "tests" / "downloaded_like.py"), str(path))
    assert proc.returncode == 0 and path.is_file(), proc.stderr
    return path


@pytest.fixture(scope="module", params=sorted(MODES))
def baked(request, scene, tmp_path_factory):
    tmp = tmp_path_factory.mktemp(request.param)
    proc = _run("-m", "detp_bake", "bake", str(scene), "--objects", *BAKED, *QUICK, *MODES[request.param],
                "--out", str(tmp / "out"), "--apply", "--save", str(tmp / "baked.blend"), "--gltf", str(tmp / "scene.glb"))
    assert proc.returncode == 0, proc.stderr
    return {"mode": request.param, "tmp": tmp, "stderr": proc.stderr}


@pytest.mark.blender
def test_apply_then_gltf_writes_every_baked_primitive_with_its_lightmap(baked):
    doc, _ = read_glb(baked["tmp"] / "scene.glb")
    lit = {}
    for name, prim in _primitives(doc):
        extensions = doc["materials"][prim["material"]].get("extensions") or {}
        lit.setdefault(name, set()).add("MOZ_lightmap" in extensions)
    assert lit == {**{n: {True} for n in BAKED}, "Statue": {False}}
    # The unused slots (floor, wood) are not in the file; the room's five used ones are.
    room = doc["meshes"][next(n["mesh"] for n in doc["nodes"] if n["name"] == "Room")]
    names = {doc["materials"][p["material"]]["name"].split(" (")[0] for p in room["primitives"]}
    assert names == {"walls", "ceiling", "trim", "glass", "rug"}
    said = [line for line in baked["stderr"].splitlines() if "no lightmap on" in line]
    assert said == ["detp_bake: warning: glTF 'scene.glb': no lightmap on object 'Statue' (not baked); "
                    "written without one"]
    assert not [p for p in baked["tmp"].iterdir() if "partial" in p.name]


@pytest.mark.blender
def test_the_khronos_validator_finds_no_error_in_a_downloaded_like_scene(baked):
    node = shutil.which("node")
    if node is None or not VALIDATOR.is_dir():
        pytest.skip("needs node and viewer/node_modules/gltf-validator (npm ci --prefix viewer)")
    proc = subprocess.run([node, str(ROOT / "tests" / "gltf_validate.mjs"), str(baked["tmp"] / "scene.glb")],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    issues = json.loads(proc.stdout)["issues"]
    assert issues["numErrors"] == 0, [m for m in issues["messages"] if m["severity"] == 0]


@pytest.mark.blender
def test_the_created_lightmap_uvs_are_xatlas_charts(baked):
    """The town (864 quads, no lightmap UV layer) gets a layer of about one chart per box side,
    not one per face (Lightmap Pack's), and no texel of the bake lies under two faces."""
    report = json.loads((baked["tmp"] / "out" / "report.json").read_text())
    town = next(o for o in report["objects"] if o["name"] == "Town")
    assert 16 * 5 <= town["charts"]["count"] <= 16 * 6 < 864 / 8
    assert "created UV layer 'Lightmap' with xatlas charts on Room" in baked["stderr"]
    assert "lie under two or more faces" not in baked["stderr"]


@pytest.mark.blender
def test_created_uvs_and_the_atlas_never_overlap(bpy, scene):
    """The project's own overlap counter (texel centres under two or more triangles) on the
    atlas the bake packs from the layers it made, and on each per-object lightmap."""
    from detp_bake import blender
    from detp_bake.lightmap import texels
    from detp_bake.run.settings import BakeSettings
    for settings in (BakeSettings(lightmaps="atlas", texel_density=6.0, atlas_size=256), BakeSettings(resolution=32)):
        bpy.ops.wm.open_mainfile(filepath=str(scene))
        exported = blender.export_scene(bpy.context.scene, None, BAKED, None, settings.resolution,
                                        log=lambda m: None, atlas=settings)
        lightmaps = texels.rasterise(exported).lightmaps
        assert len(lightmaps) == (1 if settings.lightmaps == "atlas" else len(BAKED))
        for lm in lightmaps:
            assert lm.overlap == 0.0 and lm.outside < 1e-9, lm.name


@pytest.mark.blender
def test_an_export_where_nothing_can_carry_a_lightmap_fails_and_leaves_no_file(bpy, baked, tmp_path, capsys):
    bpy.ops.wm.open_mainfile(filepath=str(baked["tmp"] / "baked.blend"))
    for name in BAKED:  # the baked objects are no longer rendered: the export leaves them out
        bpy.data.objects[name].hide_render = True
    hidden = tmp_path / "hidden.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(hidden))
    target = tmp_path / "scene.glb"
    code = main(["export-gltf", str(hidden), "--lightmaps", str(baked["tmp"] / "out"), "--out", str(target)])
    err = capsys.readouterr().err
    assert code == 2 and "no exported mesh carries a lightmap" in err and "object 'Room' (baked, but not in" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hidden.blend"]


@pytest.mark.parametrize("flags, message", [
    (["--texel-density", "20", "--atlas-size", "512"],
     "--texel-density and --atlas-size only work with atlases, and these are per-object lightmaps (sized by "
     "--resolution): add --lightmaps atlas"),
    (["--atlas-charts", "smart"], "--atlas-charts only works with atlases"),
    (["--lightmaps", "atlas", "--resolution", "64"],
     "--resolution does nothing with --lightmaps atlas (atlases are sized by --texel-density and --atlas-size): "
     "leave it out"),
])
def test_a_size_flag_that_does_nothing_is_refused_before_any_work(tmp_path, capsys, flags, message):
    code = main(["bake", str(tmp_path / "missing.blend"), "--out", str(tmp_path / "out"), *flags])
    assert code == 2 and message in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


@pytest.mark.blender
def test_faces_copied_by_a_modifier_are_named_before_the_bake_and_in_the_overlap_warning(bpy, scene):
    """An Array modifier's copies keep the mesh's UVs, so no packing can part them: said before the
    bake, and the overlap warning names the object, not the atlas."""
    from detp_bake import blender
    from detp_bake.estimators import EstimatorSettings
    from detp_bake.lightmap import texels
    from detp_bake.run.layout_warnings import layout_warnings
    from detp_bake.run.settings import BakeSettings
    bpy.ops.wm.open_mainfile(filepath=str(scene))
    array = bpy.data.objects["CrateA"].modifiers.new("Row", "ARRAY")
    array.relative_offset_displace = (0.0, 1.5, 0.0)
    said = []
    exported = blender.export_scene(bpy.context.scene, None, BAKED, None, 0, log=said.append,
                                    atlas=BakeSettings(lightmaps="atlas", texel_density=6.0, atlas_size=256))
    assert [m for m in said if "copy faces" in m] == [
        "atlas: the modifiers of 'CrateA' (Array) copy faces with their lightmap UVs, so the copies share texels "
        "(one light for all): apply the modifiers (Object › Apply) to give each copy texels of its own"]
    (lm,) = texels.rasterise(exported).lightmaps
    share = lm.placement["CrateA"]["overlap"]  # texel centres under two faces (edge texels are under one)
    assert share > 0.5
    assert all(p["overlap"] == 0.0 for n, p in lm.placement.items() if n != "CrateA")
    (warning,) = [w for w in layout_warnings(texels.rasterise(exported), EstimatorSettings()) if "two or more" in w]
    assert warning.startswith(f"objects 'CrateA' ({100 * share:.0f} %) in atlas 'atlas_0': their lightmap texels "
                              "lie under two or more faces")
