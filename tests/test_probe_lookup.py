"""Reading probes where something moves (probes/lookup.py): trilinear blend between valid probes
against numbers worked by hand, the dense fill, the 3D-texture packing and the SH rotation."""
import numpy as np

from detp_bake.probes import grid, lookup, sh9

# A 2 x 2 x 2 grid over the box [0, 4] x [0, 2] x [0, 2]: probes at x 1 and 3, y and z 0.5 and 1.5.
MATRIX = np.array([[2.0, 0, 0, 2], [0, 1, 0, 1], [0, 0, 1, 1], [0, 0, 0, 1]])


def _grid():
    g = grid.ProbeGrid.full("box", MATRIX, (2, 2, 2))
    # probe p holds uniform radiance p + 1 (p = x + 2y + 4z), so its SH reads E/π = p + 1 everywhere
    g.coefficients[:] = np.stack([sh9.uniform([p + 1.0] * 3) for p in range(8)])
    return g


def _value(c):
    return sh9.irradiance(c, np.array([0.0, 0.0, 1.0]))[..., 0]


def test_trilinear_between_probes_by_hand():
    g = _grid()
    np.testing.assert_allclose(g.positions[[0, 7]], [[1, 0.5, 0.5], [3, 1.5, 1.5]])
    # (1.5, 0.75, 1.25): fractions x 0.25, y 0.25, z 0.75; the blend of p + 1 is
    # 1 + 1·0.25 + 2·0.25 + 4·0.75 = 4.75
    np.testing.assert_allclose(_value(lookup.at([g], [1.5, 0.75, 1.25])), [4.75], rtol=1e-6)
    # outside the box: clamped to its nearest probes (x beyond 3, y, z at 0.5) → probe 1 → 2
    np.testing.assert_allclose(_value(lookup.at([g], [9.0, -3.0, 0.0])), [2.0], rtol=1e-6)


def test_invalid_probes_are_left_out_and_the_weights_renormalised():
    g = _grid()
    g.valid[[1, 3, 5, 7]] = False  # the x = 3 side
    # at x = 2 (fraction 0.5) only the x = 1 probes count: y 0.25, z 0.75 over p 0, 2, 4, 6:
    # 1 + 2·0.25 + 4·0.75 = 4.5
    np.testing.assert_allclose(_value(lookup.at([g], [2.0, 0.75, 1.25])), [4.5], rtol=1e-6)
    g.valid[:] = False
    g.valid[6] = True  # only one valid probe: every point reads it
    np.testing.assert_allclose(_value(lookup.at([g], [[3.0, 0.5, 0.5], [1.0, 1.5, 1.5]])), [7.0, 7.0])


def test_the_smallest_grid_holding_a_point_wins():
    big, small = _grid(), grid.ProbeGrid.full("small", np.diag([0.5, 0.5, 0.5, 1.0]), (1, 1, 1))
    small.matrix[:3, 3] = [1.0, 1.0, 1.0]
    small.coefficients[0] = sh9.uniform([100.0] * 3)
    np.testing.assert_allclose(_value(lookup.at([big, small], [[1.2, 1.1, 0.9], [3.0, 1.0, 1.0]])),
                               [100.0, 5.0], rtol=1e-6)


def test_dense_fill_and_texture_layout():
    g = grid.ProbeGrid.full("row", np.diag([4.0, 1.0, 1.0, 1.0]), (4, 1, 1))
    g.coefficients[:] = np.stack([sh9.uniform([v] * 3) for v in (1.0, 2.0, 3.0, 4.0)])
    g.valid[[1, 3]] = False
    values, validity = lookup.dense(g)
    # cell 1 takes the mean of cells 0 and 2; cell 3 the value of cell 2
    np.testing.assert_allclose(_value(values[0, 0]), [1.0, 2.0, 3.0, 3.0], rtol=1e-6)
    np.testing.assert_array_equal(validity[0, 0], [1, 0, 1, 0])
    tex = lookup.textures(g)
    assert tex.shape == (7, 1, 1, 4, 4) and tex.dtype == np.float16
    flat = tex[:, 0, 0].transpose(1, 0, 2).reshape(4, 28)  # per cell, numbers 0..27
    np.testing.assert_allclose(flat[:, :27].reshape(4, 9, 3), values[0, 0], rtol=1e-3)
    np.testing.assert_array_equal(flat[:, 27], [1, 0, 1, 0])


def test_rotated_sh_follows_the_light():
    d = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    c = sh9.project(d[None], np.array([[1.0, 2.0, 3.0]]))
    blender_to_gltf = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])  # (x, y, z) -> (x, z, −y)
    turned = lookup.rotated(c, blender_to_gltf)
    np.testing.assert_allclose(turned, sh9.project((blender_to_gltf @ d)[None], np.array([[1.0, 2.0, 3.0]])),
                               atol=1e-12)
