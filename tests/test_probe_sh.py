"""The probes' SH L2 convention against closed forms, and the probe file read back as written."""
import numpy as np

from detp_bake.probes import grid, sh9


def _sphere(n, seed=1):
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1)[:, None]


def test_uniform_radiance_reads_the_same_irradiance_for_every_normal():
    c = sh9.uniform([0.5, 1.0, 2.0])
    normals = _sphere(50)
    np.testing.assert_allclose(sh9.irradiance(c, normals), np.tile([0.5, 1.0, 2.0], (50, 1)), rtol=1e-12)


def test_projection_is_orthonormal_over_the_sphere():
    # Monte Carlo over uniform directions: ∫ Y_j Y_k dω = δ_jk.
    d = _sphere(400_000)
    y = sh9.basis(d)
    gram = y.T @ y * (4.0 * np.pi / len(d))
    np.testing.assert_allclose(gram, np.eye(9), atol=0.02)


def test_clamped_cosine_lobe_band_by_band():
    # Light from one direction d: E(n) against the clamped cosine truncated to band 2,
    # Σ_l A_l (2l+1)/(4π) P_l(cos θ) with A = π, 2π/3, π/4 and θ the angle between n and d.
    d = np.array([0.0, 0.6, 0.8])
    c = sh9.project(d[None], np.ones((1, 3)))
    cos = np.linspace(-1.0, 1.0, 21)
    n = cos[:, None] * d + np.sqrt(1 - cos ** 2)[:, None] * np.array([1.0, 0.0, 0.0])
    truth = (1.0 + 2.0 * cos + 1.25 * 0.5 * (3 * cos ** 2 - 1)) / 4.0
    np.testing.assert_allclose(sh9.irradiance(c, n)[:, 0] * np.pi, truth, atol=1e-12)
    assert abs(sh9.irradiance(c, d)[0] * np.pi - 1.0625) < 1e-12


def test_a_sparse_grid_is_saved_and_read_back(tmp_path):
    matrix = np.array([[2.0, 0, 0, 1], [0, 1, 0, 0], [0, 0, 0.5, 3], [0, 0, 0, 1]])
    dense = grid.ProbeGrid.full("Volume", matrix, (4, 3, 2))
    np.testing.assert_allclose(dense.positions[0], [1 - 2 + 0.5, -1 + 1 / 3, 3 - 0.25])
    assert sorted(dense.linear_index) == list(range(24))
    keep = np.arange(24) % 3 == 0
    sparse = grid.ProbeGrid("auto", matrix, (4, 3, 2), dense.index[keep], shadowmask_lights=("Sun",))
    sparse.coefficients[:] = np.arange(8 * 27, dtype=np.float32).reshape(8, 9, 3)
    sparse.valid[2] = False
    grid.save([dense, sparse], tmp_path / grid.FILE_NAME)
    back = grid.load(tmp_path / grid.FILE_NAME)
    assert [g.name for g in back] == ["Volume", "auto"]
    np.testing.assert_array_equal(back[1].coefficients, sparse.coefficients)
    np.testing.assert_array_equal(back[1].valid, sparse.valid)
    assert back[1].shadowmask_lights == ("Sun",) and back[1].occlusion.shape == (8, 1)
    np.testing.assert_allclose(back[1].positions, dense.positions[keep])
