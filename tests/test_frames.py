"""Frame ranges without Blender: the range syntax, moving objects found from the evaluated arrays,
numbered lightmaps and a report per frame, a cancel that keeps the finished frames, and no flicker."""
import json

import numpy as np
import pytest

from detp_bake.run import frames
from detp_bake.run.bake import BakeSettings, compute
from detp_bake.errors import BakeError
from detp_bake.estimators import EstimatorSettings
from test_hybrid import CENTRES, scene_at


def test_frame_ranges_parse_and_bad_ones_are_named():
    assert frames.parse_frames("1-24").frames() == list(range(1, 25))
    assert frames.parse_frames("1-24:5").frames() == [1, 6, 11, 16, 21]
    assert frames.parse_frames(" 7 ").frames() == [7]
    assert frames.parse_frames("-5--3").frames() == [-5, -4, -3]
    for text, why in (("24-1", "comes before"), ("1-4:0", "step"), ("a-b", "A-B"), ("1-", "A-B")):
        with pytest.raises(BakeError, match=why):
            frames.parse_frames(text)


def test_moving_objects_are_found_from_the_evaluated_arrays():
    sigs = [frames.object_signatures(scene_at(f)) for f in range(3)]
    lights = [frames.lights_signature(scene_at(f)) for f in range(3)]
    m = frames.find_motion(sigs, lights)
    assert m.found == ["Ball"] and m.moving == ["Ball"] and not m.lights_change
    assert m.static == ["Plate", "Back", "Ground"]
    m = frames.find_motion(sigs, lights, moving=["Back"], static=["Ball"])
    assert m.moving == ["Back"] and "Ball" in m.static and "static by --static: Ball" in m.describe()
    one = scene_at(0)
    one.albedo[one.object_named("Plate").triangles] *= 0.5  # a material change moves it too
    assert frames.object_signatures(one)["Plate"] != sigs[0]["Plate"]
    with pytest.raises(BakeError, match="'Nope'"):
        frames.find_motion(sigs, lights, moving=["Nope"])
    with pytest.raises(BakeError, match="both moving and static"):
        frames.find_motion(sigs, lights, moving=["Ball"], static=["Ball"])


def _settings(**kw):
    kw.setdefault("estimator", "hybrid")
    kw.setdefault("seed", 3)
    return BakeSettings(photons=20_000, denoise=False, batch_size=7_000, resolution=24,
                        estimator_settings=EstimatorSettings(radius_texels=1.5), **kw)


def test_a_range_writes_numbered_lightmaps_and_a_report_per_frame(tmp_path):
    said, messages = [], []
    got = frames.bake_frames(lambda f: scene_at(f - 1), frames.parse_frames("1-3"), _settings(formats=("exr", "png")),
                             tmp_path, lambda p: messages.append(p.message), log=said.append)
    assert got.frames == [1, 2, 3] and not got.cancelled
    assert said == ["found moving over the range: Ball"]
    assert any(m.startswith("Frame 2/3 · Tracing") for m in messages)
    for f in (1, 2, 3):
        for obj in ("Plate", "Back", "Ball"):
            for ext in ("exr", "png"):
                assert (tmp_path / f"{obj}.hybrid.{f:04d}.{ext}").stat().st_size > 0
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["frames"]["done"] == [1, 2, 3] and report["frames"]["moving"] == ["Ball"]
    assert report["frames"]["sequences"]["Plate"] == ["Plate.hybrid.####.exr", "Plate.hybrid.####.png"]
    sections = report["per_frame"]
    assert [s["frame"] for s in sections] == [1, 2, 3]
    assert [s["estimator"]["index_reused"] for s in sections] == [False, True, True]
    for s in sections:
        assert s["photons"] == 20_000 and set(s["noise"]) == {"Plate", "Back", "Ball"}
        assert {"export", "trace", "estimate", "write"} <= set(s["seconds"])
    # Each frame is the bake of that frame alone (frame ranges estimate every texel: sites.py).
    alone = compute(scene_at(1), _settings(estimator="disc_index", indirect_spacing=1))
    from detp_bake.lightmap.images import read_image
    img = read_image(tmp_path / "Plate.hybrid.0002.exr")
    assert np.allclose(img[..., :3], alone.images["Plate"], rtol=1e-5, atol=1e-7)


def test_a_cancel_keeps_the_finished_frames_as_a_shorter_sequence(tmp_path):
    state = {"frame2": False}

    def progress(p):
        if p.message.startswith("Frame 2/3 · Tracing"):
            state["frame2"] = True

    got = frames.bake_frames(lambda f: scene_at(f - 1), frames.parse_frames("1-3"), _settings(), tmp_path, progress,
                             cancel=lambda: state["frame2"])
    assert got.cancelled and got.frames == [1]
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["frames"]["done"] == [1] and report["frames"]["cancelled"] is True
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["Back.hybrid.0001.exr", "Ball.hybrid.0001.exr", "Plate.hybrid.0001.exr", "report.json"]


def _near_segment(c, a, b, reach):
    """Whether the segments a[i] -> b stay within `reach` of point c."""
    ab = b - a
    t = np.clip(((c - a) * ab).sum(axis=1) / (ab * ab).sum(axis=1), 0.0, 1.0)
    return np.linalg.norm(a + t[:, None] * ab - c, axis=1) <= reach


@pytest.mark.parametrize("direct", ["photons", "sampled"])
def test_texels_no_changed_path_reaches_are_identical_between_frames(tmp_path, direct):
    """No flicker: with the same photons in every frame, a static texel that no path through the
    moving ball reaches keeps its bits (denoising off: OIDN sees the whole image). With no bounce
    those paths are the light's rays that pass the ball in either frame."""
    got = frames.bake_frames(lambda f: scene_at(f, bounces=0), frames.parse_frames("0-1"),
                             _settings(direct=direct), tmp_path)
    assert got.frames == [0, 1]
    from detp_bake.lightmap.images import read_image
    probe = compute(scene_at(0, bounces=0), _settings(direct=direct))  # texel positions and disc radii
    lamp = np.array([0.3, -0.4, 1.6])
    identical = checked = 0
    for lm in probe.texels.lightmaps[:2]:  # Plate and Back: static
        pos = probe.texels.position[lm.texels]
        reach = 0.3 + 2.0 * 1.5 * lm.texel_size
        touched = _near_segment(np.array(CENTRES[0]), pos, lamp, reach) | \
            _near_segment(np.array(CENTRES[1]), pos, lamp, reach)
        pixel = probe.texels.pixel[lm.texels]
        a, b = (read_image(tmp_path / f"{lm.name}.hybrid.{f:04d}.exr")[..., :3].reshape(-1, 3)[pixel] for f in (0, 1))
        same = (a == b).all(axis=1)
        assert same[~touched].all(), f"{lm.name}: {(~same[~touched]).sum()} untouched texels changed"
        assert not same[touched].all()  # the test can fail: the ball's shadow does move
        identical += int(same.sum())
        checked += len(same)
    assert identical > 0.5 * checked


def test_direct_light_is_resampled_only_where_a_mover_can_shadow(tmp_path):
    """A point light's shadow ray is one fixed ray per texel, so the direct light kept from the
    first frame or re-sampled near the ball must equal a fresh bake of each frame bit for bit;
    and most static texels are not re-sampled."""
    got = frames.bake_frames(lambda f: scene_at(f, bounces=0), frames.parse_frames("0-2"),
                             _settings(direct="sampled"), tmp_path)
    from detp_bake.lightmap.images import read_image
    sections = json.loads((tmp_path / "report.json").read_text())["per_frame"]
    for frame, section in zip(got.frames, sections):
        fresh = compute(scene_at(frame, bounces=0), _settings(direct="sampled"))
        d = section["direct"]
        assert d["reused_texels"] + d["resampled_texels"] == len(fresh.texels)
        # A big ball, three places, one lamp; shadow rays start anywhere on their texel (texel_area.py).
        assert d["reused_texels"] > 0.15 * len(fresh.texels)
        for lm in fresh.texels.lightmaps:
            img = read_image(tmp_path / f"{lm.name}.hybrid.{frame:04d}.exr")[..., :3]
            assert np.array_equal(img, fresh.images[lm.name].astype(np.float32)), (frame, lm.name)


def test_unchanged_frames_are_kept_and_force_bakes_them_again(tmp_path):
    """A second bake of the same range keeps every frame as it is (same bytes, not rewritten);
    a frame whose scene changed is baked again, and so is everything with force."""
    def scene(f, ball=0.8):
        sc = scene_at(f - 1)
        sc.albedo[sc.object_named("Ball").triangles] = ball
        return sc

    said = []
    first = frames.bake_frames(scene, frames.parse_frames("1-3"), _settings(), tmp_path)
    assert first.skipped == []
    files = sorted(tmp_path.glob("*.exr"))
    before = {p: (p.read_bytes(), p.stat().st_ino) for p in files}  # a rewrite renames a new file in
    again = frames.bake_frames(scene, frames.parse_frames("1-3"), _settings(), tmp_path, log=said.append)
    assert again.skipped == [1, 2, 3] and again.frames == [1, 2, 3]
    assert "kept 3 unchanged frames from the last bake (1-3)" in said[-1]
    assert {p: (p.read_bytes(), p.stat().st_ino) for p in files} == before
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["frames"]["kept"] == [1, 2, 3] and [s["kept"] for s in report["per_frame"]] == [True] * 3
    # The (moving) ball turns darker at frame 3: frame 3 is baked again, frames 1 and 2 kept.
    changed = frames.bake_frames(lambda f: scene(f, 0.3 if f == 3 else 0.8), frames.parse_frames("1-3"),
                                 _settings(), tmp_path)
    assert changed.skipped == [1, 2]
    assert (tmp_path / "Plate.hybrid.0003.exr").read_bytes() != before[tmp_path / "Plate.hybrid.0003.exr"][0]
    forced = frames.bake_frames(scene, frames.parse_frames("1-3"), _settings(), tmp_path, force=True)
    assert forced.skipped == []
    for p in files:  # baked again: the same bytes (deterministic), written anew
        assert p.read_bytes() == before[p][0] and p.stat().st_ino != before[p][1]
    other_seed = frames.bake_frames(scene, frames.parse_frames("1-2"), _settings(seed=4), tmp_path)
    assert other_seed.skipped == []


def test_a_range_as_a_job_has_one_progress_bar_whose_exports_run_on_the_callers_thread(tmp_path):
    """FramesJob (what the panel and the command line run): the overall progress only grows over
    the whole range (it does not restart each frame) and ends at 1; each frame's scene is made on
    the thread that serves the job's MainThread (bpy is not thread-safe), not on the worker."""
    import threading
    import time
    from detp_bake.run import job as job_mod

    main, made_on = job_mod.MainThread(), []

    def export(frame):
        made_on.append(threading.current_thread())
        return scene_at(frame - 1)

    job = job_mod.FramesJob(lambda f: main.call(export, f), frames.parse_frames("1-3"), _settings(), tmp_path)
    job.start()
    events = []
    while not job.done:
        main.serve()
        events += job.poll()
        time.sleep(0.01)
    events += job.poll()
    progress = [e for e in events if isinstance(e, job_mod.Status)]
    assert isinstance(events[-1], job_mod.Result) and events[-1].frames.frames == [1, 2, 3]
    # Frame k of 3 moves the bar within its third of the range, and the last ends it.
    for e in progress:
        k = int(e.message.split("/")[0].split()[-1]) - 1
        assert e.phase == "evaluate" and e.overall == 0.0 or k / 3 - 1e-9 <= e.overall <= (k + 1) / 3 + 1e-9, e
    assert progress[-1].overall == pytest.approx(1.0) and progress[-1].message.endswith("written")
    assert made_on and all(t is threading.current_thread() for t in made_on)
