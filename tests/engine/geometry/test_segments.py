# SPDX-License-Identifier: GPL-3.0-or-later
import numpy as np
import pytest

from curved_reflections.engine.geometry.segments import (ranks_in_runs, segment_max, segment_mean, segment_min,
                                                         segment_sum, solve_least_squares)


def test_segment_reductions_match_per_node_loops():
    rng = np.random.default_rng(0)
    node = rng.integers(0, 5, 200)
    values = rng.normal(size=(200, 3))
    for reduce, expected in ((segment_sum, np.sum), (segment_max, np.max), (segment_min, np.min), (segment_mean, np.mean)):
        got = reduce(values, node, 5)
        want = np.stack([expected(values[node == k], axis=0) for k in range(5)])
        np.testing.assert_allclose(got, want, atol=1e-12)


def test_per_node_least_squares_recovers_each_nodes_line():
    x = np.tile(np.linspace(-1, 1, 10), 2)
    node = np.repeat([0, 1], 10)
    y = np.where(node == 0, 2 + 3 * x, -1 + 0.5 * x)
    design = np.stack([np.ones_like(x), x], axis=1)
    coefficients = solve_least_squares(design, y[:, None], node, 2)
    np.testing.assert_allclose(coefficients[:, :, 0], [[2, 3], [-1, 0.5]], atol=1e-8)


def test_a_node_without_members_is_an_error():
    with pytest.raises(ValueError, match="at least one member"):
        segment_sum(np.ones((3, 1)), np.array([0, 0, 2]), 3)


def test_ranks_in_runs_count_each_entry_s_place_among_its_equals():
    np.testing.assert_array_equal(ranks_in_runs(np.array([3, 3, 3, 5, 7, 7])), [0, 1, 2, 0, 0, 1])
    assert ranks_in_runs(np.zeros(0, dtype=np.int64)).shape == (0,)
