# SPDX-License-Identifier: GPL-3.0-or-later
"""Per-sheet bounds for culling (engine/methods/sbc/sheet_bounds.py): conservative, never dropping a
point that projects in the sheet (SBC paper, Popescu, Sacks, Mei 2006, section V-A)."""

import numpy as np

from curved_reflections.engine import look_at_view
from curved_reflections.engine.methods.sbc import build_sample_based_camera
from curved_reflections.engine.methods.sbc import sheet_bounds
from curved_reflections.engine.methods.sbc.ray_cones import in_cones
from curved_reflections.engine.geometry.sphere import icosphere


def test_morton_runs_are_chunks_whose_boxes_hold_their_points():
    points = np.random.default_rng(3).random((1000, 3)) * [4.0, 2.0, 1.0]
    order = sheet_bounds.morton_order(points)
    assert sorted(order.tolist()) == list(range(1000))
    lo, hi = sheet_bounds.chunk_boxes(points[order], 64)
    assert len(lo) == 16
    chunk = np.arange(1000) // 64
    assert np.all(points[order] >= lo[chunk]) and np.all(points[order] <= hi[chunk])
    # Sorted along the curve, runs are compact: far smaller boxes than runs in input order.
    shuffled_lo, shuffled_hi = sheet_bounds.chunk_boxes(points, 64)
    assert np.prod(hi - lo, axis=1).mean() < 0.2 * np.prod(shuffled_hi - shuffled_lo, axis=1).mean()


def test_a_box_holding_a_point_of_the_cone_is_kept():
    rng = np.random.default_rng(5)
    axis = np.array([1.0, 2.0, 0.5]) / np.linalg.norm([1.0, 2.0, 0.5])
    cone = np.r_[[0.5, -0.2, 0.1], axis, 0.3, 0.25, -0.5]
    points = rng.uniform(-6, 6, (20000, 3))
    inside = in_cones(np.broadcast_to(cone, (len(points), 9)), points)
    assert 100 < inside.sum() < len(points) - 100
    lo = points - rng.uniform(0, 0.5, points.shape)
    hi = points + rng.uniform(0, 0.5, points.shape)
    kept = sheet_bounds.chunks_in_cone(lo, hi, cone)
    assert kept[inside].all()
    assert not kept.all()  # and boxes far from it are dropped


def test_every_point_that_projects_in_a_sheet_lies_in_its_kdop():
    mirror = icosphere((0.0, 0.0, 0.0), 1.0, 3, name="Mirror")
    view = look_at_view((0.0, -5.0, 1.0), (0.0, 0.0, 0.0), fov_y_deg=30.0, width=64, height=48)
    bounds = (np.array([-4.0, -6.0, -4.0]), np.array([4.0, 4.0, 4.0]))
    sbc = build_sample_based_camera([mirror], view, bounds, downsample=2)
    diameter = float(np.linalg.norm(bounds[1] - bounds[0]))
    kdops = sheet_bounds.sheet_kdops(sbc, diameter)
    points = np.random.default_rng(7).uniform(bounds[0], bounds[1], (20000, 3))
    projected = sbc.project(points)
    assert projected.valid.sum() > 1000
    slabs = points @ sheet_bounds.DIRECTIONS.T
    for sheet in range(len(sbc.groups)):
        valid = projected.valid[sheet]
        inside = np.all((slabs >= kdops[sheet, :, 0]) & (slabs <= kdops[sheet, :, 1]), axis=1)
        assert inside[valid].all()
        lo, hi = points - 1e-9, points + 1e-9
        assert sheet_bounds.chunks_meeting(lo[valid], hi[valid], kdops[sheet]).all()
        if sbc.cones is not None:
            assert sheet_bounds.chunks_in_cone(lo[valid], hi[valid], sbc.cones[sheet]).all()
