"""Single-frame bakes into a folder that holds an earlier bake: an object's lightmap does not depend
on which other objects are baked with it (checked bit for bit, estimator by estimator), so the
objects whose inputs are unchanged keep their files and only the others are estimated."""
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from detp_bake.run import incremental, job as job_mod
from detp_bake.run.bake import BakeSettings, compute
from detp_bake.estimators import EstimatorSettings
from detp_bake.scene import AreaLight, PointLight, SunLight
from synthetic import grid, make_scene, uv_sphere

ALL = ("Plate", "Back", "Ball")


def scene(baked=ALL, sun=False, lamp=60.0, ball_resolution=24):
    plate = grid(2.0, 2.0, 3)
    back = grid(2.0, 1.2, 2, z=-1.0)  # a wall at y = 1 facing the plate
    back = (back[0][..., [0, 2, 1]] + [0.0, 2.0, 0.6], back[1][..., [0, 2, 1]] * [1, -1, 1], back[2])
    ground = grid(4.0, 4.0, 1, z=-0.3)  # never baked
    ball = uv_sphere(0.3, 8, 16)
    ball = (ball[0] + (0.5, 0.0, 0.7), ball[1], ball[2])
    panel = np.eye(4)
    panel[:3, 3] = (0.0, -0.3, 1.7)
    lights = [PointLight("Lamp", np.array([0.3, -0.4, 1.6]), np.full(3, lamp)),
              AreaLight("Panel", panel, "RECTANGLE", 0.5, 0.3, np.full(3, 40.0))]  # shadow rays with random offsets
    if sun:
        lights.append(SunLight("Sun", np.array([0.3, 0.2, -1.0]) / np.linalg.norm([0.3, 0.2, -1.0]), np.full(3, 2.0)))
    sc = make_scene([("Plate", plate, 0.6, "Plate" in baked), ("Back", back, 0.5, "Back" in baked),
                     ("Ball", ball, 0.8, "Ball" in baked), ("Ground", ground, 0.3, False)], lights, resolution=24,
                    bounces=2)
    sc.object_named("Ball").resolution = ball_resolution if "Ball" in baked else 0
    return sc


def settings(estimator="disc_index", **kw):
    kw.setdefault("denoise", False)
    return BakeSettings(estimator=estimator, photons=20_000, seed=3, batch_size=7_000,
                        estimator_settings=EstimatorSettings(radius_texels=1.5), **kw)


@pytest.mark.parametrize("estimator", incremental.PER_OBJECT)
@pytest.mark.parametrize("direct", ["photons", "sampled"])
def test_a_lightmap_does_not_depend_on_the_other_objects_baked(estimator, direct):
    """The premise of reuse: the same bits whichever objects are baked alongside, whether the
    others come before an object (its texels move in the set) or after it."""
    s = settings(estimator, direct=direct)
    full = compute(scene(), s).images
    for part in (("Back", "Ball"), ("Plate", "Back"), ("Ball",)):
        got = compute(scene(part), s).images
        assert sorted(got) == sorted(part)
        for name in part:
            assert np.array_equal(got[name], full[name]), (part, name)


def test_denoised_lightmaps_do_not_depend_on_the_other_objects_either():
    pytest.importorskip("pyoidn")
    s = settings(direct="sampled", denoise=True)
    full, part = compute(scene(), s), compute(scene(("Back", "Ball")), s)
    assert part.raw_images and np.array_equal(part.images["Ball"], full.images["Ball"])


def test_with_a_sun_the_widest_disc_of_the_whole_set_starts_the_photons():
    """Sun photons start the widest disc beyond the geometry: without the plate (the widest
    texels) they start nearer, so the others' lightmaps change; given the plate as `reach_of`,
    the bake of the rest is the full bake's, bit for bit."""
    s = settings(direct="photons")
    full = compute(scene(sun=True), s).images
    alone = compute(scene(("Back", "Ball"), sun=True), s).images
    assert not np.array_equal(alone["Ball"], full["Ball"])
    joined = compute(scene(("Back", "Ball"), sun=True), s, reach_of=["Plate"]).images
    for name in ("Back", "Ball"):
        assert np.array_equal(joined[name], full[name])


def bake(sc, out, reuse=True, **kw):
    s = kw.pop("settings", None) or settings(direct="sampled", formats=("exr", "png"))
    got = job_mod.Job(sc, s, out, reuse=reuse, **kw).run()
    assert isinstance(got, job_mod.Result), got
    return got


def files_of(out):
    return {p.name: (p.stat().st_ino, p.read_bytes()) for p in sorted(out.iterdir()) if p.name != "report.json"}


def test_a_bake_of_more_objects_estimates_only_the_new_ones(tmp_path):
    out, ref = tmp_path / "out", tmp_path / "ref"
    first = bake(scene(("Plate", "Back")), out)
    assert first.reused == {} and sorted(first.results["disc_index"].images) == ["Back", "Plate"]
    before = files_of(out)
    second = bake(scene(), out)
    # Only the ball was estimated; the plate's and the wall's files were not touched.
    assert sorted(second.results["disc_index"].images) == ["Ball"]
    assert sorted(second.reused) == ["Back", "Plate"]
    after = files_of(out)
    assert all(after[name] == before[name] for name in before)
    report = json.loads((out / "report.json").read_text())
    assert report["reused"] == ["Plate", "Back"]
    entries = {o["name"]: o for o in report["objects"]}
    assert [entries[n]["reused"] for n in ALL] == [True, True, False]
    assert all(os.path.isfile(f) for o in entries.values() for f in o["files"]) and len(entries["Ball"]["key"]) == 32
    # A full bake from nothing writes the very same bytes, the ball's included.
    bake(scene(), ref)
    assert {n: b for n, (_, b) in files_of(ref).items()} == {n: b for n, (_, b) in after.items()}

    # Nothing changed: nothing is estimated, and report.json says all three were reused.
    third = bake(scene(), out)
    assert third.results == {} and sorted(third.reused) == sorted(ALL)
    assert files_of(out) == after
    assert json.loads((out / "report.json").read_text())["reused"] == list(ALL)
    # --force bakes everything again (new files, the same bytes).
    forced = bake(scene(), out, force=True)
    assert forced.reused == {} and sorted(forced.results["disc_index"].images) == sorted(ALL)
    again = files_of(out)
    assert all(again[n][0] != after[n][0] and again[n][1] == after[n][1] for n in after)
    assert json.loads((out / "report.json").read_text())["reused"] == []


@pytest.mark.parametrize("change", ["light", "photons", "seed", "resolution", "estimator", "geometry"])
def test_a_changed_input_estimates_every_object_it_reaches(tmp_path, change):
    out = tmp_path / "out"
    bake(scene(), out)
    sc, s = scene(), settings(direct="sampled", formats=("exr", "png"))
    if change == "light":
        sc = scene(lamp=61.0)
    elif change == "photons":
        s.photons += 1
    elif change == "seed":
        s.seed += 1
    elif change == "resolution":  # only the ball's own lightmap changes
        sc = scene(ball_resolution=20)
    elif change == "estimator":
        s.estimator = "detp"
    else:  # the ground, never baked, moves: its shadows and bounces reach every lightmap
        sc.positions[sc.object_named("Ground").triangles] += [0.0, 0.0, -0.01]
    got = bake(sc, out, settings=s)
    expected = ["Ball"] if change == "resolution" else sorted(ALL)
    assert sorted(got.results[s.estimator].images) == expected
    assert sorted(got.reused) == sorted(set(ALL) - set(expected))


def test_what_cannot_be_reused_is_baked_whole(tmp_path):
    """The sphere cache, a noise target and a time limit make lightmaps that depend on the rest."""
    out = tmp_path / "out"
    for s in (settings("sphere_cache"), settings(target_noise=50.0)):
        bake(scene(("Plate", "Back")), out, settings=s)
        got = bake(scene(), out, settings=s)
        assert got.reused == {} and len(got.results[s.estimator].images) == 3
        assert "reused" not in json.loads((out / "report.json").read_text())
    # Without `reuse` (the operators, `compare`), a bake is always whole.
    bake(scene(), out)
    assert bake(scene(), out, reuse=False).reused == {}


def test_objects_left_out_of_a_bake_are_remembered_for_the_next(tmp_path):
    out = tmp_path / "out"
    bake(scene(), out)
    bake(scene(("Ball",)), out, force=True)  # the plate's and the wall's files stay, and so do their keys
    report = json.loads((out / "report.json").read_text())
    assert sorted(e["name"] for e in report["earlier_objects"]) == ["Back", "Plate"]
    got = bake(scene(), out)
    assert got.results == {} and sorted(got.reused) == sorted(ALL)
    # A copy of the folder reuses its own files, not those where report.json was written.
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    got = bake(scene(), copy)
    assert sorted(got.reused) == sorted(ALL)
    assert all(Path(f).parent == copy.resolve() for files in got.reused.values() for f in files)
