# SPDX-License-Identifier: GPL-3.0-or-later
"""Seeds of a sample-based camera's answers past its rays (engine/methods/sbc/sbc_edges.py)."""

import numpy as np

from curved_reflections.engine import Reflector, look_at_view
from curved_reflections.engine.geometry.raytrace import ReflectorSet
from curved_reflections.tools.surfaces import rotation_z
from curved_reflections.engine.geometry.sphere import icosphere
from curved_reflections.engine.methods.sbc.raymap import trace_ray_map
from curved_reflections.engine.methods.sbc.sbc_edges import SeedRays, nearest_ray_seeds, sub_ray_seeds
from curved_reflections.engine.reference.true_rays import trace_history


def test_ring_seeds_come_closest_first():
    """Four parallel rays along +Y pass a point at 0.1, 0.3, 0.2 and 5 (too far): the
    seeds are the three near ones, nearest first, then none; a point behind every
    ray's tail gets none."""
    offsets = np.array([0.1, 0.3, 0.2, 5.0])
    seeds = SeedRays(cell=np.array([[10, 0], [30, 0], [20, 0], [50, 0]], dtype=float),
                     tail=np.c_[offsets, np.zeros(4), np.zeros(4)], direction=np.tile([0.0, 1.0, 0.0], (4, 1)),
                     tail_step=np.full(4, 0.25), direction_step=np.zeros(4))  # reach 3 x 0.25
    points = np.array([[0.0, 2.0, 0.0], [0.0, -1.0, 0.0]])
    cells, distance = nearest_ray_seeds(seeds, points, ranks=4)
    assert cells.shape == (2, 4, 2) and distance.shape == (2, 4)
    np.testing.assert_array_equal(cells[0, :3, 0], [10, 20, 30])
    np.testing.assert_allclose(distance[0, :3], 2.0)
    assert np.isnan(cells[0, 3]).all() and np.isnan(distance[1]).all()


def _low_wall_and_ball():
    """A ball before a low flat wall mirror turned -35 degrees (two triangles), seen so
    that the wall's reflection in the ball is a sliver along its rim."""
    turn = rotation_z(np.radians(-35.0))
    corners = np.array([[-1.0, -2.0, 0.0], [-1.0, 2.0, 0.0], [-1.0, 2.0, 2.0], [-1.0, -2.0, 2.0]]) @ turn.T
    wall = Reflector("Wall", corners, np.array([[0, 1, 2], [0, 2, 3]]), np.tile(turn[:, 0], (4, 1)))
    reflector_set = ReflectorSet([wall, icosphere((0.7, 0.3, 0.8), 0.7, 4, "Ball")])
    view = look_at_view((3.0, -3.5, 1.5), (-0.3, 0.2, 0.9), width=320, height=240, fov_y_deg=55.0)
    return reflector_set, view


def test_sub_rays_reach_between_and_past_the_ring_rays():
    """The wall seen in the ball's rim at d = 2: the sub-rays of the history ball -> wall
    are valid paths of it, with a spacing, and some lie in unit cells none of whose four
    rays reaches the wall (the sliver of footprint past its sampled rays)."""
    reflector_set, view = _low_wall_and_ball()
    bounds = (reflector_set.vertices.min(axis=0) - 2.0, reflector_set.vertices.max(axis=0) + 2.0)
    ray_map = trace_ray_map(reflector_set, view, bounds, 2, max_order=2)
    history = (1, 0)
    grid = ray_map.group_grid(ray_map.histories.index(history))
    first_order = ray_map.group_grid(ray_map.histories.index((1,)))
    seeds = sub_ray_seeds(reflector_set, ray_map, history, grid, first_order)
    assert len(seeds) > 100
    tail, direction, _, valid, _ = trace_history(reflector_set, view, history, ray_map.cell_pixels(seeds.cell))
    assert valid.all()
    np.testing.assert_allclose(tail, seeds.tail, atol=1e-9)
    np.testing.assert_allclose(direction, seeds.direction, atol=1e-9)
    assert (seeds.tail_step > 0).all() and (seeds.direction_step > 0).all()
    base = np.floor(seeds.cell).astype(int)
    corners = sum(grid[base[:, 1] + dj, base[:, 0] + di] >= 0 for di in (0, 1) for dj in (0, 1))
    assert (corners == 0).sum() >= 5, np.bincount(corners)
