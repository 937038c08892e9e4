# SPDX-License-Identifier: GPL-3.0-or-later
import numpy as np

from curved_reflections.engine.geometry.bvh import build_bvh, descend, morton_codes, ray_box_test
from curved_reflections.engine.geometry.sphere import icosphere


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


def _slab_reference(lo, hi, origin, direction, t_min, t_max):
    """One ray against one box, written plainly: the parameter interval inside every slab."""
    if np.any(lo > hi):
        return False
    near, far = t_min, t_max
    for d in range(3):
        if direction[d] == 0.0:
            if not lo[d] <= origin[d] <= hi[d]:
                return False
            continue
        t0, t1 = sorted(((lo[d] - origin[d]) / direction[d], (hi[d] - origin[d]) / direction[d]))
        near, far = max(near, t0), min(far, t1)
    return near <= far


def test_ray_box_test_matches_a_plain_slab_test_and_rejects_empty_nodes():
    # 80 triangles in leaves of 4: 20 leaves padded to 32, so the deepest levels hold empty nodes.
    sphere = icosphere([0.0, 0.0, 0.0], 1.0, 1)
    bvh = build_bvh(sphere.vertices, sphere.triangles, sphere.normals, 4)
    rng = np.random.default_rng(7)
    origins = rng.uniform(-2.0, 2.0, (300, 3))
    directions = rng.normal(size=(300, 3))
    directions[:20, 1] = 0.0  # parallel to a pair of slabs
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    t_min, t_max = np.full(300, 1e-9), rng.uniform(0.5, 4.0, 300)
    test = ray_box_test(bvh, origins, directions, t_min, t_max)
    empty_seen = 0
    for level in range(bvh.depth + 1):
        n_nodes = len(bvh.box_lo[level])
        queries, nodes = np.repeat(np.arange(300), n_nodes), np.tile(np.arange(n_nodes), 300)
        got = test(queries, level, nodes)
        expected = [_slab_reference(bvh.box_lo[level][n], bvh.box_hi[level][n], origins[q], directions[q],
                                    t_min[q], t_max[q]) for q, n in zip(queries, nodes)]
        assert got.tolist() == expected
        empty = ~(bvh.box_lo[level] <= bvh.box_hi[level]).all(axis=1)
        empty_seen += int(empty.sum())
        assert not got[empty[nodes]].any()
    assert empty_seen > 0
    assert got.any() and not got.all()  # at the leaves, the rays both meet and miss boxes


def test_grouped_triangles_fill_aligned_subtrees_of_their_own_largest_first():
    """Three objects of 80, 20 and 3 triangles: each group's triangles fill one block of
    leaves, a power of two starting on a multiple of its size (a subtree), the largest
    first; every triangle once; each block's leaves bounded by its own object alone."""
    big, middle, small = (icosphere((3.0 * k, 0.0, 0.0), 1.0, level, f"S{k}") for k, level in enumerate((1, 0, 0)))
    parts = [big, middle, small]
    vertices = np.concatenate([p.vertices for p in parts])
    offsets = np.cumsum([0] + [len(p.vertices) for p in parts])
    triangles = np.concatenate([p.triangles + o for p, o in zip(parts, offsets)])
    triangles = triangles[: len(big.triangles) + len(middle.triangles) + 3]
    groups = np.repeat([0, 1, 2], [len(big.triangles), len(middle.triangles), 3])
    bvh = build_bvh(vertices, triangles, leaf_size=4, groups=groups)
    order = bvh.order
    assert sorted(order[order >= 0].tolist()) == list(range(len(triangles)))
    starts = {}
    for group, count in ((0, 80), (1, 20), (2, 3)):
        slots = np.flatnonzero(np.isin(order, np.flatnonzero(groups == group)))
        leaves = 1 << int(np.ceil(np.log2(-(-count // 4))))
        first_leaf = slots.min() // 4
        assert slots.max() // 4 < first_leaf + leaves and first_leaf % leaves == 0
        starts[group] = first_leaf
        level = bvh.depth - int(np.log2(leaves))
        node = first_leaf // leaves
        box = bvh.box_rows[level][:, node]
        points = vertices[triangles[groups == group]].reshape(-1, 3)
        assert np.allclose(box[:3], points.min(axis=0)) and np.allclose(box[3:], points.max(axis=0))
    assert starts[0] < starts[1] < starts[2]


def test_median_splits_halve_every_node_across_its_longest_side():
    """A complete tree's layout: each node's points split at the median of the longest
    side of their box (the first child full, the padding last), and the leaves' boxes
    smaller than the Morton curve's."""
    from curved_reflections.engine.geometry.bvh import median_split_order, morton_codes

    points = np.random.default_rng(3).random((1000, 3)) * (4.0, 1.0, 0.5)  # longest along x
    order = median_split_order(points, 4)
    assert np.array_equal(np.sort(order), np.arange(1000))
    placed = points[order]
    assert placed[:512, 0].max() <= placed[512:, 0].min()  # the root: 512 slots left, 488 right
    left = placed[:512]
    axis = np.argmax(left.max(axis=0) - left.min(axis=0))
    assert left[:256, axis].max() <= left[256:, axis].min()

    def leaf_area(ordered):  # 250 full leaves, the padding after them
        leaves = ordered.reshape(-1, 4, 3)
        extent = leaves.max(axis=1) - leaves.min(axis=1)
        return np.sum(extent[:, 0] * extent[:, 1] + extent[:, 1] * extent[:, 2] + extent[:, 0] * extent[:, 2])

    morton = points[np.argsort(morton_codes(points), kind="stable")]
    assert leaf_area(placed) < 0.9 * leaf_area(morton)
