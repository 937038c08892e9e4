# SPDX-License-Identifier: GPL-3.0-or-later
"""Bounding cones of a group's rays (engine/methods/sbc/ray_cones.py): conservative, they
hold every point along their rays, also past the heads; how much projection they skip
is measured in test_sbc.py (``test_bounding_cones_skip_work_but_change_no_answer``)."""

import numpy as np

from curved_reflections.engine import look_at_view
from curved_reflections.engine.geometry.sphere import icosphere
from curved_reflections.engine.methods.sbc import build_sample_based_camera
from curved_reflections.engine.methods.sbc.ray_cones import CONE_SIZE, in_cones, ray_cones, reachable_rays


def test_a_cone_holds_its_rays_from_tail_to_past_the_head_and_nothing_far_back_against_them():
    view = look_at_view([0.0, -5.0, 1.5], [0.0, 0.0, 1.0], width=96, height=72, fov_y_deg=40)
    bounds = (np.array([-4.0, -4.0, -1.0]), np.array([4.0, 4.0, 4.0]))
    ray_map = build_sample_based_camera([icosphere([0.0, 0.0, 1.0], 1.0, 3)], view, bounds, downsample=2).ray_map
    grid = ray_map.group_grid(0)
    rays = grid[grid >= 0]
    # Nodes of 4 x 4 cells, as small leaves are: a convex mirror's rays fan out, and a
    # node of half its footprint spans more than a cone can bound.
    block = ray_map.cell[rays] // 4
    _, node = np.unique(block[:, 0] * 10_000 + block[:, 1], return_inverse=True)
    n = int(node.max()) + 1
    member_ray, member_node = reachable_rays(ray_map, grid, rays, node, n)
    assert set(rays) <= set(member_ray)
    cones = ray_cones(ray_map, grid, member_ray, member_node, n)
    bounded = np.isfinite(cones[:, 6])
    assert cones.shape == (n, CONE_SIZE) and bounded.mean() > 0.9
    for s in (0.0, 0.5, 1.0, 3.0):  # shares of the head distance: the tail ... past the head
        along = (s * ray_map.head_distance[member_ray])[:, None] * ray_map.direction[member_ray]
        assert in_cones(cones[member_node], ray_map.tail[member_ray] + along).all()
    # Far back against its axis (the rays' mean direction) a bounded cone holds nothing.
    apex, axis = cones[bounded, 0:3], cones[bounded, 3:6]
    assert not in_cones(cones[bounded], apex - 100.0 * axis).any()
