"""The command line: a real bake in a subprocess, and bad input refused before any work."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import CORNELL, ROOT
from detp_bake.cli import main


def _run_main(capsys, argv):
    code = main(argv)
    return code, capsys.readouterr().err


def test_python_m_detp_bake_bakes_applies_and_saves(tmp_path, bpy):
    out = tmp_path / "out"
    saved = tmp_path / "baked.blend"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, "-m", "detp_bake", "bake", str(CORNELL), "--objects", "Floor", "TallBox",
                           "--photons", "100000", "--resolution", "32", "--estimator", "photon_map",
                           "--out", "out", "--format", "exr,png",  # relative: resolved against the cwd
                           "--apply", "--save", "baked.blend"], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert "Tracing" in proc.stderr
    report = json.loads((out / "report.json").read_text())
    assert [o["name"] for o in report["objects"]] == ["Floor", "TallBox"]
    assert report["photons"] == 100_000 and report["segments"] >= report["hits"] > 0
    phases = set(report["seconds"])  # the report names every phase (no timing is checked)
    assert phases >= {"export", "trace", "estimate", "write"}
    assert report["settings"]["bounces"] == 4  # the scene's Cycles diffuse bounces
    assert report["export"]["evaluation"] == "render" and report["export"]["bytes_per_triangle"] > 0
    assert report["memory"]["estimate_mb"] > 0 and report["memory"]["peak_mb"] > 0
    assert report["direct"]["mode"] == "sampled" and set(report["noise"]) == {"Floor", "TallBox"}
    for name in ("Floor.photon_map.exr", "Floor.photon_map.png", "TallBox.photon_map.exr"):
        assert (out / name).stat().st_size > 0
    assert not list(out.glob(".*partial*"))
    # Opened from elsewhere, the saved file finds its lightmaps: paths are stored relative to it.
    os.chdir(ROOT)
    bpy.ops.wm.open_mainfile(filepath=str(saved))
    mat = bpy.data.objects["Floor"].material_slots[0].material
    assert "detp_bake lightmap" in mat.node_tree.nodes
    img = bpy.data.images["Floor.photon_map"]
    assert img.filepath.startswith("//out") and img.size[0] == 32


@pytest.mark.parametrize("extra, message", [
    (["--resolution", "0"], "resolution"),
    (["--photons", "5000000000"], "photons"),
    (["--photons", "-5"], "photons"),
    (["--estimator", "nope"], "estimator"),
    (["--k", "1"], "'k'"),
    (["--format", "tiff"], "formats"),
])
def test_bad_settings_are_named(capsys, tmp_path, extra, message):
    out = tmp_path / "out"
    code, err = _run_main(capsys, ["bake", str(CORNELL), "--out", str(out), *extra])
    assert code == 2 and message in err
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.blender
def test_unreadable_scene_path(capsys, tmp_path):
    code, err = _run_main(capsys, ["bake", str(tmp_path / "missing.blend"), "--out", str(tmp_path / "o")])
    assert code == 2 and "missing.blend" in err
    assert not any((tmp_path / "o").iterdir())


def test_unwritable_output_dir_is_refused_before_tracing(capsys, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    code, err = _run_main(capsys, ["bake", str(CORNELL), "--out", str(blocker / "out")])
    assert code == 2 and "not writable" in err and str(blocker / "out") in err
    assert "Tracing" not in err


@pytest.mark.blender
def test_missing_named_uv_layer_names_the_object(capsys, tmp_path):
    code, err = _run_main(capsys, ["bake", str(CORNELL), "--uv-layer", "Baked", "--out", str(tmp_path)])
    assert code == 2 and "has no UV layer 'Baked'" in err and "object '" in err
    assert not any(tmp_path.iterdir())


@pytest.mark.blender
def test_unknown_object_is_named(capsys, tmp_path):
    code, err = _run_main(capsys, ["bake", str(CORNELL), "--objects", "Teapot", "--out", str(tmp_path)])
    assert code == 2 and "'Teapot'" in err


def test_scene_without_lights(capsys, tmp_path, empty_blend, bpy):
    from blender_helpers import plane_object
    plane_object(bpy, "Lonely", 2.0, (0, 0, 0))
    path = tmp_path / "dark.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    out = tmp_path / "out"
    code, err = _run_main(capsys, ["bake", str(path), "--out", str(out)])
    assert code == 2 and "no light" in err
    assert "Tracing" not in err and not any(out.iterdir())


def test_missing_default_uv_layer_is_created_and_said(capsys, tmp_path, empty_blend, bpy):
    from blender_helpers import plane_object
    plane_object(bpy, "Floor", 2.0, (0, 0, 0))
    bpy.ops.object.light_add(type="SUN", location=(0, 0, 3))
    path = tmp_path / "no_uv.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    code, err = _run_main(capsys, ["bake", str(path), "--photons", "20000", "--resolution", "16",
                                   "--out", str(tmp_path / "out")])
    assert code == 0, err
    assert "created UV layer 'Lightmap'" in err and "Floor" in err
    assert (tmp_path / "out" / "Floor.texel_histogram.exr").exists()


def test_names_that_collide_as_file_names_get_distinct_files(tmp_path):
    """`Wall/1` and `Wall_1`, `Box` and `box` (case-insensitive disks), `..` and `...`, `CON`
    (Windows): every lightmap gets its own valid file, and report.json says which is whose."""
    from detp_bake.lightmap import images
    from detp_bake.run.bake import BakeSettings, bake
    from detp_bake.scene import SunLight
    from synthetic import grid, make_scene
    names = ["Wall/1", "Wall_1", "Box", "box", "..", "...", "CON"]
    parts = [(n, grid(1.0, 1.0, 1, z=0.1 * i), 0.5, True) for i, n in enumerate(names)]
    sc = make_scene(parts, [SunLight("Sun", np.array([0, 0, -1.0]), np.full(3, 1.0))], resolution=4)
    result = bake(sc, BakeSettings(photons=2000, bounces=0, denoise=False), tmp_path)
    stems = images.file_stems(names)
    assert len({s.lower() for s in stems.values()}) == len(names)
    assert stems["CON"] == "CON_"
    files = sorted(p.name for p in tmp_path.iterdir() if p.suffix == ".exr")
    assert len(files) == len(names)
    import json
    report = json.loads((tmp_path / "report.json").read_text())
    assert sorted(o["name"] for o in report["objects"]) == sorted(names)
    assert all(len(o["files"]) == 1 and Path(o["files"][0]).is_file() for o in report["objects"])
    assert result.files["Wall/1"] != result.files["Wall_1"]


@pytest.mark.parametrize("option, value", [("--radius-texels", "inf"), ("--radius", "nan"), ("--radius", "inf"),
                                           ("--target-noise", "nan"), ("--time-limit", "-1")])
def test_non_finite_settings_are_refused_before_work(tmp_path, option, value, capsys):
    from detp_bake import cli
    code = cli.main(["bake", str(CORNELL), "--out", str(tmp_path / "out"), option, value])
    assert code != 0
    err = capsys.readouterr().err
    assert option.lstrip("-").replace("-", "_") in err
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


@pytest.mark.parametrize("command", ["bake", "compare"])
def test_a_bake_is_checked_once_at_the_door(tmp_path, monkeypatch, bpy, command):
    """The settings of each estimator are validated once, the output folder proved writable once, and
    the automatic photon count worked out once, however many layers (command line, job, pipeline,
    writing) the bake passes through (run/door.py)."""
    from detp_bake.lightmap import images
    from detp_bake.run import door
    from detp_bake.run.settings import BakeSettings
    calls = {"validate": 0, "writable": 0, "photons": 0}

    def counted(key, real):
        def wrapper(*args, **kwargs):
            calls[key] += 1
            return real(*args, **kwargs)
        return wrapper
    monkeypatch.setattr(BakeSettings, "validate", counted("validate", BakeSettings.validate))
    monkeypatch.setattr(images, "check_writable_dir", counted("writable", images.check_writable_dir))
    monkeypatch.setattr(door, "auto_photons", counted("photons", door.auto_photons))
    names = ["texel_histogram"] if command == "bake" else ["texel_histogram", "photon_map"]
    extra = [] if command == "bake" else ["--estimators", *names]
    assert main([command, str(CORNELL), "--objects", "Floor", "--resolution", "16", "--no-denoise",
                 "--out", str(tmp_path / "out"), *extra]) == 0
    assert calls == {"validate": len(names), "writable": 1, "photons": 1}, calls
