"""Memory is known before work: a bake that cannot fit is refused with what to lower, batches are
bounded in segments, and report.json says the estimate and the peak."""
import numpy as np
import pytest

from detp_bake import memory
from detp_bake.bake import BakeSettings, compute
from detp_bake.errors import BakeError
from detp_bake.scene import PointLight, SunLight
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
    assert memory.segments_per_photon(1.0, 1000) == 1001
    r = compute(sc, BakeSettings(photons=5000, bounces=1000, denoise=False))
    assert r.memory["batch_photons"] == memory.MAX_BATCH_SEGMENTS // 1001
    assert r.stats.segments > 4_000_000  # it really did bounce that much
    # The estimate is of the right size: within a factor of two of the peak this process reached.
    assert r.memory["estimate_mb"] < 2000 and 0.5 < r.memory["estimate_mb"] / r.memory["peak_mb"] < 2.0
    report = r.report()
    assert report["memory"]["parts_mb"]["photon batches"] > 0
