"""Bad input and bad luck, second battery (issue 35): every case runs the real command line
(`python -m detp_bake bake`, the bpy wheel, in its own process) on a .blend built here, and checks
the exit code, the message, that the output folder kept its files (names, times and bytes) when the
bake was refused or killed, and that the .blend was not touched. docs/troubleshooting.md says what
a user sees in each case."""
import hashlib
import json
import os
import shutil
import signal
import subprocess
import time

import numpy as np
import pytest

import battery
from battery import BAKE, snapshot

pytestmark = pytest.mark.blender


def _digest(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def room(bpy, tmp_path_factory):
    """One room .blend for every case, and an earlier bake of it (seed 1) to copy into a folder."""
    work = tmp_path_factory.mktemp("battery")
    blend = battery.room(bpy, work / "room.blend")
    earlier = work / "earlier"
    code, _, err = battery.run(["bake", str(blend), "--out", str(earlier), "--seed", "1", *BAKE], work)
    assert code == 0, err
    return {"blend": blend, "hash": _digest(blend), "earlier": earlier, "work": work}


def _folder_with_earlier_bake(room, out):
    """`out` holding the earlier bake's files (times kept) and a file of the user's."""
    shutil.copytree(room["earlier"], out, copy_function=shutil.copy2)
    (out / "notes.txt").write_text("the user's")
    return snapshot(out)


def _untouched(room):
    assert _digest(room["blend"]) == room["hash"], "the input .blend was modified"


# ---------------------------------------------------------------------------------------------
# SIGKILL in each phase, then a second bake into the same folder.

@pytest.mark.parametrize("phase", ["rasterise", "trace", "denoise", "write"])
def test_a_bake_killed_in_any_phase_leaves_the_folder_and_the_next_bake_succeeds(room, tmp_path, phase):
    """The bake is held in the phase by a hook the test loads into it (battery.HOOK) and killed
    there with SIGKILL (no handler runs): the earlier bake's files are as they were, and a second
    bake into the folder writes its files and leaves no temporary of the killed process."""
    out = tmp_path / "out"
    before = _folder_with_earlier_bake(room, out)
    args = ["bake", str(room["blend"]), "--out", str(out), "--seed", "2", *BAKE]
    if phase == "denoise":
        args.remove("--no-denoise")
    proc = battery.start(args, tmp_path, hook=tmp_path / "hook", DETP_TEST_HOLD=phase)
    battery.wait_for(proc, f"holding in {phase}")
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    left = snapshot(out)
    stale = [n for n in left if f".{proc.pid}.partial" in n]
    assert bool(stale) == (phase == "write"), left  # only the write phase had a file staged
    assert {n: v for n, v in left.items() if n not in stale} == before
    _untouched(room)

    code, stdout, err = battery.run([*args, "--no-denoise"] if phase == "denoise" else args, tmp_path)
    assert code == 0, err
    after = snapshot(out)
    for name in ("Floor.texel_histogram.exr", "Wall.texel_histogram.exr", "report.json"):
        assert after[name] != before[name] and str(out / name) in stdout.splitlines()
    assert after["notes.txt"] == before["notes.txt"]
    # The killed bake's temporaries are gone once another bake has run in the folder (branch
    # `defects`: a bake removes the .partial files of processes that no longer run).
    assert not [n for n in after if ".partial" in n], sorted(after)
    _untouched(room)


# ---------------------------------------------------------------------------------------------
# Two bakes into one folder at once.

def test_two_bakes_into_one_folder_at_once_leave_one_bakes_files(room, tmp_path):
    """Both bakes are held before their renames (battery.HOOK); A starts renaming first and slowly
    (0.4 s after each file), B 0.15 s later at full speed. Without one commit at a time the folder
    would end with B's first file beside A's others. Every file left must be the same bake's."""
    out = tmp_path / "out"
    go, copies = tmp_path / "go", tmp_path / "copies"
    common = ["bake", str(room["blend"]), "--out", str(out), *BAKE]
    env = dict(DETP_TEST_COMMIT_GO=str(go), DETP_TEST_COPY=str(copies))
    a = battery.start([*common, "--seed", "1"], tmp_path, hook=tmp_path / "hook", DETP_TEST_RENAME_DELAY="0.4", **env)
    b = battery.start([*common, "--seed", "2"], tmp_path, hook=tmp_path / "hook", DETP_TEST_COMMIT_AFTER="0.15", **env)
    battery.wait_for(a, "holding before commit")
    battery.wait_for(b, "holding before commit")
    go.write_text("")
    results = {p.pid: (p.communicate(timeout=120), p.returncode) for p in (a, b)}
    for pid, ((_, err), code) in results.items():
        assert code == 0, err
    final = {p.name: p.read_bytes() for p in out.iterdir()}
    assert sorted(final) == ["Floor.texel_histogram.exr", "Wall.texel_histogram.exr", "report.json"]
    owners = {name: [pid for pid in results if (copies / str(pid) / name).read_bytes() == data]
              for name, data in final.items()}
    assert all(len(o) == 1 for o in owners.values()), owners  # the two bakes' files differ
    assert len({o[0] for o in owners.values()}) == 1, f"files of two bakes mixed: {owners}"
    report = json.loads(final["report.json"])
    assert report["settings"]["seed"] == (1 if owners["report.json"][0] == a.pid else 2)
    _untouched(room)


# ---------------------------------------------------------------------------------------------
# A read-only output folder, a full disk.

def _mount(*args):
    return subprocess.run(["mount", *args], capture_output=True, text=True)


@pytest.fixture
def read_only(tmp_path):
    """A folder that cannot be written: a read-only bind mount of itself as root (chmod does not
    stop root), chmod 555 otherwise. Yields a function that makes `out` so."""
    made = []

    def make(out):
        if os.geteuid() != 0:
            out.chmod(0o555)
        else:
            bind = _mount("--bind", str(out), str(out))
            if bind.returncode != 0:
                pytest.skip(f"running as root and cannot bind-mount ({bind.stderr.strip()})")
            made.append(out)
            remount = _mount("-o", "remount,ro,bind", str(out))
            assert remount.returncode == 0, remount.stderr
    yield make
    for out in made:
        subprocess.run(["umount", str(out)], check=True)


def test_a_read_only_output_folder_is_refused_before_work(room, tmp_path, read_only):
    out = tmp_path / "out"
    before = _folder_with_earlier_bake(room, out)
    read_only(out)
    code, stdout, err = battery.run(["bake", str(room["blend"]), "--out", str(out), "--seed", "2", *BAKE], tmp_path)
    assert code == 2, err
    assert f"detp_bake: error: output directory '{out}' is not writable" in err
    assert "Tracing" not in err and "Traceback" not in err and stdout == ""
    assert snapshot(out) == before
    _untouched(room)


@pytest.fixture
def small_disk(tmp_path):
    """A 2 MB tmpfs (root only) filled to all but one page: the first small file fits, the next fails."""
    if os.geteuid() != 0:
        pytest.skip("a full disk needs a small tmpfs, and mounting one needs root")
    disk = tmp_path / "disk"
    disk.mkdir()
    made = _mount("-t", "tmpfs", "-o", "size=2m", "tmpfs", str(disk))
    if made.returncode != 0:
        pytest.skip(f"running as root and cannot mount a tmpfs ({made.stderr.strip()})")
    yield disk
    subprocess.run(["umount", str(disk)], check=True)


def _fill(disk, leave=4096):
    filler = disk / "filler"
    with open(filler, "wb") as f:
        try:
            f.write(b"\0" * (4 << 20))
        except OSError:
            pass
    size = filler.stat().st_size
    os.truncate(filler, size - leave)


def test_a_full_disk_fails_cleanly(room, tmp_path, small_disk):
    """The bake fails with exit code 2 and one line naming the file in the folder and the cause;
    the earlier bake's files are as they were and no temporary is left."""
    out = small_disk / "out"
    before = _folder_with_earlier_bake(room, out)
    _fill(small_disk)
    code, stdout, err = battery.run(["bake", str(room["blend"]), "--out", str(out), "--seed", "2", *BAKE], tmp_path)
    assert code == 2, err
    line = [x for x in err.splitlines() if "error:" in x]
    assert len(line) == 1 and f"cannot write '{out}/" in line[0] and "No space left on device" in line[0], err
    assert "Traceback" not in err and stdout == ""
    assert snapshot(out) == before
    _untouched(room)


# ---------------------------------------------------------------------------------------------
# A .blend from a newer Blender, linked library objects.

def _newer(blend, path):
    """A copy of `blend` whose header says it was written by Blender 9.99."""
    data = bytearray(blend.read_bytes())
    if data.startswith(b"BLENDER17-01v"):  # Blender 5's header: a four-digit version
        data[13:17] = b"0999"
    else:  # BLENDER-v405 (4.x): three digits
        assert data[:9] in (b"BLENDER-v", b"BLENDER_v"), bytes(data[:16])
        data[9:12] = b"999"
    path.write_bytes(bytes(data))
    return path


def test_a_blend_from_a_newer_blender_is_refused(bpy, room, tmp_path):
    battery.room(bpy, tmp_path / "plain.blend")
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "plain.blend"), compress=False)
    newer = _newer(tmp_path / "plain.blend", tmp_path / "newer.blend")
    digest = _digest(newer)
    out = tmp_path / "out"
    before = _folder_with_earlier_bake(room, out)
    code, stdout, err = battery.run(["bake", str(newer), "--out", str(out), *BAKE], tmp_path)
    assert code == 2, err
    assert f"scene file '{newer}' was saved by Blender 9.99" in err and "newer than this Blender" in err, err
    assert "Tracing" not in err and stdout == ""
    assert snapshot(out) == before and _digest(newer) == digest


def _linked_scene(bpy, tmp_path, with_uv):
    """A room that links the object 'Crate' from another .blend (with or without a Lightmap layer)."""
    from blender_helpers import plane_object
    from detp_bake import blender
    bpy.ops.wm.read_factory_settings(use_empty=True)
    crate = plane_object(bpy, "Crate", 1.0, (0, 0, 0.5))
    if with_uv:
        blender.ensure_lightmap_uv(crate, blender.DEFAULT_UV)
    library = tmp_path / "library.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(library))
    battery.room(bpy, tmp_path / "scene.blend")
    with bpy.data.libraries.load(str(library), link=True) as (_, linked):
        linked.objects = ["Crate"]
    bpy.context.scene.collection.objects.link(linked.objects[0])
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "scene.blend"))
    return tmp_path / "scene.blend", library


@pytest.mark.parametrize("with_uv", [True, False], ids=["with-lightmap-uv", "without"])
def test_linked_library_objects_bake_or_are_named(bpy, tmp_path, with_uv):
    """A linked object with its Lightmap UV layer bakes like any other; without it the layer cannot
    be made (linked data is read-only): refused before any work, naming the object and its library."""
    scene, library = _linked_scene(bpy, tmp_path, with_uv)
    digests = {p: _digest(p) for p in (scene, library)}
    out = tmp_path / "out"
    code, stdout, err = battery.run(["bake", str(scene), "--out", str(out), *BAKE], tmp_path)
    if with_uv:
        assert code == 0, err
        assert (out / "Crate.texel_histogram.exr").stat().st_size > 0
        report = json.loads((out / "report.json").read_text())
        assert sorted(o["name"] for o in report["objects"]) == ["Crate", "Floor", "Wall"]
    else:
        assert code == 2, err
        assert f"object 'Crate' is linked from '{library}'" in err and "UV layer 'Lightmap'" in err, err
        assert "Traceback" not in err and snapshot(out) == {}
    assert {p: _digest(p) for p in digests} == digests


# ---------------------------------------------------------------------------------------------
# Degenerate faces; a million triangles.

def test_degenerate_faces_bake_without_nan_and_are_said(bpy, tmp_path):
    """Quads collapsed to a point and to a line and one with a zero-length edge beside a good one:
    the bake writes finite lightmaps and one warning names the object and the triangles left out."""
    import OpenImageIO as oiio
    battery.room(bpy, tmp_path / "scene.blend")
    co = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],  # a good quad
                   [2, 0, 0], [2, 0, 0], [2, 0, 0], [2, 0, 0],  # collapsed to a point
                   [3, 0, 0], [4, 0, 0], [4, 0, 0], [3, 1, 0],  # a zero-length edge: one triangle left
                   [5, 0, 0], [6, 0, 0], [7, 0, 0], [5.5, 0, 0]], float) * 0.3 + [-1, -0.5, 0.3]  # a line
    uv = np.array([[0, 0], [.2, 0], [.2, .2], [0, .2], [.3, .3], [.3, .3], [.3, .3], [.3, .3],
                   [.5, 0], [.7, 0], [.7, 0], [.5, .2], [0, .5], [.2, .5], [.4, .5], [.1, .5]])
    battery.mesh_object(bpy, "Junk", co, np.arange(16).reshape(4, 4), uv=uv)
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "scene.blend"))
    out = tmp_path / "out"
    code, _, err = battery.run(["bake", str(tmp_path / "scene.blend"), "--out", str(out), *BAKE], tmp_path)
    assert code == 0, err
    for path in out.glob("*.exr"):
        pixels = oiio.ImageBuf(str(path)).get_pixels(oiio.FLOAT)
        assert np.isfinite(pixels).all(), path.name
    said = [line for line in err.splitlines() if "warning:" in line and "'Junk'" in line and "no area" in line]
    assert len(said) == 1 and "5 of its 8 triangles" in said[0], err
    report = json.loads((out / "report.json").read_text())
    assert any("'Junk'" in w and "no area" in w for w in report["warnings"])


def test_a_million_triangles_at_a_small_lightmap_stay_within_the_memory_estimate(bpy, room, tmp_path):
    """1,000,000 triangles (a 1000 × 500 grid of quads, built with foreach_set) at 16², 20k photons:
    the bake succeeds, and its process's peak resident memory, less that of a bake of the 4-triangle
    room (interpreter, Blender, kernels), stays under the bake's own estimate in report.json."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    battery.grid_mesh(bpy, "Dense", 1000, 500, size=4.0)
    bpy.ops.object.light_add(type="POINT", location=(0.3, 0, 1.5))
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "dense.blend"))
    args = ["--photons", "20000", "--resolution", "16", "--no-denoise"]
    code, _, err, base = battery.run_measured(["bake", str(room["blend"]), "--out", str(tmp_path / "small"), *args],
                                              tmp_path)
    assert code == 0, err
    t0 = time.perf_counter()
    code, _, err, peak = battery.run_measured(["bake", str(tmp_path / "dense.blend"), "--out", str(tmp_path / "out"),
                                               *args], tmp_path)
    seconds = time.perf_counter() - t0
    assert code == 0, err
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    estimate = report["memory"]["estimate_mb"] * 1e6
    print(f"1M triangles at 16²: {seconds:.1f} s, process peak {peak / 1e6:.0f} MB, the room's {base / 1e6:.0f} MB, "
          f"bake's estimate {estimate / 1e6:.0f} MB, report peak {report['memory']['peak_mb']:.0f} MB, "
          f"seconds {json.dumps({k: round(v, 2) for k, v in report['seconds'].items()})}")
    assert report["export"]["triangles"] == 1_000_000
    assert (tmp_path / "out" / "Dense.texel_histogram.exr").stat().st_size > 0
    assert peak - base < estimate, f"{(peak - base) / 1e6:.0f} MB used over the room's, {estimate / 1e6:.0f} MB estimated"


# ---------------------------------------------------------------------------------------------
# Big scenes, reduced (benchmarks/big_scenes.py runs them at 1,500 objects and 800 lights).

def test_many_objects_and_many_lights_bake_and_write_every_file(tmp_path):
    import sys
    env = dict(os.environ, PYTHONPATH=str(battery.ROOT))
    out = tmp_path / "big.json"
    proc = subprocess.run([sys.executable, str(battery.ROOT / "benchmarks" / "big_scenes.py"), "--objects", "150",
                           "--lights", "80", "--resolution", "8", "--photons", "20000", "--json", str(out)],
                          capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    rows = {r["case"]: r for r in json.loads(out.read_text())["rows"]}
    assert rows["level, one lightmap each"]["files"] == 151
    assert rows["level, atlases"]["files"] >= 1
    assert rows["room, point lights"]["files"] == 6
