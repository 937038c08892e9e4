# SPDX-License-Identifier: GPL-3.0-or-later
import numpy as np

from curved_reflections.engine.geometry.vectors import cross, cross_rows, dot, dot_rows, lengths, normalized


def _vectors(n=50, seed=3):
    rng = np.random.default_rng(seed)
    return rng.normal(size=(n, 3)), rng.normal(size=(n, 3))


def test_row_operations_match_numpy():
    a, b = _vectors()
    np.testing.assert_allclose(dot(a, b), (a * b).sum(axis=1), rtol=1e-14)
    np.testing.assert_allclose(lengths(a), np.linalg.norm(a, axis=1), rtol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(normalized(a), axis=1), 1.0, rtol=1e-14)
    np.testing.assert_allclose(cross(a, b), np.cross(a, b), rtol=1e-14, atol=1e-15)
    assert np.all(normalized(np.zeros((2, 3))) == 0.0)


def test_cross_broadcasts_one_vector_against_rows():
    a, _ = _vectors()
    axis = np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(cross(a, axis), np.cross(a, axis), atol=1e-15)


def test_coordinate_rows_give_the_same_products_as_vector_rows():
    a, b = _vectors()
    np.testing.assert_allclose(np.stack(cross_rows(a.T, b.T), axis=1), np.cross(a, b), atol=1e-15)
    np.testing.assert_allclose(dot_rows(list(a.T), list(b.T)), (a * b).sum(axis=1), rtol=1e-14)
