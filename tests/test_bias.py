"""The two biases DETP was made to remove (docs/design.md, Estimators): darkened edges and light picked up from a
neighbouring surface. Both estimators see the same photons (same seed and count)."""
import numpy as np

from detp_bake.run.bake import BakeSettings, compute
from detp_bake.estimators import EstimatorSettings
from detp_bake.scene import SunLight
from synthetic import grid, make_scene

SUN = 3.0


def _sun_scene(parts, res=32):
    return make_scene(parts, [SunLight("Sun", np.array([0.0, 0.0, -1.0]), np.full(3, SUN))],
                      albedo=0.0, resolution=res)


def test_plate_edges_stay_lit_for_detp_and_halve_for_the_photon_map():
    sc = _sun_scene([("Plate", grid(2.0, 2.0, 4), None, True)])
    # k = 1000 of 200k photons: r_k ≈ 4 texels, so an edge texel's neighbourhood hangs half off the plate.
    common = dict(photons=200_000, bounces=0, direct="photons")
    detp = compute(sc, BakeSettings(estimator="disc_index", **common))
    pmap = compute(sc, BakeSettings(estimator="photon_map", estimator_settings=EstimatorSettings(k=1000), **common))
    i, j = detp.texels.pixel % 32, detp.texels.pixel // 32
    edge = ((i == 0) | (i == 31) | (j == 0) | (j == 31)) & ~(((i == 0) | (i == 31)) & ((j == 0) | (j == 31)))
    interior = (i > 6) & (i < 25) & (j > 6) & (j < 25)
    ratio = lambda r: r.value[edge, 0].mean() / r.value[interior, 0].mean()
    assert abs(ratio(detp) - 1.0) < 0.05
    assert 0.4 < ratio(pmap) < 0.75  # about half: the texel centre sits half a texel inside the edge
    assert abs(detp.value[interior, 0].mean() / (SUN / np.pi) - 1) < 0.02


def test_detp_does_not_pick_up_light_from_a_shelf_just_above():
    """A floor with a sunlit shelf 4 cm above it: the floor under the shelf is in full shadow
    (E = 0). The photon map borrows the shelf's photons (same normal, same direction, a few cm
    away); DETP counts only segments crossing the floor's own discs, so it stays exactly dark."""
    floor = grid(2.0, 2.0, 4)
    shelf = grid(1.0, 1.0, 2, z=0.04)
    sc = _sun_scene([("Floor", floor, None, True), ("Shelf", shelf, None, False)])
    common = dict(photons=200_000, bounces=0, direct="photons")
    detp = compute(sc, BakeSettings(estimator="disc_index", **common))
    pmap = compute(sc, BakeSettings(estimator="photon_map", estimator_settings=EstimatorSettings(k=200), **common))
    x = detp.texels.position
    under = (np.abs(x[:, 0]) < 0.35) & (np.abs(x[:, 1]) < 0.35)
    open_floor = (np.abs(x[:, 0]) > 0.7) | (np.abs(x[:, 1]) > 0.7)
    lit = SUN / np.pi
    assert np.all(detp.value[under] == 0.0)
    assert pmap.value[under, 0].mean() > 0.2 * lit  # the photon map leaks light under the shelf
    assert abs(detp.value[open_floor, 0].mean() / lit - 1) < 0.05
