# SPDX-License-Identifier: GPL-3.0-or-later
"""Rays through glass (engine/glass/paths.py) against closed forms: a slab's lateral
shift, a ball lens's focal length, total internal reflection inside a block."""

import numpy as np
import pytest

from curved_reflections.engine.errors import SceneInputError
from curved_reflections.engine.geometry.sphere import icosphere
from curved_reflections.engine.glass import Glass, GlassSet
from curved_reflections.tools.surfaces import flat_box


def test_a_slab_shifts_a_ray_sideways_by_the_closed_form_and_keeps_its_direction():
    """A slab of thickness t and index n shifts a ray at incidence theta by
    t sin(theta - theta') / cos(theta'), sin(theta) = n sin(theta'), and sends it on
    parallel to itself."""
    t, n = 0.4, 1.5
    glass = GlassSet([Glass(flat_box("Slab", (-20, -20, -t / 2), (20, 20, t / 2)), n)])
    theta = np.radians([0.0, 20.0, 45.0, 70.0])
    directions = np.stack([np.sin(theta), np.zeros(4), -np.cos(theta)], axis=1)
    origins = np.array([0.0, 0.0, 2.0]) - 2.0 * directions
    paths = glass.trace(origins, directions)
    assert paths.through_glass.all() and list(paths.interfaces) == [2] * 4 and not paths.total_reflections.any()
    assert np.allclose(paths.direction, directions, atol=1e-12) and np.all(paths.medium == -1)
    shift = np.linalg.norm(np.cross(paths.origin - origins, directions), axis=1)
    theta_t = np.arcsin(np.sin(theta) / n)
    assert np.allclose(shift, t * np.sin(theta - theta_t) / np.cos(theta_t), atol=1e-9)


def test_a_glass_ball_focuses_paraxial_rays_at_its_focal_length():
    """A ball lens of radius R and index n brings parallel rays near its axis to a focus
    n R / (2 (n - 1)) from its centre (1.5 R for n = 1.5). On a mesh (icosphere, 20k
    triangles, interpolated normals) within 1 %."""
    glass = GlassSet([Glass(icosphere((0.0, 0.0, 0.0), 1.0, 5, "Ball"), 1.5)])
    heights = np.array([0.02, 0.04, -0.03])
    origins = np.stack([heights, np.zeros(3), np.full(3, 4.0)], axis=1)
    paths = glass.trace(origins, np.tile([0.0, 0.0, -1.0], (3, 1)))
    assert paths.through_glass.all() and list(paths.interfaces) == [2] * 3
    t = -paths.origin[:, 0] / paths.direction[:, 0]
    focus = -(paths.origin[:, 2] + t * paths.direction[:, 2])
    assert np.allclose(focus, 1.5 / (2.0 * 0.5), rtol=0.01)


def test_total_internal_reflection_inside_a_block_reflects_the_ray_and_lets_it_out_below():
    """Entering a cube's top at 80 degrees, the ray meets its side at 49 degrees, past the
    critical angle (41.8): it is reflected there, then leaves through the bottom, going
    on as the incoming ray mirrored in the side."""
    glass = GlassSet([Glass(flat_box("Block", (-1, -1, -1), (1, 1, 1)), 1.5)])
    theta = np.radians(80.0)
    direction = np.array([[np.sin(theta), 0.0, -np.cos(theta)]])
    paths = glass.trace(np.array([[0.2, 0.0, 1.0]]) - 3.0 * direction, direction)
    assert paths.through_glass[0] and paths.total_reflections[0] == 1 and paths.interfaces[0] == 3
    assert np.allclose(paths.direction[0], direction[0] * (-1.0, 1.0, 1.0), atol=1e-12)
    assert paths.origin[0, 2] < -0.99


def test_glass_in_glass_is_marked_and_a_bad_index_names_the_object():
    outer = Glass(icosphere((0.0, 0.0, 0.0), 1.0, 3, "Outer"), 1.5)
    inner = Glass(icosphere((0.0, 0.0, 0.0), 0.4, 3, "Inner"), 1.33)
    paths = GlassSet([outer, inner]).trace(np.array([[0.05, 0.0, 3.0], [0.9, 0.0, 3.0]]),
                                            np.tile([0.0, 0.0, -1.0], (2, 1)))
    assert list(paths.nested) == [True, False] and list(paths.interfaces) == [4, 2]
    with pytest.raises(SceneInputError, match="Lens.*index of refraction of 0.0"):
        Glass(icosphere((0.0, 0.0, 0.0), 1.0, 1, "Lens"), 0.0)


def test_rays_started_near_where_they_meet_the_glass_follow_the_same_paths():
    """Given roughly where each ray meets the glass first (a pre-pass's float depth; some
    unknown), the paths are those found by the BVH alone."""
    glass = GlassSet([Glass(icosphere((0.0, 0.0, 0.0), 1.0, 4, "Ball"), 1.5)])
    rng = np.random.default_rng(5)
    origins = np.c_[rng.uniform(-0.9, 0.9, (200, 2)), np.full(200, 4.0)]
    directions = np.tile([0.0, 0.0, -1.0], (200, 1))
    alone = glass.trace(origins, directions)
    near = alone.first_position + rng.normal(scale=1e-4, size=(200, 3))
    near[::7] = np.nan
    guided = glass.trace(origins, directions, near_surface=near)
    assert 100 < alone.through_glass.sum() < 200  # some miss the ball: no glass to start near
    np.testing.assert_allclose(guided.origin, alone.origin)
    np.testing.assert_allclose(guided.direction, alone.direction)
