# SPDX-License-Identifier: GPL-3.0-or-later
"""Answers of a sample-based camera's tree past its rays (``sbc.SampleBasedCamera``):
which ray-map cells hold all four rays of a grid, the rays along a tree's edge, and the
seeds that start the true-ray polish (``true_rays.py``) there: across a sharp edge of
the mirror between two smooth pieces, and in the last ring of a higher order's
footprint, where some rays left the path's mirrors, with sub-rays traced between the
ring's rays (``SeedRays``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .bsp import BSPTree
from .raymap import RayMap
from ...geometry.raytrace import ReflectorSet
from ...geometry.segments import expand_ranges, ranks_in_runs
from ...reference.true_rays import trace_history

#: Camera answers up to this many cells past their leaf's rays, across a sharp edge of
#: the mirror, are polished on the true rays (SampleBasedCamera._across_edge).
EDGE_REACH_CELLS = 1.0


def complete_quads(grid: np.ndarray) -> np.ndarray:
    """(rows - 1, columns - 1) whether the four rays at the corners of each unit cell exist in ``grid``."""
    present = grid >= 0
    return present[:-1, :-1] & present[:-1, 1:] & present[1:, :-1] & present[1:, 1:]


def touched_quads(mask: np.ndarray) -> np.ndarray:
    """(rows - 1, columns - 1) whether ``mask`` (rows, columns) holds some corner of each unit cell."""
    return mask[:-1, :-1] | mask[:-1, 1:] | mask[1:, :-1] | mask[1:, 1:]


@dataclass(frozen=True)
class SeedRays:
    """Traced rays that start the true-ray polish: fractional ray-map cells (S, 2), tails
    and unit directions (S, 3), and how far the rays one cell away pass (tail step and
    direction step (S,): at distance s along the ray, tail + s * direction, world units)."""

    cell: np.ndarray
    tail: np.ndarray
    direction: np.ndarray
    tail_step: np.ndarray
    direction_step: np.ndarray

    @classmethod
    def of_rays(cls, ray_map: RayMap, rays: np.ndarray, spacing) -> "SeedRays":
        """The ray map's ``rays`` with their neighbour ``spacing`` (per ray of the map, (tail,
        direction) of ``raymap.neighbour_spacing``)."""
        return cls(ray_map.cell[rays].astype(np.float64), ray_map.tail[rays], ray_map.direction[rays],
                   spacing[0][rays], spacing[1][rays])

    def __len__(self) -> int:
        return len(self.cell)

    def __add__(self, other: "SeedRays") -> "SeedRays":
        return SeedRays(*(np.concatenate([getattr(self, f), getattr(other, f)]) for f in self.__dataclass_fields__))


def edge_seeds(ray_map: RayMap, tree: BSPTree, row, points, edge_rays: np.ndarray, spacing):
    """Seeds for images near a sharp edge, on ray-list rows ``row`` (P,) whose cells
    neither hold the point nor reach it across the edge: per point, the row's ray along
    the edge (``edge_rays``) whose line passes closest to it (:func:`_closest_seeds`).
    Returns (ray-map cells (P, 2), distance along the ray (P,)), NaN where no such ray
    passes near.

    A ray-list leaf one ray wide along the edge has no complete cell, and next to where
    three pieces meet a point's image may lie in the cells of another leaf than the one
    it descends to; the true-ray polish starts at the ray.
    """
    start, stop = tree.list_ray_start[row], tree.list_ray_start[row + 1]
    pair_point, pair_ray = expand_ranges(start, stop - start)
    ray = tree.list_rays[pair_ray]
    on_edge = np.flatnonzero(edge_rays[ray])
    seeds = SeedRays.of_rays(ray_map, ray[on_edge], spacing)
    cells, distance = _closest_seeds(seeds, points, pair_point[on_edge], np.arange(len(on_edge)))
    return cells[:, 0], distance[:, 0]


#: How far (neighbour spacings) the last ring's rays seed a higher order's answers (3 and
#: 1.5 found the same images on four two-mirror scenes; 1.5 seeds fewer points with none).
SEED_REACH = 1.5
#: Points whose nearest-ray seeds are looked for together (points x rays pairs per batch).
SEED_PAIRS = 1 << 22
#: Sub-rays between a higher order's ring rays lie this far apart (desired-view pixels).
SUB_RAY_PX = 0.5
#: ... in the unit cells within this many cells of the footprint.
SUB_RAY_REACH_CELLS = 2


def nearest_ray_seeds(seeds: SeedRays, points, ranks: int = 1):
    """For each of ``points``, the ``ranks`` seed rays passing closest (within SEED_REACH
    of their neighbour spacing, closest first), over every seed (a higher order's ring,
    a few hundred to a few thousand), in batches: (cells (P, ranks, 2), distances along
    the rays (P, ranks)), NaN where fewer pass near."""
    cells = np.full((len(points), ranks, 2), np.nan)
    distance = np.full((len(points), ranks), np.nan)
    if len(seeds) == 0 or len(points) == 0:
        return cells, distance
    batch = max(1, SEED_PAIRS // len(seeds))
    for start in range(0, len(points), batch):
        part = points[start:start + batch]
        pair_point = np.repeat(np.arange(len(part)), len(seeds))
        cells[start:start + batch], distance[start:start + batch] = _closest_seeds(
            seeds, part, pair_point, np.tile(np.arange(len(seeds)), len(part)), SEED_REACH, ranks)
    return cells, distance


def sub_ray_seeds(reflector_set: ReflectorSet, ray_map: RayMap, history, grid: np.ndarray,
                  first_order: np.ndarray) -> SeedRays:
    """Rays of a higher order's ``history`` traced between the ray map's, SUB_RAY_PX
    apart, in the unit cells that do not hold all four rays of its ``grid`` but hold one
    of the first reflector's (``first_order``, that reflector's first-order grid), within
    SUB_RAY_REACH_CELLS of the footprint.

    Where a path grazes a mirror, its footprint thins to a sliver a cell wide or less
    (a low wall seen in the rim of a ball), and the images between the ring's rays lie
    ten or more pixels from the nearest ray that reaches the second mirror: the polish
    from there does not find them. Each sub-ray's spacing is measured to its traced
    neighbours and scaled to a cell, as the ray map's rays' are.
    """
    present = grid >= 0
    near = present.copy()
    for _ in range(SUB_RAY_REACH_CELLS):
        near[1:] |= near[:-1]
        near[:-1] |= near[1:]
        near[:, 1:] |= near[:, :-1]
        near[:, :-1] |= near[:, 1:]
    quads = ~complete_quads(grid) & touched_quads(near) & touched_quads(first_order >= 0)
    j, i = np.nonzero(quads)
    per_axis = max(2, math.ceil(ray_map.downsample / SUB_RAY_PX))
    step = 1.0 / per_axis
    a, b = np.meshgrid(np.arange(per_axis), np.arange(per_axis), indexing="ij")
    offsets = np.c_[a.ravel(), b.ravel()][1:] * step  # the (0, 0) ray is the map's own
    cells = (np.c_[i, j][:, None, :] + offsets[None]).reshape(-1, 2)
    if len(cells) == 0:
        return SeedRays(*(np.zeros((0, 2)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0)))
    traced = np.concatenate([cells, cells + (step, 0.0), cells + (0.0, step)])
    tail, direction, _, valid, _ = trace_history(reflector_set, ray_map.view, history,
                                                 ray_map.cell_pixels(traced))
    n = len(cells)
    tail, direction, valid = tail.reshape(3, n, 3), direction.reshape(3, n, 3), valid.reshape(3, n)
    keep = np.flatnonzero(valid[0])
    tail_step = np.zeros(n)
    direction_step = np.zeros(n)
    for k in (1, 2):
        other = valid[k]
        tail_step = np.maximum(tail_step, np.where(other, np.linalg.norm(tail[k] - tail[0], axis=1), 0.0))
        direction_step = np.maximum(direction_step,
                                    np.where(other, np.linalg.norm(direction[k] - direction[0], axis=1), 0.0))
    tail_step, direction_step = per_axis * tail_step[keep], per_axis * direction_step[keep]
    # A sub-ray at a sliver's tip, neither neighbour on the path: the others' median spacing.
    alone = tail_step <= 0.0
    if alone.any() and not alone.all():
        tail_step[alone] = np.median(tail_step[~alone])
        direction_step[alone] = np.median(direction_step[~alone])
    return SeedRays(cells[keep], tail[0, keep], direction[0, keep], tail_step, direction_step)


def _closest_seeds(seeds: SeedRays, points, pair_point, seed, reach: float = EDGE_REACH_CELLS, ranks: int = 1):
    """Per point, of the candidate (``pair_point``, ``seed``) pairs, the ``ranks`` seed rays
    whose lines pass closest to it relative to how far their neighbours pass there
    (within ``reach`` of them), ahead of their tails, closest first: (ray-map cells
    (P, ranks, 2), distances along the rays (P, ranks)), NaN where fewer pass near."""
    offset = points[pair_point] - seeds.tail[seed]
    along = np.einsum("ij,ij->i", offset, seeds.direction[seed])
    miss = np.sqrt(np.maximum(np.einsum("ij,ij->i", offset, offset) - along * along, 0.0))
    step = seeds.tail_step[seed] + np.maximum(along, 0.0) * seeds.direction_step[seed]
    ratio = miss / np.maximum(reach * step, 1e-300)
    near = np.flatnonzero((along >= 0) & (ratio <= 1.0))
    order = near[np.lexsort((ratio[near], pair_point[near]))]
    owner = pair_point[order]
    rank = ranks_in_runs(owner)
    chosen = np.flatnonzero(rank < ranks)
    cells = np.full((len(points), ranks, 2), np.nan)
    distance = np.full((len(points), ranks), np.nan)
    cells[owner[chosen], rank[chosen]] = seeds.cell[seed[order[chosen]]]
    distance[owner[chosen], rank[chosen]] = along[order[chosen]]
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
