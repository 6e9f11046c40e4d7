"""Reuse from the command line: `bake --objects A B` then `--objects A B C` into the same folder
estimates only C, keeps A's and B's files, says so in one line and in report.json; --force and a
changed light bake everything."""
import json

from conftest import ROOT
from detp_bake.cli import main

QUASI_STATIC = ROOT / "sample_scenes" / "quasi_static.blend"
FAST = ["--photons", "30000", "--resolution", "16", "--no-denoise"]


def files(out):
    return {p.name: (p.stat().st_ino, p.read_bytes()) for p in sorted(out.glob("*.exr"))}


def test_a_bake_of_more_objects_reuses_the_others(tmp_path, capsys, bpy):
    out = tmp_path / "out"
    assert main(["bake", str(QUASI_STATIC), "--objects", "Floor", "Table", "--out", str(out), *FAST]) == 0
    assert "reused" not in capsys.readouterr().err
    before = files(out)
    assert sorted(before) == ["Floor.texel_histogram.exr", "Table.texel_histogram.exr"]

    code = main(["bake", str(QUASI_STATIC), "--objects", "Floor", "Table", "Mover", "--out", str(out), "--json", *FAST])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    said = [line for line in captured.err.splitlines() if "reused" in line]
    assert said == [f"detp_bake: reused 2 lightmaps unchanged since the last bake into {out}: Floor, Table "
                    "(--force bakes them again)"]
    summary = json.loads(captured.out)
    assert summary["reused"] == ["Floor", "Table"] and sorted(summary["files"]) == ["Floor", "Mover", "Table"]
    after = files(out)
    assert {n: after[n] for n in before} == before  # not rewritten: the same files, the same bytes
    report = json.loads((out / "report.json").read_text())
    assert report["reused"] == ["Floor", "Table"]
    assert {o["name"]: o["reused"] for o in report["objects"]} == {"Floor": True, "Table": True, "Mover": False}

    # The same three baked from nothing: byte-identical lightmaps.
    ref = tmp_path / "ref"
    assert main(["bake", str(QUASI_STATIC), "--objects", "Floor", "Table", "Mover", "--out", str(ref), *FAST]) == 0
    assert {n: b for n, (_, b) in files(ref).items()} == {n: b for n, (_, b) in after.items()}

    # --force bakes all three again.
    capsys.readouterr()
    assert main(["bake", str(QUASI_STATIC), "--objects", "Floor", "Table", "Mover", "--out", str(out), "--force",
                 *FAST]) == 0
    assert "reused" not in capsys.readouterr().err
    assert all(files(out)[n][0] != after[n][0] for n in after)
    assert json.loads((out / "report.json").read_text())["reused"] == []


def test_a_changed_light_rebakes_every_object(tmp_path, capsys, bpy):
    out = tmp_path / "out"
    assert main(["bake", str(QUASI_STATIC), "--objects", "Floor", "Table", "--out", str(out), *FAST]) == 0
    bpy.ops.wm.open_mainfile(filepath=str(QUASI_STATIC))
    scene = bpy.context.scene
    scene.objects["CeilingLight"].data.energy *= 1.01
    capsys.readouterr()
    assert main(["bake", "--objects", "Floor", "Table", "Mover", "--out", str(out), *FAST], bl_scene=scene) == 0
    assert "reused" not in capsys.readouterr().err
    assert json.loads((out / "report.json").read_text())["reused"] == []
