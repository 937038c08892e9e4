# SPDX-License-Identifier: GPL-3.0-or-later
"""Answers of a sample-based camera's tree past its rays (``sbc.SampleBasedCamera``):
which ray-map cells hold all four rays of a grid, the rays along a tree's edge, and the
seeds that start the true-ray polish (``true_rays.py``) there: across a sharp edge of
the mirror between two smooth pieces, and in the last ring of a higher order's
footprint, where some rays left the path's mirrors.
"""

from __future__ import annotations

import numpy as np

from .bsp import BSPTree
from .raymap import RayMap
from ...geometry.segments import expand_ranges

#: Camera answers up to this many cells past their leaf's rays, across a sharp edge of
#: the mirror, are polished on the true rays (SampleBasedCamera._across_edge).
EDGE_REACH_CELLS = 1.0


def complete_quads(grid: np.ndarray) -> np.ndarray:
    """(rows - 1, columns - 1) whether the four rays at the corners of each unit cell exist in ``grid``."""
    present = grid >= 0
    return present[:-1, :-1] & present[:-1, 1:] & present[1:, :-1] & present[1:, 1:]


def edge_seeds(ray_map: RayMap, tree: BSPTree, row, points, edge_rays: np.ndarray, spacing):
    """Seeds for images near a sharp edge, on ray-list rows ``row`` (P,) whose cells
    neither hold the point nor reach it across the edge: per point, the row's ray along
    the edge (``edge_rays``) whose line passes closest to it (:func:`_closest_rays`).
    Returns (ray-map cells (P, 2), distance along the ray (P,)), NaN where no such ray
    passes near.

    A ray-list leaf one ray wide along the edge has no complete cell, and next to where
    three pieces meet a point's image may lie in the cells of another leaf than the one
    it descends to; the true-ray polish starts at the ray.
    """
    start, stop = tree.list_ray_start[row], tree.list_ray_start[row + 1]
    pair_point, pair_ray = expand_ranges(start, stop - start)
    ray = tree.list_rays[pair_ray]
    on_edge = edge_rays[ray]
    return _closest_rays(ray_map, points, pair_point[on_edge], ray[on_edge], spacing)


#: How far (neighbour spacings) the last ring's rays seed a higher order's answers.
SEED_REACH = 3.0
#: Points whose nearest-ray seeds are looked for together (points x rays pairs per batch).
SEED_PAIRS = 1 << 22


def nearest_ray_seeds(ray_map: RayMap, points, edge_rays: np.ndarray, spacing):
    """As :func:`edge_seeds`, over every ray of ``edge_rays`` (a higher order's last ring
    of footprint rays, a few hundred) for each of ``points``, in batches."""
    rays = np.flatnonzero(edge_rays)
    cells = np.full((len(points), 2), np.nan)
    distance = np.full(len(points), np.nan)
    if len(rays) == 0 or len(points) == 0:
        return cells, distance
    batch = max(1, SEED_PAIRS // len(rays))
    for start in range(0, len(points), batch):
        part = points[start:start + batch]
        pair_point = np.repeat(np.arange(len(part)), len(rays))
        cells[start:start + batch], distance[start:start + batch] = _closest_rays(
            ray_map, part, pair_point, np.tile(rays, len(part)), spacing, SEED_REACH)
    return cells, distance


def _closest_rays(ray_map: RayMap, points, pair_point, ray, spacing, reach: float = EDGE_REACH_CELLS):
    """Per point, of the candidate (``pair_point``, ``ray``) pairs, the ray whose line
    passes closest to it relative to how far the neighbouring rays pass there
    (``spacing``: per ray, (tail, direction) of ``bsp.neighbour_spacing``; within
    EDGE_REACH_CELLS of them), ahead of its tail: (ray-map cells (P, 2), distance along
    the ray (P,)), NaN where none passes near."""
    offset = points[pair_point] - ray_map.tail[ray]
    along = np.einsum("ij,ij->i", offset, ray_map.direction[ray])
    miss = np.sqrt(np.maximum(np.einsum("ij,ij->i", offset, offset) - along * along, 0.0))
    tail_step, direction_step = spacing[0][ray], spacing[1][ray]
    ratio = miss / np.maximum(reach * (tail_step + np.maximum(along, 0.0) * direction_step), 1e-300)
    near = np.flatnonzero((along >= 0) & (ratio <= 1.0))
    order = near[np.lexsort((ratio[near], pair_point[near]))]
    first = order[np.concatenate([[True], pair_point[order][1:] != pair_point[order][:-1]])] if len(order) else order
    cells = np.full((len(points), 2), np.nan)
    distance = np.full(len(points), np.nan)
    cells[pair_point[first]] = ray_map.cell[ray[first]]
    distance[pair_point[first]] = along[first]
    return cells, distance


def _corners(grid: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """(P, 4) whether each of the four rays around each fractional cell exists in ``grid``
    (False outside it)."""
    base = np.floor(cells).astype(np.int64)
    rows, columns = grid.shape
    present = np.zeros((len(base), 4), dtype=bool)
    for k, (dj, di) in enumerate(((0, 0), (0, 1), (1, 0), (1, 1))):
        i, j = base[:, 0] + di, base[:, 1] + dj
        inside = (i >= 0) & (j >= 0) & (i < columns) & (j < rows)
        present[:, k] = inside & (grid[np.where(inside, j, 0), np.where(inside, i, 0)] >= 0)
    return present


def complete(grid: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Whether the four rays around each fractional cell exist in ``grid``."""
    return _corners(grid, cells).all(axis=1)


def touches(grid: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Whether some of the four rays around each fractional cell exist in ``grid``."""
    return _corners(grid, cells).any(axis=1)
