# SPDX-License-Identifier: GPL-3.0-or-later
"""The Taylor step from a seed path to a target (engine/methods/perturbation/taylor_step.py,
Chen & Arvo 2000 eq. 4): what it gives where the answer is known, and the steps it does
not trust. Its accuracy over whole views is measured in test_perturbation.py."""

import numpy as np

from curved_reflections.engine.geometry.raytrace import ReflectorSet
from curved_reflections.tools.surfaces import ellipsoid
from curved_reflections.engine.methods.perturbation import AnalyticSurface, trace_seed_paths
from curved_reflections.engine.methods.perturbation.seeds import seed_quadrics
from curved_reflections.engine.methods.perturbation.taylor_step import first_order_pixels, taylor_step
from curved_reflections.engine.view import look_at_view

CENTRE = np.array([-0.4, 0.3, 0.2])
RADII = (0.9, 1.3, 0.6)


def _seeds():
    placed = np.eye(4)
    placed[:3, 3] = CENTRE
    surfaces = {0: AnalyticSurface("Egg", "ELLIPSOID", placed, RADII)}
    reflector_set = ReflectorSet([ellipsoid(CENTRE, RADII, 4, name="Egg")])
    view = look_at_view((-3.0, -3.2, 1.9), CENTRE, fov_y_deg=45.0, width=240, height=180)
    seeds = trace_seed_paths(reflector_set, view, view.pixel_grid(8), 1, surfaces)[0]
    return view, seeds, seed_quadrics(reflector_set, seeds, surfaces)


def test_a_target_on_its_seeds_reflected_ray_is_seen_where_the_seed_is():
    view, seeds, quadrics = _seeds()
    seed_of = np.arange(len(seeds.pixels))
    assert len(seed_of) > 20
    targets = seeds.points[:, -1] + 0.5 * seeds.outgoing
    first, last, estimate, pixel = taylor_step(view, seeds, quadrics, targets, seed_of, np.zeros(len(seed_of)), 1e9)
    np.testing.assert_allclose(pixel, seeds.pixels, atol=1e-6)
    np.testing.assert_allclose(first, seeds.points[:, 0], atol=1e-9)
    np.testing.assert_allclose(last, first, atol=1e-12)  # first order: one bounce
    assert (estimate < 1e-6).all()
    np.testing.assert_allclose(first_order_pixels(view, seeds, quadrics, targets, seed_of), seeds.pixels, atol=1e-6)


def test_a_step_to_a_point_inside_the_mirror_or_beyond_its_reach_is_not_trusted():
    view, seeds, quadrics = _seeds()
    seed_of = np.arange(len(seeds.pixels))
    inside = np.broadcast_to(CENTRE, (len(seed_of), 3))
    _, _, estimate, _ = taylor_step(view, seeds, quadrics, inside, seed_of, np.zeros(len(seed_of)), 1e9)
    assert np.isinf(estimate).all()  # its path would arrive from behind the surface
    # A little off the ray, the step is good, but not when it may move the image by no pixel.
    near = seeds.points[:, -1] + 0.5 * seeds.outgoing + 0.02
    _, _, free, _ = taylor_step(view, seeds, quadrics, near, seed_of, np.zeros(len(seed_of)), 1e9)
    _, _, held, _ = taylor_step(view, seeds, quadrics, near, seed_of, np.zeros(len(seed_of)), 1e-3)
    assert np.isfinite(free).mean() > 0.9 and np.isinf(held).all()
