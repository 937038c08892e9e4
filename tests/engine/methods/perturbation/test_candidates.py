# SPDX-License-Identifier: GPL-3.0-or-later
"""The candidate scan: local minima of the point-to-ray distance over a seed grid."""

from types import SimpleNamespace

import numpy as np

from curved_reflections.engine.methods.perturbation.candidates import candidate_images


def _parallel_rays(rows=7, columns=9, missing=()):
    """A seed grid whose rays run along +z from (column, row, 0): the distance from a
    point to the ray of cell (r, c) is its distance from (c, r) in the xy plane."""
    grid = np.full((rows, columns), -1, dtype=np.int64)
    cells = [(r, c) for r in range(rows) for c in range(columns) if (r, c) not in missing]
    grid[tuple(np.array(cells).T)] = np.arange(len(cells))
    points = np.array([[c, r, 0.0] for r, c in cells], dtype=float)[:, None]
    outgoing = np.tile([0.0, 0.0, 1.0], (len(cells), 1))
    seeds = SimpleNamespace(points=points, outgoing=outgoing)
    return SimpleNamespace(seeds=seeds, grid=grid, coarse=1, inner=None), cells


def test_each_point_is_a_candidate_at_the_ray_it_passes_nearest():
    group, cells = _parallel_rays()
    points = np.array([[2.2, 3.1, 4.0], [6.9, 0.4, 2.0]])
    point_of, seed_of = candidate_images(group, points)
    assert point_of.tolist() == [0, 1]
    assert [cells[s] for s in seed_of] == [(3, 2), (0, 7)]


def test_a_point_beyond_the_footprint_is_a_candidate_at_its_edge():
    """The distance falls toward the edge: the image lies beyond the last seeds."""
    group, cells = _parallel_rays(missing=((3, 4),))
    point_of, seed_of = candidate_images(group, np.array([[12.0, 3.0, 1.0], [4.0, 3.0, 1.0]]))
    found = {(p, cells[s]) for p, s in zip(point_of, seed_of)}
    assert (0, (3, 8)) in found
    # Around a missing cell its four neighbours are equally near (diagonal neighbours of
    # each other): one candidate, the first in raster order.
    assert {c for p, c in found if p == 1} == {(2, 4)}


def test_inner_cells_are_never_candidates_and_a_flat_minimum_is_one():
    group, cells = _parallel_rays()
    inner = np.zeros(group.grid.shape, dtype=bool)
    inner[3, 2] = True
    group.inner = inner
    point_of, seed_of = candidate_images(group, np.array([[2.0, 3.0, 1.0], [4.5, 5.0, 1.0]]))
    assert 0 not in point_of.tolist()
    assert [cells[s] for s in seed_of] == [(5, 4)]  # tie between (5, 4) and (5, 5): the first
