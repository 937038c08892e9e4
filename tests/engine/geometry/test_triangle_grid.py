# SPDX-License-Identifier: GPL-3.0-or-later
"""The mirror's walking tables (``engine/geometry/triangle_grid.py``): a grid cell's
triangle lies near any point close to the surface and none is found far from it; each
triangle's neighbour across an edge shares that edge, both ways, and an open edge has none."""

import numpy as np

from curved_reflections.engine.geometry.raytrace import NEAR_SURFACE, ReflectorSet
from curved_reflections.engine.geometry.sphere import icosphere
from curved_reflections.engine.geometry.triangle_grid import TriangleGrid, edge_neighbours
from curved_reflections.engine.scene import Reflector


def _distance_to_triangles(mirror, triangles, points):
    """Upper bound on each point's distance to its triangle: to the nearest of a fine
    barycentric lattice of the triangle."""
    weights = np.array([(i, j, 8 - i - j) for i in range(9) for j in range(9 - i)], dtype=np.float64) / 8
    corners = mirror.vertices[mirror.triangles[triangles]]  # (P, 3, 3)
    samples = np.einsum("sk,pkd->psd", weights, corners)
    return np.linalg.norm(samples - points[:, None], axis=2).min(axis=1)


def test_a_point_near_the_surface_finds_a_triangle_beside_it():
    mirror = ReflectorSet([icosphere((0.0, 0.0, 1.0), 1.0, 4, "Sphere")])
    grid = mirror.triangle_grid
    rng = np.random.default_rng(5)
    directions = rng.normal(size=(2000, 3))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    on_surface = np.array([0.0, 0.0, 1.0]) + directions
    found = grid.nearby(on_surface)
    assert (found >= 0).all()
    # Measured 0.05-0.09 radii at most; a cell is the median edge (0.06 radii) long, and
    # a triangle is registered in every cell a lattice sample of it falls in.
    assert _distance_to_triangles(mirror, found, on_surface).max() < 2.0 * grid.cell
    lifted = np.array([0.0, 0.0, 1.0]) + directions * (1.0 + 0.8 * NEAR_SURFACE * mirror.scale)
    assert (grid.nearby(lifted) >= 0).all()
    far = np.array([0.0, 0.0, 1.0]) + directions * 0.3  # deep inside
    assert (grid.nearby(far) < 0).all()
    assert (grid.nearby(np.array([[50.0, 0.0, 0.0], [np.nan, 0.0, 0.0]])) == -1).all()


def test_the_grid_is_bounded_by_its_cell_count():
    # Two tiny triangles far apart: cells of their edge's size would number 1e12.
    tiny = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.01, 0.0]])
    grid = TriangleGrid(np.concatenate([tiny, tiny + 100.0]), np.array([[0, 1, 2], [3, 4, 5]]), reach=1.0)
    assert max(grid.cells.shape) <= 128 + 2 * 3 + 2
    np.testing.assert_array_equal(grid.nearby(np.array([[0.003, 0.003, 0.0], [100.003, 100.003, 100.0],
                                                        [50.0, 50.0, 50.0]])), [0, 1, -1])


def test_edge_neighbours_share_their_edge_both_ways():
    mirror = ReflectorSet([icosphere((0.0, 0.0, 0.0), 1.0, 3, "Sphere")])
    across = mirror.edge_neighbours
    assert across.shape == (len(mirror.triangles), 3) and (across >= 0).all()  # closed
    welded = mirror.welded_triangles
    for k in range(3):
        edge = np.sort(welded[:, [(k + 1) % 3, (k + 2) % 3]], axis=1)
        other = welded[across[:, k]]
        shares = (other[:, :, None] == edge[:, None, :]).any(axis=1).all(axis=1)
        assert shares.all()
        assert (across[across[:, k]] == np.arange(len(welded))[:, None]).any(axis=1).all()


def test_an_open_edge_has_no_neighbour():
    # Two triangles of a square: one shared edge, four open ones.
    square = Reflector("Square", np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]]),
                       np.array([[0, 1, 2], [0, 2, 3]]), np.tile([0.0, 0.0, 1.0], (4, 1)))
    across = edge_neighbours(ReflectorSet([square]).welded_triangles)
    np.testing.assert_array_equal(across, [[-1, 1, -1], [-1, -1, 0]])
