"""Memory is known before work: a bake that cannot fit is refused with what to lower, batches are
bounded in segments, and report.json says the estimate and the peak."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from detp_bake.run import memory
from detp_bake.run.bake import BakeSettings, compute
from detp_bake.transport.scattering import flights_per_photon
from detp_bake.errors import BakeError
from detp_bake.scene import PointLight, SunLight
from conftest import ROOT
from synthetic import grid, make_scene, uv_sphere


def test_a_huge_lightmap_is_refused_before_work_naming_the_resolution():
    sc = make_scene([("Floor", grid(2.0, 2.0, 1), 0.5, True)],
                    [SunLight("Sun", np.array([0, 0, -1.0]), np.full(3, 1.0))], resolution=16384)
    with pytest.raises(BakeError, match=r"would need about .* GB .*resolution") as err:
        compute(sc, BakeSettings(photons=1000, resolution=16384, memory_budget_mb=4000))
    assert "texels" in str(err.value) or "lightmap" in str(err.value)


def test_the_photon_map_at_many_photons_is_told_to_stream():
    sc = make_scene([("Floor", grid(2.0, 2.0, 1), 0.5, True)],
                    [SunLight("Sun", np.array([0, 0, -1.0]), np.full(3, 1.0))], resolution=16)
    with pytest.raises(BakeError, match="DETP estimator"):
        compute(sc, BakeSettings(estimator="photon_map", photons=100_000_000, bounces=4, memory_budget_mb=2000))


def test_a_thousand_bounces_in_a_white_room_bound_the_batch_by_segments():
    """Albedo 1 and 1000 bounces: a photon makes about a thousand segments, so a batch holds a
    few thousand photons, not 100,000; the estimate stays near what the bake really used."""
    sc = make_scene([("Sphere", uv_sphere(1.0, 12, 24, inward=True), 1.0, True)],
                    [PointLight("Lamp", np.zeros(3), np.full(3, 10.0))], resolution=16)
    assert flights_per_photon(1.0, 1000) == 1001
    r = compute(sc, BakeSettings(photons=5000, bounces=1000, denoise=False))
    assert r.memory["batch_photons"] == memory.MAX_BATCH_SEGMENTS // 1001
    assert r.stats.segments > 4_000_000  # it really did bounce that much
    # The estimate is of the right size: within a factor of two of the peak this process reached.
    assert r.memory["estimate_mb"] < 2000 and 0.5 < r.memory["estimate_mb"] / r.memory["peak_mb"] < 2.0
    report = r.report()
    assert report["memory"]["parts_mb"]["photon batches"] > 0


def _bake_alone(resolution: int) -> dict:
    """A disc_index bake in a fresh process (its peak resident memory is its own), as
    benchmarks/memory.py makes them: a floor with a 5 % UV gutter, 5000 photons, no denoising."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "memory.py"), "--child", "disc_index",
                           str(resolution), "5000", "0", "0.05", "none", "0"], capture_output=True, text=True,
                          env=env, cwd=ROOT, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_the_estimate_per_texel_bounds_the_peak_a_bake_really_reaches():
    """Bytes per texel, estimated and measured, from a 32² and a 768² bake (0.48 M texels): the
    estimate must not be under the peak (a bake it lets through could run out of memory) nor
    more than 1.5 times it (a bake that fits would be refused). About 280 bytes a texel now."""
    _bake_alone(32)  # compiles what the kernel cache lacks: a compile's peak is not the bake's
    small, large = _bake_alone(32), _bake_alone(768)
    texels = large["texels"] - small["texels"]
    measured = (large["peak"] - small["peak"]) / texels
    estimated = (large["estimate_texels"] - small["estimate_texels"]) / texels
    assert measured < estimated < 1.5 * measured, (estimated, measured, large["phases"])
    assert measured < 400, measured  # before issue 10's cuts: about 500
