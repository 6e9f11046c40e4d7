"""The job every front end runs (detp_bake/run/job.py): its events for a bake, a cancel in each phase,
an error and a comparison; the lock; Stop and keep; the live preview against a bake without it.
No Blender: a plane under a point light, built as arrays."""
import json

import numpy as np
import pytest

from detp_bake.run import job as job_mod
from detp_bake.run.bake import BakeSettings
from detp_bake.estimators import EstimatorSettings
from detp_bake.scene import PointLight
from synthetic import grid, make_scene

PHOTONS, BATCH = 40_000, 5_000


def _scene():
    return make_scene([("Floor", grid(2.0, 2.0, 2), 0.5, True), ("Roof", grid(2.0, 2.0, 2, z=1.0, flip=True), 0.5, True)],
                      [PointLight("Lamp", np.array([0.0, 0.0, 0.5]), np.full(3, 50.0))], resolution=16, bounces=2)


def _settings(**kw):
    kw.setdefault("estimator", "disc_index")
    return BakeSettings(photons=PHOTONS, batch_size=BATCH, denoise=False,
                        estimator_settings=EstimatorSettings(radius=0.1), **kw)


def _kinds(events):
    return [type(e).__name__ for e in events]


def test_a_bake_tells_started_phases_progress_and_one_result(tmp_path):
    events = list(job_mod.Job(_scene(), _settings(), tmp_path).events())
    kinds = _kinds(events)
    assert kinds[0] == "Started" and kinds[-1] == "Result" and kinds.count("Result") == 1
    assert "Error" not in kinds and "Cancelled" not in kinds and "Preview" not in kinds
    phases = [e.phase for e in events if isinstance(e, job_mod.Phase)]
    assert phases == ["direct", "prepare", "trace", "estimate", "write"]
    progress = [e for e in events if isinstance(e, job_mod.Status)]
    overall = [p.overall for p in progress]
    assert overall == sorted(overall) and overall[-1] == 1.0  # the bar only moves forward
    traced = [p for p in progress if p.phase == "trace"]
    assert len(traced) == PHOTONS // BATCH and traced[-1].fraction == 1.0
    result = events[-1]
    assert result.report == tmp_path / "report.json"
    assert json.loads(result.report.read_text())["photons"] == PHOTONS
    assert job_mod.running() is None  # the lock is free again


@pytest.mark.parametrize("phase", ["direct", "prepare", "trace", "estimate", "write"])
def test_a_cancel_in_each_phase_ends_in_cancelled_and_writes_nothing(tmp_path, phase):
    job = job_mod.Job(_scene(), _settings(), tmp_path)
    hook = job._progress

    def cancel_in_phase(p):  # on the worker: the cancel lands in that very phase
        hook(p)
        if p.phase == phase:
            job.cancel()
    job._progress = cancel_in_phase
    events = list(job.events())
    assert isinstance(events[-1], job_mod.Cancelled) and events[-1].phase == phase
    assert "Result" not in _kinds(events) and list(tmp_path.iterdir()) == []


def test_bad_settings_end_in_one_error_naming_the_setting(tmp_path):
    events = list(job_mod.Job(_scene(), _settings(resolution=0), tmp_path).events())
    assert _kinds(events) == ["Started", "Error"]
    assert "resolution" in events[-1].message and not events[-1].unexpected


def test_a_comparison_feeds_the_same_photons_and_writes_one_report(tmp_path):
    names = ["photon_map", "disc_index"]
    events = list(job_mod.Job(_scene(), _settings(), tmp_path, names).events())
    assert events[0].kind == "compare" and events[0].estimators == names
    result = events[-1]
    assert isinstance(result, job_mod.Result) and set(result.results) == set(names)
    report = json.loads((tmp_path / "compare.json").read_text())
    assert report["reference"] == "photon_map" and list(report["sections"]) == names
    assert report["sections"]["photon_map"]["difference_to_reference"] == 0.0
    assert 0.0 < report["difference_to_first"]["disc_index"] < 1.0
    assert report["sections"]["disc_index"]["photons"] == report["photons"] == PHOTONS
    assert (tmp_path / "compare.png").stat().st_size > 0


def test_the_lock_refuses_a_second_job_while_one_runs(tmp_path):
    first = job_mod.Job(_scene(), _settings(), tmp_path / "a")
    release = __import__("threading").Event()
    hook = first._progress

    def held(p):
        hook(p)
        release.wait(30)  # keep the first job running until the second has been refused
    first._progress = held
    first.start()
    try:
        assert job_mod.running() is first and "bake is running" in job_mod.busy_message()
        with pytest.raises(job_mod.JobBusy, match="running"):
            job_mod.Job(_scene(), _settings(), tmp_path / "b").start()
    finally:
        release.set()
        first._progress = hook
    assert isinstance(first.run(), job_mod.Result)
    assert job_mod.running() is None
    assert isinstance(job_mod.Job(_scene(), _settings(), tmp_path / "b").run(), job_mod.Result)


def test_stop_and_keep_writes_a_whole_set_with_the_photons_traced(tmp_path):
    job = job_mod.Job(_scene(), _settings(), tmp_path)
    hook = job._progress

    def stop_after_three_batches(p):
        hook(p)
        if p.phase == "trace" and p.fraction >= 3 * BATCH / PHOTONS:
            job.stop()
    job._progress = stop_after_three_batches
    result = job.run()
    assert isinstance(result, job_mod.Result)
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["photons"] == 3 * BATCH and report["stopped_by"] == "user"
    files = [f for o in report["objects"] for f in o["files"]]
    assert len(files) == 2 and all((tmp_path / f).stat().st_size > 0 for f in map(str, files))
    # What is kept stands for the whole bake: about the mean of the full one (unbiased).
    full = job_mod.Job(_scene(), _settings(), None).run().results["disc_index"]
    kept = result.results["disc_index"]
    assert abs(kept.value.mean() / full.value.mean() - 1.0) < 0.1


def test_the_preview_refines_and_the_final_lightmaps_are_those_of_a_bake_without_it():
    events = list(job_mod.Job(_scene(), _settings(), None, preview=1e-9).events())
    previews = [e for e in events if isinstance(e, job_mod.Preview)]
    assert len(previews) == PHOTONS // BATCH  # one per batch at this interval
    assert [p.photons for p in previews] == [BATCH * (i + 1) for i in range(len(previews))]
    first, last = previews[0].images["Floor"], previews[-1].images["Floor"]
    assert first.shape == (16, 16, 3) and not np.array_equal(first, last)
    final = events[-1].results["disc_index"]
    plain = job_mod.Job(_scene(), _settings(), None).run().results["disc_index"]
    assert np.array_equal(final.value, plain.value)
    for name in plain.images:
        assert np.array_equal(final.images[name], plain.images[name])
    # The last preview is the finished bake before denoising.
    assert np.allclose(last, plain.images["Floor"], rtol=1e-5, atol=1e-7)


def test_the_photon_map_previews_its_gather_so_far_and_ends_as_a_bake_without_previews(monkeypatch):
    """Each preview gathers over the hits so far, scaled to the share traced: blurrier than the
    final lightmap but as bright. The last one is the final gather; previews leave it untouched."""
    settings = _settings(estimator="photon_map")
    monkeypatch.setattr(job_mod, "SLOW_PREVIEW_WAIT", 0.0)  # every batch, to see each one
    events = list(job_mod.Job(_scene(), settings, None, preview=1e-9).events())
    previews = [e for e in events if isinstance(e, job_mod.Preview)]
    assert [p.photons for p in previews] == [BATCH * (i + 1) for i in range(PHOTONS // BATCH)]
    assert all(p.estimator == "photon_map" for p in previews)
    first, last = previews[0].images["Floor"], previews[-1].images["Floor"]
    assert first.shape == (16, 16, 3) and not np.array_equal(first, last)
    assert abs(first.mean() / last.mean() - 1.0) < 0.1
    final = events[-1].results["photon_map"]
    plain = job_mod.Job(_scene(), settings, None).run().results["photon_map"]
    assert np.array_equal(final.value, plain.value)
    for name in plain.images:
        assert np.array_equal(final.images[name], plain.images[name])
        assert np.array_equal(previews[-1].images[name], plain.images[name].astype(np.float32))
    # At the real rate a preview waits SLOW_PREVIEW_WAIT times its own gather: here, for ever.
    monkeypatch.setattr(job_mod, "SLOW_PREVIEW_WAIT", 1e9)
    events = list(job_mod.Job(_scene(), settings, None, preview=1e-9).events())
    assert [e.photons for e in events if isinstance(e, job_mod.Preview)] == [BATCH]


def test_a_job_started_during_the_warm_up_waits_for_it_and_then_runs(tmp_path, monkeypatch):
    """The warm-up (every kernel compiled on a tiny scene) holds the lock without refusing jobs:
    a bake clicked meanwhile starts once it is done; a second warm-up does not start."""
    from detp_bake.run import warmup
    monkeypatch.setattr(warmup, "seconds", None)  # set when a warm-up's work is done, before it lets go
    assert warmup.start() is not None
    try:
        assert job_mod.warming() and job_mod.busy_message() is None  # the buttons stay live
        assert warmup.start() is None
        assert warmup.seconds is None, "the premise: the job is started while the warm-up still works"
        job = job_mod.Job(_scene(), _settings(), tmp_path).start()
        assert warmup.seconds is not None and warmup.seconds > 0.0  # start waited for the warm-up's end
        result = job.run()
    finally:
        warmup.wait()
    assert not warmup.running()
    assert isinstance(result, job_mod.Result) and job_mod.running() is None
