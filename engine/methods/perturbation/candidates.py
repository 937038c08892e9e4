# SPDX-License-Identifier: GPL-3.0-or-later
"""Candidate images: where on a history's seed grid a point may appear.

Instead of the ray octree of Chen & Arvo (2000), section III-B.2, the seeds' image-plane
grid is searched: the local minima, over a sub-grid of the seeds, of the distance from
the point to each seed's outgoing ray are the point's candidate images (several on a
non-convex mirror: the grouping of III-C.1, without its thresholds). The scan visits
only the cells that hold a seed, so a sparse grid (the dense band along a non-convex
mirror's rim, ``rim.py``) costs its seeds, not its bounding box.
"""

from __future__ import annotations

import numpy as np

#: Images of one point in one history kept at most (non-convex mirrors).
MAX_IMAGES = 8
#: Candidates farther from their nearest ray than this many times the point's best are
#: dropped. A small image (near a fold, where the mirror shrinks what it shows) has its
#: rays spread wide at the point: a smaller spread drops those images on bumpy mirrors.
CANDIDATE_SPREAD = 16.0
#: Distances evaluated per block of points (points x scanned seeds).
BLOCK_SIZE = 4_000_000

#: The 8 neighbours (row, column offsets), those before a cell in raster order first.
_NEIGHBOURS = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))
_BEFORE = 4


def candidate_images(group, points):
    """(point, seed) pairs: the local minima over ``group``'s scanned cells (its grid's
    every ``coarse``-th seed) of the distance from each point to each seed's outgoing ray
    (behind its start: to the start). Cells in ``group.inner`` (next to seeds another
    group answers) are never candidates."""
    seed_at, neighbours, blocked = scanned_cells(group)
    seeds = group.seeds
    tail, direction = seeds.points[seed_at, -1], seeds.outgoing[seed_at]
    # Squared distance to each ray from dot products alone (two small matrix products):
    # |p - t|^2 - max((p - t) . d, 0)^2.
    tail_along = np.einsum("si,si->s", tail, direction)
    tail_square = np.einsum("si,si->s", tail, tail)
    block = max(1, BLOCK_SIZE // max(len(seed_at), 1))
    point_of, seed_of = [], []
    for start in range(0, len(points), block):
        chunk = points[start:start + block]
        along = np.maximum(chunk @ direction.T - tail_along, 0.0)
        square = np.einsum("pi,pi->p", chunk, chunk)[:, None] - 2.0 * chunk @ tail.T + tail_square - along * along
        distance = np.sqrt(np.maximum(square, 0.0))
        # A candidate much farther from its rays than the point's best is an edge
        # minimum, not an image: every image's rays pass within a seed spacing's spread.
        # (The best is a local minimum too: cells beyond the spread need no test.)
        best = (distance[:, ~blocked] if blocked.any() else distance).min(axis=1, keepdims=True)
        p, s = np.nonzero(distance <= CANDIDATE_SPREAD * best)
        keep = _local_minima(distance, p, s, neighbours) & ~blocked[s]
        p, s = p[keep], s[keep]
        found = distance[p, s]
        order = np.lexsort((found, p))
        p, s = p[order], s[order]
        keep = np.arange(len(p)) - np.searchsorted(p, p) < MAX_IMAGES
        point_of.append(p[keep] + start)
        seed_of.append(seed_at[s[keep]])
    return np.concatenate(point_of), np.concatenate(seed_of)


def scanned_cells(group):
    """The scan's cells: (S,) seed index of each, (S, 8) each one's neighbours in the scan
    (position among the S, -1 where none), (S,) bool cells that may not be candidates."""
    step = group.coarse
    grid = group.grid[step // 2::step, step // 2::step]
    if not (grid >= 0).any():
        grid, step = group.grid, 1
    rows, columns = np.nonzero(grid >= 0)
    position = np.full(grid.shape, -1, dtype=np.int64)
    position[rows, columns] = np.arange(len(rows))
    padded = np.pad(position, 1, constant_values=-1)
    neighbours = np.stack([padded[rows + 1 + di, columns + 1 + dj] for di, dj in _NEIGHBOURS], axis=1)
    blocked = np.zeros(len(rows), dtype=bool)
    if group.inner is not None:
        blocked = group.inner[step // 2::step, step // 2::step][rows, columns]
    return grid[rows, columns], neighbours, blocked


def _local_minima(distance: np.ndarray, p: np.ndarray, s: np.ndarray, neighbours: np.ndarray) -> np.ndarray:
    """(K,) bool: whether cells ``s`` are, for points ``p``, no farther than their 8
    neighbours (ties go to the first in raster order, so a flat minimum is one
    candidate). A missing neighbour counts as infinitely far: cells on the footprint's
    edge count whenever the distance falls toward the edge, as an image close to the
    silhouette lies beyond the last seeds."""
    found = distance[p, s]
    alive = np.arange(len(p))
    for k in range(len(_NEIGHBOURS)):  # the survivors only: most cells fail a first test
        neighbour = neighbours[s[alive], k]
        there = np.where(neighbour >= 0, distance[p[alive], np.maximum(neighbour, 0)], np.inf)
        alive = alive[(found[alive] < there) if k < _BEFORE else (found[alive] <= there)]
    minimum = np.zeros(len(p), dtype=bool)
    minimum[alive] = True
    return minimum
