"""Where a photon lands (transport/scattering.py): a photon that brings indirect light alone always
reflects from its first landing, its flux times the albedo; other landings go by Russian roulette.
Both keep the flux exact."""
import numpy as np

from detp_bake.scene import PointLight
from detp_bake.transport.photons import PhotonTracer
from detp_bake.transport.scattering import flights_per_photon
from synthetic import grid, make_scene


def _traced(bounces, indirect_only=True):
    """A lamp 1 m over a floor of albedo 0.5, 20 m wide, nothing else: what lands reflects up and out."""
    sc = make_scene([("Floor", grid(20.0, 20.0, 2), 0.5, True)],
                    [PointLight("Lamp", np.array([0.0, 0.0, 1.0]), np.full(3, 100.0))], resolution=8)
    tracer = PhotonTracer(sc, 100_000, bounces=bounces, seed=3, indirect_only=indirect_only)
    for _ in tracer.batches():
        pass
    return tracer.stats


def test_every_photon_is_reflected_from_its_first_landing():
    st = _traced(4)
    assert 0.45 * st.photons < st.photons_hit < 0.5 * st.photons  # the floor's half of the lamp's sphere
    # One flight more for every landing: none lost to the roulette (about half would be).
    assert st.rays == st.photons + st.photons_hit
    # Exact flux: half of what landed is absorbed, the other half leaves with the rest.
    landed = st.emitted * st.photons_hit / st.photons
    assert np.allclose(st.absorbed, 0.5 * landed, rtol=0.01)
    assert np.allclose(st.absorbed + st.escaped + st.truncated, st.emitted, rtol=1e-6)
    # Where the first landings are the direct light (--direct photons), the roulette decides there too.
    rr = _traced(4, indirect_only=False)
    assert abs((rr.rays - rr.photons) / rr.photons_hit - 0.5) < 0.02
    assert np.allclose(rr.absorbed + rr.escaped + rr.truncated, rr.emitted, rtol=0.02)


def test_the_expected_flights_count_the_first_reflection_as_certain():
    assert flights_per_photon(0.5, 0) == 1.0
    assert flights_per_photon(0.5, 3) == 1.0 + 1.0 + 0.5 + 0.25
    assert flights_per_photon(0.5, 3, first=1) == 1.75
    assert flights_per_photon(0.0, 3) == 1.0 and flights_per_photon(0.0, 3, first=1) == 0.0
    assert flights_per_photon(1.0, 9) == 10.0
    assert flights_per_photon(0.5, 3, certain=False) == 1.0 + 0.5 + 0.25 + 0.125
    assert flights_per_photon(0.5, 3, first=1, certain=False) == 0.875


def test_segments_are_counted_but_not_copied_when_no_estimator_reads_them():
    """The texel histogram and the photon map read the hits alone: the tracer then hands out
    batches without segments (PhotonTracer(segments=False)), the same hits and the same counts."""
    sc = make_scene([("Floor", grid(20.0, 20.0, 2), 0.5, True)],
                    [PointLight("Lamp", np.array([0.0, 0.0, 1.0]), np.full(3, 100.0))], resolution=8)
    runs = []
    for segments in (True, False):
        tracer = PhotonTracer(sc, 30_000, bounces=3, seed=4, batch_size=10_000, segments=segments)
        runs.append((tracer, [(b.segment_count, b.hit_position.copy(), b.hit_flux.copy()) for b in tracer.batches()]))
    (with_seg, a), (without, b) = runs
    assert with_seg.stats.segments == without.stats.segments > 30_000
    assert all(sa > 0 and sb == 0 for (sa, _, _), (sb, _, _) in zip(a, b))
    assert all(np.array_equal(pa, pb) and np.array_equal(fa, fb) for (_, pa, fa), (_, pb, fb) in zip(a, b))
