"""Every benchmark script runs on a tiny configuration, so none of them can rot. Timings are not
checked here (they live in benchmarks/); the outputs' shape and sanity are."""
import json
import os
import subprocess
import sys

import pytest

from conftest import ROOT

BENCH = ROOT / "benchmarks"


def _run(script, *args, timeout=600):
    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg")
    proc = subprocess.run([sys.executable, str(BENCH / script), *args], capture_output=True, text=True,
                          env=env, cwd=ROOT, timeout=timeout)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc.stdout


def test_estimators_benchmark(tmp_path):
    out = tmp_path / "estimators.json"
    text = _run("estimators.py", "--quick", "--scenes", "dense", "--json", str(out))
    data = json.loads(out.read_text())["results"][0]
    assert "disc_index is" in text and data["segments"] > data["photons"]
    by = {(r["estimator"], r["radius_texels"]): r for r in data["radius_sweep"]}
    # Same photons, same rule: both accelerations find the same crossings at every radius.
    for (name, radius), row in by.items():
        assert row["crossings"] == by[("disc_index", radius)]["crossings"] > 0


@pytest.mark.blender  # its scenes are .blend files
def test_trace_benchmark(tmp_path):
    out = tmp_path / "trace.json"
    _run("trace.py", "--quick", "--json", str(out))
    rows = json.loads(out.read_text())
    rows = rows["results"] if isinstance(rows, dict) else rows
    assert rows and all(r["segments"] > 0 for r in rows)


@pytest.mark.blender  # its scenes are .blend files
def test_paper_benchmark(tmp_path):
    _run("paper.py", "--quick", "--scenes", "tree", "--out", str(tmp_path))
    data = json.loads((tmp_path / "paper.json").read_text())["results"]["tree"]
    assert {r["estimator"] for r in data["radius"]} == {"sphere_cache", "disc_index"}
    assert "fitted exponent" in (tmp_path / "paper.md").read_text()


@pytest.mark.blender  # its scenes are .blend files
def test_sites_benchmark(tmp_path):
    out = tmp_path / "sites.json"
    text = _run("sites.py", "--scene", "cornell_box", "--resolutions", "32", "--photons", "5000", "--seeds", "1",
                "--reference", "40000", "--json", str(out))
    doc = json.loads(out.read_text())
    assert [r["spacing"] for r in doc["rows"]] == [1, 2]
    every, two = doc["rows"]
    assert two["sites"] < every["sites"] == every["texels"] and 0 < every["rmse"] < 1 and 0 < two["rmse"] < 1
    assert len(doc["summary"]) == 1 and "time" in text


@pytest.mark.blender  # its scenes are .blend files
def test_lights_benchmark(tmp_path):
    out = tmp_path / "lights.json"
    text = _run("lights.py", "--scenes", "l_room", "--resolution", "16", "--samples", "4", "--reference", "32",
                "--json", str(out))
    doc = json.loads(out.read_text())
    assert [r["shared"] for r in doc["rows"]] == [False, True]
    plain, shared = doc["rows"]
    assert plain["shared_lights"] == 0 and shared["shared_lights"] == 2
    assert 0 < shared["rmse"] < 1 and 0 < plain["rmse"] < 1 and len(doc["summary"]) == 1 and "efficient" in text


@pytest.mark.blender  # its scenes are .blend files
def test_quality_benchmark(tmp_path):
    _run("quality.py", "--quick", "--scenes", "cornell_box", "--sweep-scene", "cornell_box",
         "--compositor-check", "--out", str(tmp_path))
    doc = json.loads((tmp_path / "quality.json").read_text())
    res = doc["results"][0]
    methods = {r["method"] for r in res["rows"]}
    assert {"cycles", "cycles+oidn", "texel_histogram", "texel_histogram/no-denoise", "disc_index",
            "disc_index/no-denoise", "disc_index/photons", "photon_map"} <= methods
    assert all(0 < r["rmse_measured"] < 2 and 0 <= r["rmse"] <= r["rmse_measured"] for r in res["rows"])
    assert set(res["reach"]) == methods and all(set(t) == {"5%", "3%"} for t in res["reach"].values())
    assert 0 < res["reference_noise"] < 1
    # The sweeps bake every radius and shadow-ray count, denoised and raw, at every photon count.
    sweep = doc["sweeps"][0]
    knobs = {(r["knob"], r["value"], r["denoised"]) for r in sweep["rows"]}
    assert len(knobs) == 2 * len(doc["config"]["radius_texels"] + doc["config"]["direct_samples"])
    # Blender's Denoise node runs the same OIDN filter as denoise_lightmap(filter="RT").
    assert doc["compositor_check"]["max_relative_difference"] < 0.01
    # The reference is cached: a second run does not bake it again.
    assert list((tmp_path / "cache").glob("cornell_box-*.npz"))


def test_disc_index_embree_benchmark(tmp_path):
    out = tmp_path / "embree.json"
    _run("disc_index_embree.py", "--quick", "--case", "room", "--repeat", "1", "--no-staggered",
         "--json", str(out))
    doc = json.loads(out.read_text())
    rows = {r["method"]: r for r in doc["rows"]}
    assert len(rows) == 3 and all(r["workload"] == "room" and r["crossings"] > 0 for r in rows.values())
    # The Embree query finds what the compiled index does (rule a) and nothing else: the same
    # irradiance to rounding, and crossings it loses are few.
    embree = next(r for m, r in rows.items() if m.startswith("embree"))
    assert embree["irradiance_max_diff_vs_rule_a"] < 1e-3
    assert doc["ratio_embree_over_ours"]["room"]["same_rule"] > 0


@pytest.mark.blender  # the level is built and unwrapped in Blender
def test_levels_benchmark(tmp_path):
    text = _run("levels.py", "--quick", "--out", str(tmp_path))
    data = json.loads((tmp_path / "levels.json").read_text())
    row = data["phases"][0]
    # What it measured, not what it was given: the texels baked, phases that add up to no more than the
    # bake's wall time, OIDN timed on its own.
    assert data["faces"] > 30_000 and row["texels"] > 0
    assert {"rasterise", "direct", "trace", "estimate", "denoise"} <= set(row["seconds"]) and row["oidn_alone"] > 0
    assert 0 < sum(row["seconds"][k] for k in ("rasterise", "direct", "trace", "estimate", "denoise")) <= row["wall"]
    assert row["charts"]["count"] > 500 and row["warned"]  # Smart UV Project at 64²: fragments, and said so
    methods = [r["method"] for r in data["race"]["rows"]]
    assert methods[0].startswith("ours") and methods[-1] == "Cycles 8 spp + OIDN"
    assert all(0 < r["error"] < 2 and r["seconds"] > 0 for r in data["race"]["rows"])
    assert "Race at 32²" in text


def test_the_docs_measured_figures_are_the_recorded_ones():
    """Every `<!-- measured … -->` block in README.md and docs/ is its rendering of
    benchmarks/measured/*.json (measured.py): a figure typed by hand, or a benchmark recorded
    without `measured.py --write`, fails here; and each renderer is used by some doc."""
    sys.path.insert(0, str(BENCH))
    import measured
    used = set()
    for path in measured.DOCS:
        for name, indent, body in measured.blocks(path.read_text()):
            used.add(name)
            assert body == measured.rendered(name, indent), \
                f"{path.name}: block '{name}' is not what benchmarks/measured/ holds (python benchmarks/measured.py --write)"
    assert used == set(measured.BLOCKS)
    # A block holds the figures: one changed in the record changes the text.
    data = measured.load("levels")
    data["phases"][0]["seconds"]["trace"] += 1.0
    assert measured.BLOCKS["levels.phases"][1](data) != measured.render("levels.phases")
