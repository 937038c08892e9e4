# SPDX-License-Identifier: GPL-3.0-or-later
import numpy as np

from curved_reflections.engine.geometry.spd_solve import cholesky_factor, solve_spd


def _spd(rng, n, k, condition=1.0):
    a = rng.normal(size=(n, k, k))
    return a @ a.transpose(0, 2, 1) + condition * np.eye(k)


def test_the_factor_is_lower_triangular_and_reproduces_each_matrix():
    matrices = _spd(np.random.default_rng(0), 50, 6)
    lower = cholesky_factor(matrices)
    assert np.all(np.triu(lower, 1) == 0.0)
    np.testing.assert_allclose(lower @ lower.transpose(0, 2, 1), matrices, atol=1e-12)


def test_batched_solves_match_lapack_for_vectors_and_matrices_of_right_hand_sides():
    rng = np.random.default_rng(1)
    for k in (2, 3, 6):
        matrices = _spd(rng, 200, k, condition=1e-3)
        for rhs in (rng.normal(size=(200, k)), rng.normal(size=(200, k, 8))):
            got = solve_spd(matrices, rhs)
            want = np.linalg.solve(matrices, rhs if rhs.ndim == 3 else rhs[..., None])
            assert got.shape == rhs.shape
            np.testing.assert_allclose(got, want if rhs.ndim == 3 else want[..., 0], rtol=1e-8, atol=1e-9)


def test_a_singular_matrix_gets_a_finite_answer_that_solves_its_consistent_part():
    # Rank 1: [[1, 1], [1, 1]] x = [2, 2] is consistent; x must be finite and satisfy it.
    matrices = np.array([[[1.0, 1.0], [1.0, 1.0]], [[0.0, 0.0], [0.0, 0.0]]])
    x = solve_spd(matrices, np.array([[2.0, 2.0], [0.0, 0.0]]))
    assert np.all(np.isfinite(x))
    np.testing.assert_allclose(matrices[0] @ x[0], [2.0, 2.0], atol=1e-6)
    np.testing.assert_array_equal(x[1], [0.0, 0.0])
