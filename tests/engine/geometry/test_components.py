# SPDX-License-Identifier: GPL-3.0-or-later
"""Connected components on whole arrays (engine/geometry/components.py)."""

import numpy as np

from curved_reflections.engine.geometry.components import component_roots, numbered_in_order


def test_components_of_edges_are_labelled_by_their_lowest_node():
    # 0-1-2 a chain given backwards, 3 alone, 4-5 and 5-6 joined through 5, 7 with itself.
    edges = np.array([[2, 1], [1, 0], [6, 5], [5, 4], [7, 7]])
    np.testing.assert_array_equal(component_roots(edges, 8), [0, 0, 0, 3, 4, 4, 4, 7])


def test_a_long_path_needs_no_pass_per_node():
    n = 100_000
    path = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)[::-1]
    assert (component_roots(path, n) == 0).all()


def test_no_groups_leave_every_node_alone():
    np.testing.assert_array_equal(component_roots(np.zeros((0, 3), np.int64), 4), np.arange(4))


def test_keys_are_numbered_in_the_order_they_first_appear():
    np.testing.assert_array_equal(numbered_in_order(np.array([7, 3, 7, 9, 3])), [0, 1, 0, 2, 1])
