# SPDX-License-Identifier: GPL-3.0-or-later
import numpy as np

from curved_reflections.addon.bvh import build_bvh, descend, morton_codes
from curved_reflections.addon.sphere import icosphere


def _sphere_bvh(subdivisions=3, leaf_size=4):
    sphere = icosphere([1.0, 2.0, 3.0], 2.0, subdivisions)
    return sphere, build_bvh(sphere.vertices, sphere.triangles, sphere.normals, leaf_size)


def test_every_triangle_sits_in_exactly_one_leaf_slot():
    sphere, bvh = _sphere_bvh()
    placed = bvh.order[bvh.order >= 0]
    assert sorted(placed.tolist()) == list(range(len(sphere.triangles)))
    assert len(bvh.order) == bvh.leaf_size << bvh.depth


def test_boxes_contain_their_triangles_at_every_level():
    sphere, bvh = _sphere_bvh()
    corners = sphere.vertices[sphere.triangles]
    for level in range(bvh.depth + 1):
        span = len(bvh.order) >> level
        node = np.flatnonzero(bvh.order >= 0) // span
        triangle = bvh.order[bvh.order >= 0]
        assert np.all(bvh.box_lo[level][node] <= corners[triangle].min(axis=1) + 1e-12)
        assert np.all(bvh.box_hi[level][node] >= corners[triangle].max(axis=1) - 1e-12)


def test_cones_contain_the_vertex_normals_of_their_triangles():
    sphere, bvh = _sphere_bvh()
    normals = sphere.normals[sphere.triangles]  # (M, 3, 3)
    for level in range(bvh.depth + 1):
        span = len(bvh.order) >> level
        node = np.flatnonzero(bvh.order >= 0) // span
        triangle = bvh.order[bvh.order >= 0]
        dots = np.einsum("tkd,td->tk", normals[triangle], bvh.cone_axis[level][node])
        assert np.all(dots >= bvh.cone_cos[level][node][:, None] - 1e-12)
    assert bvh.cone_cos[0][0] == -1.0  # the whole sphere faces every way
    assert bvh.cone_cos[-1].max() > 0.95  # a leaf of a fine sphere faces one way


def test_descend_with_an_always_true_test_returns_every_pair():
    sphere, bvh = _sphere_bvh(subdivisions=2)
    queries, triangles = descend(bvh, np.arange(3), lambda q, level, n: np.ones(len(q), bool))
    assert len(queries) == 3 * len(sphere.triangles)
    assert np.all(np.diff(queries) >= 0)


def test_morton_codes_keep_neighbours_close():
    points = np.array([[0, 0, 0], [1e-3, 0, 0], [1, 1, 1], [0.999, 1, 1]], dtype=float)
    order = np.argsort(morton_codes(points))
    assert {frozenset(order[:2]), frozenset(order[2:])} == {frozenset({0, 1}), frozenset({2, 3})}
