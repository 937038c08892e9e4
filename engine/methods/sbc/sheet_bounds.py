# SPDX-License-Identifier: GPL-3.0-or-later
"""Where each sheet of a sample-based camera can project: a k-DOP per sheet, and spatial chunks.

SBC paper (Popescu, Sacks, Mei 2006), section IV-B/V-A: a point projects in a group
(sheet) only near one of the group's rays, between four neighbouring rays of its ray
map, at most ``sbc_cells.MISS_CELLS`` cell spacings off the interpolated ray and not beyond
its head when the head is on a reflector. So a sheet reflects only the part of space
its rays sweep. This module bounds that part conservatively and lets the renderer skip,
per sheet, the diffuse vertices that lie outside it (``drawing/methods/sbc_triangles.py``):

- :func:`sheet_kdops`: per sheet, a k-DOP (:data:`DIRECTIONS`, 13 slab directions) of
  its rays' tails and heads (a ray segment lies in the convex hull of its ends, and the
  interpolated ray of four neighbouring rays in the hull of theirs), widened by
  ``MISS_CELLS + 1`` times the largest spacing between neighbouring rays (ends of
  neighbouring rays) and a small tolerance. A ray whose head leaves the scene box
  does not limit projection (``sbc._project_group``): it is extended to the scene's
  diameter, the longest distance from a reflector point to any diffuse vertex.
- :func:`morton_order` and :func:`chunk_boxes`: vertices sorted along a Morton curve,
  so that fixed-size runs of them are spatially compact, and each run's AABB.
- :func:`chunks_meeting`: the runs whose AABB meets a k-DOP (slab test on the k-DOP's
  directions: conservative, it never drops a run that meets it); :func:`chunks_in_cone`:
  those that may meet a sheet's bounding cone (``sbc.cones``, :func:`.ray_cones.ray_cones`:
  the engine's own bound, per sheet, of the rays' reach, unbounded beyond the heads).
  The k-DOP is per ray-map group (``sbc.grids`` is shared by the sheets of a group) and
  bounds the far end; the cone separates the sheets of a group.
"""

from __future__ import annotations

import numpy as np

from ...geometry.bvh import morton_codes
from .sbc_cells import MISS_CELLS

#: Slab directions of the k-DOPs: the axes, the face diagonals and the body diagonals (k = 26).
DIRECTIONS = np.array([
    [1, 0, 0], [0, 1, 0], [0, 0, 1],
    [1, 1, 0], [1, -1, 0], [1, 0, 1], [1, 0, -1], [0, 1, 1], [0, 1, -1],
    [1, 1, 1], [1, 1, -1], [1, -1, 1], [-1, 1, 1],
], dtype=np.float64)
DIRECTIONS = DIRECTIONS / np.linalg.norm(DIRECTIONS, axis=1, keepdims=True)
#: Added to every slab, times the scene's diameter (float32 rounding on the GPU and the
#: shader's tolerances are far below this).
RELATIVE_TOLERANCE = 1e-4


def sheet_kdops(sbc, diameter: float) -> np.ndarray:
    """(sheets, len(DIRECTIONS), 2) float64: per sheet the [min, max] of each slab, or
    [+inf, -inf] (empty) for a sheet without rays. ``diameter`` bounds the distance from
    any reflector point to any diffuse vertex."""
    ray_map = sbc.ray_map
    result = np.empty((len(sbc.grids), len(DIRECTIONS), 2))
    result[..., 0], result[..., 1] = np.inf, -np.inf
    head_distance = np.where(np.isfinite(ray_map.head_distance), ray_map.head_distance, 0.0)
    tails, directions = ray_map.tail, ray_map.direction
    by_grid: dict = {}  # the sheets of a group share its grid (and its MixedCells)
    for sheet, grid in enumerate(sbc.grids):
        if id(grid) in by_grid:
            result[sheet] = by_grid[id(grid)]
            continue
        rays = grid[grid >= 0]
        if len(rays) == 0:
            by_grid[id(grid)] = result[sheet]
            continue
        mixed = sbc.mixed[sheet] if sbc.mixed is not None else None
        # In a mixed cell a sub-ray decides, which may leave the box while the corners are blocked.
        any_mixed = mixed is not None and bool((mixed.index >= 0).any())
        extend = ~ray_map.blocked[rays] | any_mixed
        length = np.zeros(len(tails))
        length[rays] = np.where(extend, np.maximum(head_distance[rays], diameter), head_distance[rays])
        spacing = 0.0
        for a, b in ((grid[:, :-1], grid[:, 1:]), (grid[:-1, :], grid[1:, :])):
            both = (a >= 0) & (b >= 0)
            if both.any():
                # |tail_i - tail_j + s (dir_i - dir_j)| is largest at an end of s's range.
                i, j = a[both], b[both]
                reach = np.maximum(length[i], length[j])[:, None]
                apart = tails[i] - tails[j]
                spacing = max(spacing, float(np.linalg.norm(apart, axis=1).max()),
                              float(np.linalg.norm(apart + reach * (directions[i] - directions[j]), axis=1).max()))
        ends = np.concatenate([tails[rays], tails[rays] + length[rays, None] * directions[rays]]) @ DIRECTIONS.T
        margin = (MISS_CELLS + 1.0) * spacing + RELATIVE_TOLERANCE * diameter
        result[sheet, :, 0] = ends.min(axis=0) - margin
        result[sheet, :, 1] = ends.max(axis=0) + margin
        by_grid[id(grid)] = result[sheet]
    return result


def morton_order(points: np.ndarray) -> np.ndarray:
    """The permutation sorting ``points`` (N, 3) along the BVH's 30-bit Morton curve."""
    points = np.asarray(points, np.float64)
    if len(points) == 0:
        return np.zeros(0, np.int64)
    return np.argsort(morton_codes(points), kind="stable")


def chunk_boxes(points: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi), each (ceil(N / size), 3): the AABB of each run of ``size`` points."""
    points = np.asarray(points, np.float64)
    n = -(-len(points) // size)
    padded = np.concatenate([points, np.repeat(points[-1:], n * size - len(points), axis=0)]) if n else points
    runs = padded.reshape(n, size, 3)
    return runs.min(axis=1), runs.max(axis=1)


def chunks_in_cone(lo: np.ndarray, hi: np.ndarray, cone: np.ndarray) -> np.ndarray:
    """(C,) bool: the AABBs (lo, hi) that may meet ``cone`` (a sheet's bounding cone of
    ``ray_cones.ray_cones``: apex, unit axis, radius at the apex, radius growth per unit along
    the axis, least distance along the axis). Tested with each box's bounding sphere:
    a box is dropped only when no point within its sphere's radius r of its centre can
    be in the cone (along + r below the least distance, or the distance from the axis
    minus r beyond the radius at along + r)."""
    centre = 0.5 * (lo + hi)
    r = 0.5 * np.linalg.norm(hi - lo, axis=1)
    offset = centre - cone[0:3]
    along = offset @ cone[3:6]
    perp = np.sqrt(np.maximum(np.einsum("cd,cd->c", offset, offset) - along * along, 0.0))
    with np.errstate(invalid="ignore"):
        reach = cone[6] + cone[7] * np.maximum(along + r, 0.0)
        return (along + r >= cone[8]) & ~(perp - r > reach)


def chunks_meeting(lo: np.ndarray, hi: np.ndarray, kdop: np.ndarray) -> np.ndarray:
    """(C,) bool: the AABBs (lo, hi) that meet the k-DOP ``kdop`` (len(DIRECTIONS), 2)."""
    centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    middle = centre @ DIRECTIONS.T
    reach = half @ np.abs(DIRECTIONS).T
    return np.all((middle + reach >= kdop[:, 0]) & (middle - reach <= kdop[:, 1]), axis=1)
