# SPDX-License-Identifier: GPL-3.0-or-later
"""Bounding cones of a group's rays: where a BSP leaf, or a whole sheet, can project a point.

A leaf (``bsp.py``) answers only the cells around its member rays, and a point only
within ``sbc_cells.MISS_CELLS`` cell spacings of a cell's interpolated ray. A cone around
every ray that can be a corner of such a cell, followed to infinity and widened by the
spacing of neighbouring rays, therefore holds every point the leaf can project: a point
outside it skips the leaf before any Newton iteration (``SampleBasedCamera.project``),
and a sheet's cone skips its whole tree (also for the GPU draw's culling,
``sheet_bounds.py``). The test is conservative, never an approximation: answers are the
same with and without cones.
"""

from __future__ import annotations

import numpy as np

from .raymap import RayMap, neighbour_spacing
from ...geometry.segments import expand_ranges, segment_max, segment_min
from ...geometry.vectors import cross


def reachable_rays(ray_map: RayMap, grid: np.ndarray, member_ray: np.ndarray, member_leaf: np.ndarray, n: int):
    """(rays, leaf) pairs: every ray of the group that can be a corner of a cell a leaf answers.

    A leaf answers cells within half a cell of its member cells' bounding box (camera
    leaves, ray_patch.project_patches) or cells whose four corners are its members
    (ray lists); the corners of those cells lie in the box grown by one cell.
    """
    cells = ray_map.cell[member_ray]
    lo = np.maximum(segment_min(cells, member_leaf, n) - 1, 0)
    hi = np.minimum(segment_max(cells, member_leaf, n) + 1, [ray_map.columns - 1, ray_map.rows - 1])
    width, height = hi[:, 0] - lo[:, 0] + 1, hi[:, 1] - lo[:, 1] + 1
    count = width * height
    leaf, local = expand_ranges(np.zeros(n, dtype=np.int64), count)
    i = lo[leaf, 0] + local % width[leaf]
    j = lo[leaf, 1] + local // width[leaf]
    ray = grid[j, i]
    return ray[ray >= 0], leaf[ray >= 0]


#: Row layout of a bounding cone: apex (3), unit axis (3), radius at the apex, growth of
#: the radius per unit along the axis, least distance along the axis.
CONE_SIZE = 9
#: Cones are widened by this many times the largest spacing of neighbouring rays.
CONE_MARGIN_CELLS = 3.0
#: Rays more than this far (cosine) from the cone axis make the cone unbounded.
CONE_MIN_COS = 0.05


def ray_cones(ray_map: RayMap, grid: np.ndarray, member_ray: np.ndarray, member_node: np.ndarray,
              n: int) -> np.ndarray:
    """(n, CONE_SIZE) cones around the region where each node's rays can project a point.

    A node (leaf or sheet) projects a point only within MISS_CELLS cell spacings of the
    interpolated ray of a cell it answers; ``member_ray`` holds every ray that can be a
    corner of such a cell (:func:`reachable_rays`). The cone holds every point
    t_i + s d_i (s >= 0, also beyond the head) of those rays: with axis d and apex c,
    a radius growing by k >= |d_i x d| / (d_i . d) per unit along d holds a ray whose
    tail it holds. It is widened by CONE_MARGIN_CELLS times the largest distance between
    neighbouring rays (at tail and head, growing with the directions' difference): the
    MISS_CELLS tolerance plus the bend of the normalised interpolated direction. A point
    outside its cone cannot project there, so projection skips it before any Newton
    iteration; the test is conservative, not an approximation.
    """
    cones = np.zeros((n, CONE_SIZE))
    cones[:, 6], cones[:, 8] = np.inf, -np.inf  # nodes without rays (none expected) accept everything
    if len(member_ray) == 0:
        return cones
    head = ray_map.head
    rays, nodes = member_ray, member_node
    spacing_tail, spacing_direction = neighbour_spacing(ray_map, grid, member_ray)
    present = np.bincount(nodes, minlength=n) > 0
    reduce = _SortedSegments(nodes, n)
    tails, directions = ray_map.tail[rays], ray_map.direction[rays]
    apex = reduce.sum(tails) / np.maximum(reduce.counts, 1)[:, None]
    axis = reduce.sum(directions)
    axis /= np.maximum(np.linalg.norm(axis, axis=1), 1e-300)[:, None]
    cos = np.einsum("md,md->m", directions, axis[nodes])
    sin = np.linalg.norm(cross(directions, axis[nodes]), axis=1)
    growth = reduce.max(np.where(cos > CONE_MIN_COS, sin / np.maximum(cos, CONE_MIN_COS), np.inf))
    bounded = present & np.isfinite(growth)
    safe_growth = np.where(bounded, growth, 0.0)
    radius, least = np.full(n, -np.inf), np.full(n, np.inf)
    for ends in (tails, head[rays]):
        offset = ends - apex[nodes]
        along = np.einsum("md,md->m", offset, axis[nodes])
        perp = np.linalg.norm(offset - along[:, None] * axis[nodes], axis=1)
        radius = np.maximum(radius, reduce.max(perp - safe_growth[nodes] * along))
        least = np.minimum(least, reduce.min(along))
    # Neighbouring rays at distance s along them are at most |dt| + s |dd| apart, and
    # s <= (along - least) / cos along the axis.
    # A point that far off a ray in the cone is also that far along the axis, where the
    # radius is k times that smaller: hence the factor 1 + k.
    margin = CONE_MARGIN_CELLS * reduce.max(spacing_tail) * (1.0 + safe_growth)
    margin_growth = (CONE_MARGIN_CELLS * reduce.max(spacing_direction) / reduce.min(np.maximum(cos, CONE_MIN_COS))
                     * (1.0 + safe_growth))
    least = np.where(present, least, 0.0)
    scale = 1e-6 * (1.0 + np.abs(apex).max(axis=1) + np.abs(least))
    cones[:, 0:3], cones[:, 3:6] = apex, axis
    cones[:, 6] = np.where(bounded, radius + margin + margin_growth * np.maximum(-least, 0.0) + scale, np.inf)
    cones[:, 7] = np.where(bounded, safe_growth + margin_growth, 0.0)
    # Along the axis, a ray only moves forward where every ray is within the cone's angle.
    cones[:, 8] = np.where(bounded, least - margin - scale, -np.inf)
    return cones


class _SortedSegments:
    """Per-node reductions over rows sorted once by node (nodes without rows get the identity)."""

    def __init__(self, node: np.ndarray, n: int):
        self.order = np.argsort(node, kind="stable")
        self.counts = np.bincount(node, minlength=n)
        self.present = self.counts > 0
        self.starts = (np.cumsum(self.counts) - self.counts)[self.present]
        self.n = n

    def _reduce(self, ufunc, values, empty):
        out = np.full((self.n,) + values.shape[1:], empty, dtype=np.float64)
        if len(values):
            out[self.present] = ufunc.reduceat(values[self.order], self.starts, axis=0)
        return out

    def sum(self, values):
        return self._reduce(np.add, values, 0.0)

    def max(self, values):
        return self._reduce(np.maximum, values, -np.inf)

    def min(self, values):
        return self._reduce(np.minimum, values, np.inf)


def in_cones(cones: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Which points (P, 3) lie in their cone (rows of (P, CONE_SIZE), see ray_cones)."""
    offset = points - cones[:, 0:3]
    along = np.einsum("pd,pd->p", offset, cones[:, 3:6])
    squared = np.einsum("pd,pd->p", offset, offset) - along * along
    reach = cones[:, 6] + cones[:, 7] * np.maximum(along, 0.0)
    return (along >= cones[:, 8]) & (squared <= reach * reach)
