# SPDX-License-Identifier: GPL-3.0-or-later
"""BSP construction details: focal distances of the ray field and depth bands of camera leaves."""

import numpy as np

from curved_reflections.engine import look_at_view
from curved_reflections.engine.geometry.raytrace import ReflectorSet
from curved_reflections.engine.methods.sbc.bsp import _band_ends, focal_distances
from curved_reflections.engine.methods.sbc.raymap import trace_ray_map

from test_sbc import _bowl, ellipsoid


def _ray_map(reflector, view, bounds):
    """The ray map a camera at down-sampling 2 is built on (``build_sample_based_camera``
    traces it first; the camera's trees and traced cells are not needed here)."""
    ray_map = trace_ray_map(ReflectorSet([reflector]), view, bounds, 2, 1)
    return ray_map, ray_map.group_grid(0)


def test_a_bowl_seen_from_its_centre_focuses_every_ray_at_its_radius():
    """Every ray reflected by a sphere back toward the eye at its centre passes through the
    centre: both focal distances are the radius (1.5)."""
    ray_map, grid = _ray_map(_bowl(radius=1.5), look_at_view([0, 0, 0], [0, 1, 0], width=160, height=120,
                                                             fov_y_deg=60), (np.full(3, -2.0), np.full(3, 2.0)))
    focal = focal_distances(ray_map, grid, np.arange(ray_map.n_rays))
    complete = np.isfinite(focal).all(axis=1)
    assert complete.sum() > 0.9 * ray_map.n_rays
    np.testing.assert_allclose(focal[complete], 1.5, rtol=1e-3)
    # Rays at the edge of the footprint lack a neighbour: no estimate there.
    assert np.isnan(focal[~complete]).all()


def test_a_convex_mirror_focuses_behind_itself():
    reflector = ellipsoid(np.array([0.3, 0.2, 1.1]), [1.3, 0.8, 1.0])
    view = look_at_view([4.5, -3.5, 2.8], [0.3, 0.2, 1.0], width=160, height=120, fov_y_deg=38)
    ray_map, grid = _ray_map(reflector, view, (np.array([-4.0, -4.0, -1.0]), np.array([4.0, 4.0, 4.0])))
    focal = focal_distances(ray_map, grid, np.arange(ray_map.n_rays))
    finite = focal[np.isfinite(focal)]
    assert len(finite) > 0.8 * 2 * ray_map.n_rays and (finite < 0).all()


def test_a_band_runs_between_the_passing_samples_around_every_failing_one():
    fractions = np.array([0.0, 0.1, 0.2, 0.3, 0.4, 0.0, 0.1, 0.2, 0.3, 0.0, 0.1, 0.0, 0.1])
    node = np.array([0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 3, 3])
    good = np.array([1, 1, 0, 1, 0, 1, 1, 0, 0, 0, 1, 1, 1], dtype=bool)
    # Shuffled: the order of the samples does not matter.
    order = np.random.default_rng(3).permutation(len(node))
    low, high = _band_ends(node[order], fractions[order], good[order], 4)
    np.testing.assert_array_equal(low[:3], [0.1, 0.1, -np.inf])
    np.testing.assert_array_equal(high[:3], [np.inf, np.inf, 0.1])
    # Node 0 passes at 0.3 but fails on both sides of it: the band holds 0.3 too.
    assert np.isnan(low[3]) and np.isnan(high[3])  # nothing fails: no band
