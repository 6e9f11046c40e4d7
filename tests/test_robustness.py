"""The command line under stress: Ctrl+C and SIGTERM, a full disk, an older bake in the output
folder, compare's single report, honest stdout and the warnings for results that would silently be
wrong; each on a real scene (the bundled Cornell box or one built here with bpy)."""
import json
import os
import resource
import signal
import subprocess
import sys
import threading

import numpy as np
import pytest

from conftest import CORNELL, ROOT
from detp_bake.cli import main
import battery


def _files(folder):
    """Every file in `folder`, hidden ones included: {name: bytes}."""
    return {p.name: p.read_bytes() for p in folder.iterdir()} if folder.exists() else {}


# Loaded by the bake's own interpreter (site imports `sitecustomize` from PYTHONPATH): after its
# first staged file the write phase says so and waits until the signal has cancelled the bake's
# job, so the cancel lands while a file is being staged. The product has no hook of its own for it.
_HOLD_IN_WRITE = """
import sys, time
from detp_bake.lightmap import staging
from detp_bake.run import job

_stage, _init, _jobs = staging.FileSet.stage, job.Job.__init__, []

def init(self, *args, **kwargs):
    _init(self, *args, **kwargs)
    _jobs.append(self)

def stage(self, *args, **kwargs):
    out = _stage(self, *args, **kwargs)
    print("detp_bake: test: holding in write", file=sys.stderr, flush=True)
    end = time.monotonic() + 60.0
    while not any(j.cancelling for j in _jobs) and time.monotonic() < end:
        time.sleep(0.02)
    return out

job.Job.__init__, staging.FileSet.stage = init, stage
"""


def _start(args, tmp_path, hold_in_write=False, **env):
    path = str(ROOT)
    if hold_in_write:
        (tmp_path / "hook").mkdir()
        (tmp_path / "hook" / "sitecustomize.py").write_text(_HOLD_IN_WRITE)
        path = f"{tmp_path / 'hook'}{os.pathsep}{ROOT}"
    environ = dict(os.environ, PYTHONPATH=path, **env)
    if "NUMBA_CACHE_DIR" in environ:  # the subprocess runs elsewhere: keep the compiled cache
        environ["NUMBA_CACHE_DIR"] = os.path.abspath(environ["NUMBA_CACHE_DIR"])
    return subprocess.Popen([sys.executable, "-m", "detp_bake", *args], cwd=tmp_path, env=environ,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _older_bake(out):
    out.mkdir()
    (out / "Floor.texel_histogram.exr").write_bytes(b"an older bake")
    (out / "notes.txt").write_text("the user's")
    return _files(out)


@pytest.mark.blender  # bakes a .blend through the CLI
@pytest.mark.parametrize("sig, phase", [(signal.SIGINT, "trace"), (signal.SIGTERM, "trace"),
                                        (signal.SIGINT, "write")], ids=["sigint-trace", "sigterm-trace", "sigint-write"])
def test_a_signal_cancels_cleanly_while_tracing_or_writing(tmp_path, sig, phase):
    """One line, exit code 130, nothing on stdout, the folder exactly as it was (no hidden
    temporary file either). The write phase is reached by a hold the test loads into the bake
    (_HOLD_IN_WRITE): the bake waits after its first staged file, which the test sees on disk
    before it sends the signal, and goes on once the signal has set the cancel."""
    out = tmp_path / "out"
    before = _older_bake(out)
    photons = "100000000" if phase == "trace" else "5000"
    proc = _start(["bake", str(CORNELL), "--photons", photons, "--resolution", "16", "--out", str(out)],
                  tmp_path, hold_in_write=phase == "write")
    seen = battery.wait_for(proc, "Tracing" if phase == "trace" else "holding in write")
    if phase == "write":
        assert any(".partial." in name for name in _files(out))  # a file really was being staged
    proc.send_signal(sig)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, "".join(seen) + stderr
    assert stderr.strip() == "detp_bake: cancelled: nothing written"
    assert "Traceback" not in stderr and stdout == ""
    assert _files(out) == before


def test_a_full_disk_leaves_no_partial_file(tmp_path, empty_blend, bpy):
    """The file size limit (RLIMIT_FSIZE) makes every write past 512 bytes fail as a full disk would:
    the bake says which folder, and neither a 0-byte nor a half-written image is left."""
    from blender_helpers import export, plane_object
    from detp_bake.run import bake
    from detp_bake.errors import BakeError
    plane_object(bpy, "Floor", 2.0, (0, 0, 0))
    bpy.ops.object.light_add(type="POINT", location=(0.3, 0, 0.5))  # a gradient: no tiny constant image
    scene = export(bpy, resolution=32)
    result = bake.compute(scene, bake.BakeSettings(photons=2000, resolution=32, denoise=False))
    out = tmp_path / "out"
    before = _older_bake(out)
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    previous = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (512, hard))
    try:
        with pytest.raises(BakeError, match="cannot write") as err:
            bake.write(result, out)
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, previous)
    assert "Floor.texel_histogram" in str(err.value)  # the image being written when the disk filled
    assert _files(out) == before
    bake.write(result, out)  # with room again, the same result writes
    assert (out / "Floor.texel_histogram.exr").stat().st_size > 2048 and (out / "notes.txt").exists()


@pytest.mark.blender  # bakes a .blend through the CLI
def test_signal_handlers_are_restored_and_an_in_process_cancel_says_so(tmp_path, capsys):
    """`blender -c detp_bake` runs `main` inside Blender: a SIGINT during its bake cancels it, and
    afterwards Blender's own handlers are back."""
    before = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    timer = threading.Timer(4.0, os.kill, (os.getpid(), signal.SIGINT))
    timer.start()
    try:
        code = main(["bake", str(CORNELL), "--photons", "1000000000", "--resolution", "16",
                     "--out", str(tmp_path / "out")])
    finally:
        timer.cancel()
    assert code == 130 and "cancelled: nothing written" in capsys.readouterr().err
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == before
    assert _files(tmp_path / "out") == {}


@pytest.mark.blender  # bakes a .blend through the CLI
def test_compare_writes_one_report_with_a_section_per_estimator(tmp_path, capsys):
    out = tmp_path / "c"
    code = main(["compare", str(CORNELL), "--estimators", "photon_map", "disc_index", "--objects", "Floor",
                 "--photons", "20000", "--resolution", "16", "--out", str(out), "--json"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    report = json.loads((out / "report.json").read_text())
    assert set(report["estimators"]) == {"photon_map", "disc_index"}
    for name, section in report["estimators"].items():
        assert section["settings"]["estimator"] == name and section["estimator"]["name"] == name
        assert section["objects"][0]["files"] == [str(out / f"Floor.{name}.exr")]
    assert report["comparison"]["estimators"] == ["photon_map", "disc_index"]
    assert 0 < report["comparison"]["difference_to_first"]["disc_index"] < 1
    summary = json.loads(captured.out)  # --json: stdout is one JSON document
    assert summary["report"] == str(out / "report.json") and str(out / "compare.png") in summary["extra"]
    assert sorted(p.name for p in out.iterdir()) == ["Floor.disc_index.exr", "Floor.photon_map.exr",
                                                    "compare.json", "compare.png", "report.json"]


def _room(bpy, path, lightmap_uv=False):
    """A floor and a wall lit by a point light, saved as `path`; Lightmap UVs only if asked."""
    from blender_helpers import plane_object
    from detp_bake import blender
    bpy.ops.wm.read_factory_settings(use_empty=True)
    floor = plane_object(bpy, "Floor", 2.0, (0, 0, 0))
    wall = plane_object(bpy, "Wall", 2.0, (0, 1, 1), rotation=(np.pi / 2, 0, 0))
    bpy.ops.object.light_add(type="POINT", location=(0, 0, 1.5))
    bpy.context.active_object.data.energy = 100.0
    if lightmap_uv:
        for obj in (floor, wall):
            blender.ensure_lightmap_uv(obj, blender.DEFAULT_UV)
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


def test_stdout_holds_only_the_files_written_and_warnings_say_what_will_not_last(tmp_path, capfd, bpy):
    """Blender's "Read blend:" and Lightmap Pack's chatter (printed from C) go to stderr; a Lightmap
    UV layer created without --save, and --apply without --save, are said; a second bake replaces
    its own files, leaves the rest, and lists in one line the older PNGs it did not replace."""
    scene = _room(bpy, tmp_path / "room.blend")
    out = tmp_path / "out"
    common = ["bake", str(scene), "--photons", "20000", "--resolution", "16", "--out", str(out)]
    capfd.readouterr()
    assert main([*common, "--format", "exr,png"]) == 0
    first = capfd.readouterr()
    lines = first.out.splitlines()
    assert lines == [str(out / n) for n in ("Floor.texel_histogram.exr", "Floor.texel_histogram.png", "Wall.texel_histogram.exr",
                                           "Wall.texel_histogram.png", "report.json")]
    assert "Read blend" in first.err and "Read blend" not in first.out
    assert "warning: UV layer 'Lightmap' created on Floor, Wall is not stored anywhere (no --save)" in first.err
    png = (out / "Floor.texel_histogram.png").read_bytes()
    (out / "notes.txt").write_text("the user's")

    assert main([*common, "--format", "exr", "--apply"]) == 0
    second = capfd.readouterr()
    assert second.out.splitlines() == [str(out / n) for n in ("Floor.texel_histogram.exr", "Wall.texel_histogram.exr",
                                                              "report.json")]
    assert "warning: --apply without --save" in second.err and "nothing lasting happens" in second.err
    stale = [line for line in second.err.splitlines() if "older bake" in line]
    assert len(stale) == 1 and "Floor.texel_histogram.png, Wall.texel_histogram.png" in stale[0]
    assert (out / "Floor.texel_histogram.png").read_bytes() == png and (out / "notes.txt").exists()
    report = json.loads((out / "report.json").read_text())
    assert report["settings"]["formats"] == ["exr"] and any("older bake" in w for w in report["warnings"])


def test_save_pointing_at_a_folder_is_refused_before_work(tmp_path, capsys, bpy):
    scene = _room(bpy, tmp_path / "room.blend", lightmap_uv=True)
    folder = tmp_path / "saved"
    folder.mkdir()
    code = main(["bake", str(scene), "--out", str(tmp_path / "out"), "--apply", "--save", str(folder)])
    err = capsys.readouterr().err
    assert code == 2 and f"--save '{folder}' is a folder" in err and "Tracing" not in err
    assert _files(tmp_path / "out") == {} and _files(folder) == {}


@pytest.mark.parametrize("estimator", ["disc_index", "photon_map"])
def test_a_scene_10_km_from_the_origin_bakes_as_it_does_at_the_origin(tmp_path, bpy, estimator):
    """float32 rays, texels and discs work in coordinates relative to the scene's centre: the
    same room moved 10 km away reads within 0.5 % of the room at the origin, lightmap by lightmap."""
    from blender_helpers import export
    from detp_bake.run.bake import BakeSettings, compute
    _room(bpy, tmp_path / "room.blend", lightmap_uv=True)
    settings = BakeSettings(estimator=estimator, photons=60000, resolution=16, bounces=2, denoise=False)
    near = compute(export(bpy, resolution=16), settings)
    for obj in bpy.context.scene.objects:
        obj.location = (obj.location[0] + 10000.0, obj.location[1] - 10000.0, obj.location[2] + 500.0)
    bpy.context.view_layer.update()
    far_scene = export(bpy, resolution=16)
    assert far_scene.positions[:, :, 0].min() > 9990.0
    far = compute(far_scene, settings)
    for lm in near.texels.lightmaps:
        a, b = near.value[lm.texels].mean(), far.value[lm.texels].mean()
        assert abs(b / a - 1.0) < 0.005, (lm.name, a, b)
    # Texel positions are reported where the texels are, in world space.
    assert np.allclose(far.texels.position, near.texels.position + [10000.0, -10000.0, 500.0], atol=1e-3)


def _square_uvs(obj, size):
    """The plane's Lightmap layer set to cover [0, size]²."""
    layer = obj.data.uv_layers.get("Lightmap") or obj.data.uv_layers.new(name="Lightmap")
    corners = {(-1, -1): (0, 0), (1, -1): (size, 0), (1, 1): (size, size), (-1, 1): (0, size)}
    for loop in obj.data.loops:
        co = obj.data.vertices[loop.vertex_index].co
        layer.data[loop.index].uv = corners[(round(co.x), round(co.y))]


def test_overlapping_and_out_of_range_uvs_huge_discs_and_a_large_k_are_warned(tmp_path, capsys, bpy):
    """Array copies sharing one UV square (every texel under two faces), UVs over [0, 2]² (75 % of
    their area outside 0..1), discs of 1000 texels on a 2 m plane, and k over the photons stored:
    each a warning that names the object or setting and the share; the bake still writes."""
    from blender_helpers import plane_object
    bpy.ops.wm.read_factory_settings(use_empty=True)
    tiles = plane_object(bpy, "Tiles", 2.0, (0, 0, 0))
    _square_uvs(tiles, 1.0)
    array = tiles.modifiers.new("Array", "ARRAY")
    array.count = 2
    poster = plane_object(bpy, "Poster", 2.0, (0, 3, 1), rotation=(np.pi / 2, 0, 0))
    _square_uvs(poster, 2.0)
    bpy.ops.object.light_add(type="POINT", location=(1, 1, 2))
    path = tmp_path / "uvs.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    out = tmp_path / "out"
    code = main(["bake", str(path), "--photons", "20000", "--resolution", "16", "--estimator", "disc_index",
                 "--radius-texels", "1000", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 0, err
    warnings = [line for line in err.splitlines() if "warning:" in line]
    assert any("object 'Tiles': 100 % of its lightmap texels lie under two or more faces" in w for w in warnings)
    assert any("object 'Poster': 75.0 % of its lightmap UV area lies outside 0..1" in w for w in warnings)
    wide = [w for w in warnings if "setting 'radius_texels' = 1000" in w]
    assert len(wide) == 1 and "'Tiles'" in wide[0] and "'Poster'" in wide[0]
    assert not any("Poster" in w and "two or more faces" in w for w in warnings)
    report = json.loads((out / "report.json").read_text())
    assert len(report["warnings"]) == len(warnings)
    assert sorted(p.name for p in out.iterdir()) == ["Poster.disc_index.exr", "Tiles.disc_index.exr", "report.json"]

    code = main(["bake", str(path), "--estimator", "photon_map", "--photons", "300", "--k", "5000",
                 "--resolution", "16", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 0, err
    assert any("setting 'k' = 5000 is more than the" in line for line in err.splitlines() if "warning:" in line)
    assert "radius_texels" not in err  # the photon map has no discs
