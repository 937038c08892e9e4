# SPDX-License-Identifier: GPL-3.0-or-later
"""A bounding volume hierarchy built and traversed with whole-array numpy operations.

Triangles are sorted along a Morton (Z-order) curve of their centroids and cut into
leaves of ``leaf_size`` consecutive triangles; the tree is the complete binary tree over
those leaves (padded to a power of two). Every node at level k then covers one
contiguous slice of the sorted triangles, so each level's bounds are a single
reshape-and-reduce, and traversal is breadth-first over (query, node) pairs, one level
at a time: no per-node or per-ray Python loop. For tessellated surfaces the Morton
order gives compact leaves, which is what the ray tracer and the exact solver need. The
GPU's tree of a whole scene (``grouped_order``) gives each object a subtree and splits
it at the median along its box's longest side, node after node: tighter boxes than the
Morton curve's jumps make, for the rays walked per pixel every frame.

Besides boxes, each node stores a cone bounding the vertex normals of its triangles
(axis and cosine of the half-angle). Interpolated normals are normalised convex
combinations of vertex normals, so they stay inside the cone; the exact solver uses
that to discard nodes where no mirror reflection can occur.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

MORTON_BITS = 10
#: Triangles (or slots, points) a build step holds temporaries for at once.
BLOCK = 1 << 16
#: An object of up to this many triangles is split at medians in the GPU's tree (a sort
#: per level: 0.3 s for 100k triangles on a core; the traced frames of the mirror
#: family 15-35 % faster than Morton order's); a larger one is Morton-sorted (a million
#: triangles would take seconds).
MEDIAN_SPLIT_MAX = 1 << 17


def _spread_bits(values: np.ndarray) -> np.ndarray:
    """Insert two zero bits between the low 10 bits of each value (for 30-bit Morton codes)."""
    x = values.astype(np.uint64) & np.uint64(0x3FF)
    x = (x | (x << np.uint64(16))) & np.uint64(0x030000FF)
    x = (x | (x << np.uint64(8))) & np.uint64(0x0300F00F)
    x = (x | (x << np.uint64(4))) & np.uint64(0x030C30C3)
    x = (x | (x << np.uint64(2))) & np.uint64(0x09249249)
    return x


def morton_codes(points: np.ndarray) -> np.ndarray:
    """30-bit Morton codes of points, quantised in their own bounding box."""
    return _morton_codes(lambda start: points[start:start + BLOCK], len(points))


def _morton_codes(block, n_points: int) -> np.ndarray:
    """:func:`morton_codes` of ``n_points`` points made :data:`BLOCK` at a time by
    ``block(start)``: twice, for their box and then for their codes, so that a million
    triangles' centroids and temporaries are never held at once."""
    starts = range(0, n_points, BLOCK)
    lo = np.min([block(start).min(axis=0) for start in starts], axis=0)
    hi = np.max([block(start).max(axis=0) for start in starts], axis=0)
    scale = (1 << MORTON_BITS) - 1
    extent = np.maximum(hi - lo, 1e-300)
    codes = np.empty(n_points, dtype=np.uint64)
    for start in starts:
        cells = np.floor((block(start) - lo) / extent * scale).astype(np.int64)
        cells = np.clip(cells, 0, scale)
        codes[start:start + BLOCK] = ((_spread_bits(cells[:, 0]) << np.uint64(2))
                                      | (_spread_bits(cells[:, 1]) << np.uint64(1)) | _spread_bits(cells[:, 2]))
    return codes


@dataclass(frozen=True)
class BVH:
    """Complete binary tree over Morton-sorted triangles.

    ``order`` (n_leaves * leaf_size,) maps sorted slots to triangle indices, -1 for
    padding. Level k has 2**k nodes; ``box_rows[k]`` (6, 2**k) holds their boxes as six
    coordinate rows (lo x, y, z, hi x, y, z), so that one gather gives a batch's boxes
    coordinate by coordinate (:func:`ray_box_test`); empty nodes have NaN bounds:
    np.maximum and np.minimum carry NaN through, and NaN <= far is False, so every slab
    test rejects them. ``box_lo[k]``, ``box_hi[k]`` are the same boxes as (2**k, 3) rows,
    empty nodes with lo = +inf, hi = -inf.
    ``cone_axis[k]`` (2**k, 3) and ``cone_cos[k]`` (2**k,) bound the vertex normals;
    cone_cos = -1 means "any direction".

    The corners and cones are made on first use, from the ``triangles`` and ``normals``
    the tree was built over (kept by reference): the exact solver's; the ray tracer
    needs the rows alone (a million-triangle mirror's corners are 25 MB each way, its
    cones 17 MB).
    """

    order: np.ndarray
    leaf_size: int
    box_rows: tuple
    triangles: np.ndarray = field(default=None, repr=False)
    normals: np.ndarray | None = field(default=None, repr=False)

    @property
    def depth(self) -> int:
        """Index of the leaf level."""
        return len(self.box_rows) - 1

    @property
    def nbytes(self) -> int:
        """Bytes of the tree's own arrays, those made on first use included once made."""
        arrays = [self.order, *self.box_rows, *self.__dict__.get("box_lo", ()), *self.__dict__.get("box_hi", ())]
        if "_cones" in self.__dict__:
            arrays += [*self._cones[0], *self._cones[1]]
        return int(sum(a.nbytes for a in arrays))

    @functools.cached_property
    def box_lo(self) -> tuple:
        """Per level, the boxes' low corners (2**k, 3); +inf for an empty node."""
        return tuple(np.where(np.isnan(rows[:3].T), np.inf, rows[:3].T) for rows in self.box_rows)

    @functools.cached_property
    def box_hi(self) -> tuple:
        """Per level, the boxes' high corners (2**k, 3); -inf for an empty node."""
        return tuple(np.where(np.isnan(rows[3:].T), -np.inf, rows[3:].T) for rows in self.box_rows)

    @property
    def cone_axis(self) -> tuple:
        return self._cones[0]

    @property
    def cone_cos(self) -> tuple:
        return self._cones[1]

    @functools.cached_property
    def _cones(self) -> tuple:
        return _cones(self.order, self.leaf_size, self.triangles, self.normals)


def _blocks(n_slots: int, leaf_size: int) -> tuple[int, int, int]:
    """(leaves per block, slots per block, ``deep``): the build's blocks of slots, whole
    nodes of every level from ``deep`` down (the nodes above span several blocks)."""
    n_leaves = n_slots // leaf_size
    block_leaves = min(n_leaves, 1 << max(0, int(np.log2(max(1, BLOCK // leaf_size)))))
    depth = int(np.log2(n_leaves))
    return block_leaves, block_leaves * leaf_size, depth - int(np.log2(block_leaves))


def _leaves_for(n_triangles: int, leaf_size: int) -> int:
    """The leaves of a complete tree over ``n_triangles``: a power of two."""
    return 1 << max(0, int(np.ceil(np.log2(max(1, -(-n_triangles // leaf_size))))))


def median_split_order(points: np.ndarray, leaf_size: int) -> np.ndarray:
    """A permutation of ``points`` (M, 3) laid out for a complete tree of
    ``_leaves_for(M, leaf_size)`` leaves, the padding at the end: every node's points
    split across the longest side of their box, the first child taking as many as it
    holds (the median, while the node is full). Level by level, one sort for all nodes."""
    order = np.arange(len(points))
    placed = np.asarray(points, dtype=np.float64)
    capacity = _leaves_for(len(points), leaf_size) * leaf_size
    starts, counts = np.array([0]), np.array([len(points)])
    while capacity > leaf_size and len(points):
        node = np.repeat(np.arange(len(starts)), counts)
        lo = np.minimum.reduceat(placed, starts, axis=0)
        extent = np.maximum.reduceat(placed, starts, axis=0) - lo
        axis = np.argmax(extent, axis=1)
        # One sort for every node: the node's number plus the point's place along its axis, in [0, 1).
        along = (placed[np.arange(len(order)), axis[node]] - lo[node, axis[node]]) / np.maximum(
            extent[np.arange(len(starts)), axis], 1e-300)[node]
        sort = np.argsort(node + 0.999 * np.clip(along, 0.0, 1.0))
        order, placed = order[sort], placed[sort]
        left = np.minimum(counts, capacity // 2)
        starts = np.stack([starts, starts + left], axis=1).reshape(-1)
        counts = np.stack([left, counts - left], axis=1).reshape(-1)
        starts, counts, capacity = starts[counts > 0], counts[counts > 0], capacity // 2
    return order


def _object_order(centroids: np.ndarray, leaf_size: int) -> np.ndarray:
    """One object's triangles (by ``centroids``) in a subtree: split at medians
    (:func:`median_split_order`), or Morton-sorted past :data:`MEDIAN_SPLIT_MAX`."""
    if len(centroids) > MEDIAN_SPLIT_MAX:
        return np.argsort(morton_codes(centroids), kind="stable")
    return median_split_order(centroids, leaf_size)


def grouped_order(vertices: np.ndarray, triangles: np.ndarray, groups: np.ndarray, leaf_size: int) -> np.ndarray:
    """Slots -> triangle index (-1 for padding) of a complete tree in which each group of
    triangles (``groups`` (T,), e.g. one id per object) fills a subtree of its own, split
    at medians in its own box (:func:`_object_order`), the larger subtrees first (each
    then starts on a boundary of its size). Sorted over the whole scene, a floor's few
    big triangles share leaves with the small ones around them, and their boxes swell
    every node above; apart, a ray crossing a glass ball descends the ball's subtree alone."""
    members = [np.flatnonzero(groups == group) for group in np.unique(groups)]  # per object, not per triangle
    sorted_members = [m[_object_order(vertices[triangles[m]].mean(axis=1), leaf_size)] for m in members]
    blocks = sorted(((_leaves_for(len(m), leaf_size), m) for m in sorted_members), key=lambda block: -block[0])
    leaves = _leaves_for(sum(count for count, _ in blocks) * leaf_size, leaf_size)
    order = np.full(leaves * leaf_size, -1, dtype=np.int64)
    start = 0
    for count, ordered in blocks:
        order[start:start + len(ordered)] = ordered
        start += count * leaf_size
    return order


def build_bvh(vertices: np.ndarray, triangles: np.ndarray, normals: np.ndarray | None = None,
              leaf_size: int = 4, groups: np.ndarray | None = None) -> BVH:
    """Build the BVH of a triangle mesh; ``normals`` (N, 3) unit vertex normals for the
    cones; ``groups`` (T,): each group a subtree of its own (:func:`grouped_order`).

    Streamed over blocks of slots (:data:`BLOCK`): no (M, 3, 3) array of every
    triangle's corners is made (a million-triangle mirror's cost 300 MB at once with
    the corner normals). The boxes above the leaves are the smaller of their
    children's bounds (exact), so the tree is the same as one built all at once."""
    n_triangles = len(triangles)
    if groups is None:
        order = np.full(_leaves_for(n_triangles, leaf_size) * leaf_size, -1, dtype=np.int64)
        order[:n_triangles] = np.argsort(_morton_codes(
            lambda start: vertices[triangles[start:start + BLOCK]].mean(axis=1), n_triangles), kind="stable")
    else:
        order = grouped_order(vertices, triangles, np.asarray(groups), leaf_size)
    n_slots = len(order)
    n_leaves = n_slots // leaf_size
    depth = int(np.log2(n_leaves))
    _, block_slots, _ = _blocks(n_slots, leaf_size)
    leaf_lo, leaf_hi = np.empty((n_leaves, 3)), np.empty((n_leaves, 3))
    for start in range(0, n_slots, block_slots):
        slots = order[start:start + block_slots]
        filled = slots >= 0
        corners = vertices[triangles[np.where(filled, slots, 0)]]
        leaves = slice(start // leaf_size, (start + block_slots) // leaf_size)
        leaf_lo[leaves] = np.where(filled[:, None], corners.min(axis=1), np.inf).reshape(-1, leaf_size, 3).min(axis=1)
        leaf_hi[leaves] = np.where(filled[:, None], corners.max(axis=1), -np.inf).reshape(-1, leaf_size, 3).max(axis=1)
    box_rows = [None] * (depth + 1)
    lo, hi = leaf_lo, leaf_hi
    for level in range(depth, -1, -1):
        if level < depth:
            lo = np.minimum(lo[0::2], lo[1::2])
            hi = np.maximum(hi[0::2], hi[1::2])
        box_rows[level] = np.where((lo <= hi).all(axis=1), np.concatenate([lo, hi], axis=1).T, np.nan).copy()
    return BVH(order, leaf_size, tuple(box_rows), triangles, normals)


def _cones(order: np.ndarray, leaf_size: int, triangles: np.ndarray, normals: np.ndarray | None) -> tuple:
    """(cone_axis, cone_cos) per level (:class:`BVH`), streamed over blocks of slots:
    each cone sums its node's corner normals in slot order, as one sum over the node
    would (a node spanning several blocks carries its sum from block to block), then
    takes the smallest cosine to that axis."""
    n_slots = len(order)
    depth = int(np.log2(n_slots // leaf_size))
    block_leaves, block_slots, deep = _blocks(n_slots, leaf_size)
    cone_axis = [np.empty((1 << level, 3)) for level in range(depth + 1)]
    cone_cos = [np.empty(1 << level) for level in range(depth + 1)]
    top_sum = [np.zeros((1 << level, 3)) for level in range(deep)]
    top_min = [np.full(1 << level, np.inf) for level in range(deep)]

    def block(start: int):
        """(corner normals (slots, 3, 3), filled (slots,)) of the slots from ``start``."""
        slots = order[start:start + block_slots]
        filled = slots >= 0
        if normals is None:
            return np.zeros((len(slots), 3, 3)), filled
        slot_normals = normals[triangles[np.where(filled, slots, 0)]]
        slot_normals[~filled] = 0.0
        return slot_normals, filled

    for start in range(0, n_slots, block_slots):
        slot_normals, filled = block(start)
        for level in range(deep, depth + 1):
            nodes = block_leaves >> (depth - level)
            first = start // (n_slots >> level)
            axis, cos = _normal_cones(slot_normals.reshape(nodes, -1, 3), filled.reshape(nodes, -1))
            cone_axis[level][first:first + nodes], cone_cos[level][first:first + nodes] = axis, cos
        for level in range(deep):  # the node holding this block, its normals summed in slot order
            node = start // (n_slots >> level)
            part = slot_normals.reshape(1, -1, 3)
            if start % (n_slots >> level):
                part = np.concatenate([top_sum[level][node][None, None], part], axis=1)
            top_sum[level][node] = part.sum(axis=1)[0]
    for level in range(deep):
        length = np.linalg.norm(top_sum[level], axis=1)
        cone_axis[level][:] = top_sum[level] / np.maximum(length, 1e-300)[:, None]
    if deep:
        for start in range(0, n_slots, block_slots):  # again, for the cosines about the axes
            slot_normals, filled = block(start)
            present = np.repeat(filled, 3)
            for level in range(deep):
                node = start // (n_slots >> level)
                dots = np.einsum("nsd,nd->ns", slot_normals.reshape(1, -1, 3), cone_axis[level][node][None])
                top_min[level][node] = min(top_min[level][node], np.where(present, dots[0], np.inf).min())
        for level in range(deep):
            length = np.linalg.norm(top_sum[level], axis=1)
            cos = top_min[level]
            cone_cos[level][:] = np.where((length < 1e-9) | ~np.isfinite(cos), -1.0, np.clip(cos, -1.0, 1.0))
    return tuple(cone_axis), tuple(cone_cos)


def _normal_cones(node_normals: np.ndarray, node_filled: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cone (axis, cos half-angle) around each node's normals.

    ``node_normals`` is (nodes, 3 * slots, 3), three corner normals per triangle slot;
    ``node_filled`` (nodes, slots) marks the slots holding a triangle.
    """
    total = node_normals.sum(axis=1)
    length = np.linalg.norm(total, axis=1)
    axis = total / np.maximum(length, 1e-300)[:, None]
    dots = np.einsum("nsd,nd->ns", node_normals, axis)
    present = np.repeat(node_filled, 3, axis=1)
    cos = np.where(present, dots, np.inf).min(axis=1)
    cos = np.where((length < 1e-9) | ~np.isfinite(cos), -1.0, np.clip(cos, -1.0, 1.0))
    return axis, cos


NodeTest = Callable[[np.ndarray, int, np.ndarray], np.ndarray]


def descend(bvh: BVH, query_roots: np.ndarray, node_test: NodeTest) -> tuple[np.ndarray, np.ndarray]:
    """Breadth-first descent of (query, node) pairs; returns candidate (query, triangle) pairs.

    ``node_test(queries, level, nodes)`` returns a bool mask of the pairs to keep. All
    queries start at the root; pairs that pass the test at the leaf level expand into
    their leaf's triangles. Both returned arrays are sorted by query.
    """
    queries = np.asarray(query_roots, dtype=np.int64)
    nodes = np.zeros(len(queries), dtype=np.int64)
    for level in range(bvh.depth + 1):
        keep = node_test(queries, level, nodes)
        queries, nodes = queries[keep], nodes[keep]
        if level < bvh.depth:
            queries = np.repeat(queries, 2)
            nodes = (np.repeat(nodes, 2) << 1) | np.tile(np.array([0, 1]), len(nodes))
    slots = nodes[:, None] * bvh.leaf_size + np.arange(bvh.leaf_size)
    triangles = bvh.order[slots]
    queries = np.broadcast_to(queries[:, None], triangles.shape)
    present = triangles >= 0
    return queries[present], triangles[present]


def ray_box_test(bvh: BVH, origins: np.ndarray, directions: np.ndarray,
                 t_min: np.ndarray, t_max: np.ndarray) -> NodeTest:
    """Slab test of rays against node boxes, for :func:`descend`.

    Zero direction components are replaced by a tiny value of the same sign so that
    the slab distances stay finite (no 0 * inf NaNs on box faces).
    """
    safe = np.where(np.abs(directions) < 1e-30, np.where(directions < 0, -1e-30, 1e-30), directions)
    # Structure of arrays: one gather per side gives every coordinate as a contiguous row.
    rays = np.concatenate([origins, 1.0 / safe], axis=1).T.copy()
    boxes = bvh.box_rows

    def test(queries: np.ndarray, level: int, nodes: np.ndarray) -> np.ndarray:
        box = boxes[level][:, nodes]
        ray = rays[:, queries]
        near, far = t_min[queries], t_max[queries]
        for d in range(3):
            t0 = (box[d] - ray[d]) * ray[d + 3]
            t1 = (box[d + 3] - ray[d]) * ray[d + 3]
            near = np.maximum(near, np.minimum(t0, t1))
            far = np.minimum(far, np.maximum(t0, t1))
        return near <= far

    return test
