# SPDX-License-Identifier: GPL-3.0-or-later
"""The blend's local surface (``addon/methods/morphing/morph_surface.py``): a quadric
fitted to the nodes' images is exact on quadric mirrors, where the quadratic height field
it extends erred, and its slopes are the derivatives of its height."""

import numpy as np

from curved_reflections.addon.geometry.sphere import sphere_reflection
from curved_reflections.addon.methods.morphing import morph_surface


def _sphere_case(rng, count=400):
    """Four node eyes a grid cell apart (0.75 x 0.75 x 1.5, as the default grid's
    spacing around a unit sphere), a desired eye among them, points around: the nodes'
    exact images, the eye's exact reflection points, and the eye's weights."""
    nodes = np.array([[0.0, -1.5, 0.4], [0.75, -1.5, 0.4], [0.0, -2.25, 0.4], [0.0, -1.5, 1.9]])
    weights = np.array([0.4, 0.3, 0.2, 0.1])
    eye = weights @ nodes
    points = rng.uniform([-2.5, -2.5, -1.0], [2.5, 0.5, 2.5], (count, 3))
    points = points[np.linalg.norm(points, axis=1) > 1.3]
    images, seen = zip(*(sphere_reflection((0, 0, 0), 1.0, node, points) for node in nodes))
    truth, truth_seen = sphere_reflection((0, 0, 0), 1.0, eye, points)
    keep = np.all(seen, axis=0) & truth_seen
    return (np.stack(images, axis=1)[keep], nodes, points[keep], eye,
            np.tile(weights, (keep.sum(), 1)), truth[keep])


def _refined_with_ridge(ridge, images, nodes, points, eye, weights):
    """refine_on_local_surface with the quadric's three terms held by ``ridge``."""
    saved = morph_surface.FIT_RIDGE.copy()
    try:
        morph_surface.FIT_RIDGE[6:] = ridge
        refined, ok, _, _ = morph_surface.refine_on_local_surface(images, np.ones(weights.shape, bool), nodes,
                                                                  points, eye, weights)
    finally:
        morph_surface.FIT_RIDGE[:] = saved
    return refined, ok


def test_quadric_fit_finds_the_exact_reflection_on_a_sphere():
    images, nodes, points, eye, weights, truth = _sphere_case(np.random.default_rng(5))
    present = np.ones(weights.shape, bool)
    refined, ok, normal, _ = morph_surface.refine_on_local_surface(images, present, nodes, points, eye, weights)
    error = np.linalg.norm(refined - truth, axis=1)[ok]
    assert ok.mean() > 0.95 and len(error) > 150
    # QUADRIC_RIDGE's pull (it serves noisy images) leaves about 1e-3 of the radius here,
    # a fifth of a pixel seen from half a radius at 400 px per unit angle.
    assert np.percentile(error, 99) < 2e-3
    np.testing.assert_allclose(normal[ok], refined[ok], atol=1e-2)  # the sphere's normal is radial
    # Unpinned, the fit is exact; the blend alone, and the quadratic height field (the
    # three terms pinned to zero), are far off.
    free, ok_free = _refined_with_ridge(1e-10, images, nodes, points, eye, weights)
    free_error = np.percentile(np.linalg.norm(free - truth, axis=1)[ok_free], 99)
    assert free_error < 1e-4
    blend = np.einsum("qn,qnd->qd", weights, images)
    assert np.percentile(np.linalg.norm(blend - truth, axis=1), 50) > 1e-2
    quadratic, ok_quadratic = _refined_with_ridge(1e12, images, nodes, points, eye, weights)
    assert np.percentile(np.linalg.norm(quadratic - truth, axis=1)[ok_quadratic], 99) > 10 * free_error


def test_quadric_height_slopes_are_its_derivatives():
    rng = np.random.default_rng(2)
    c = rng.normal(scale=0.1, size=(50, 9))  # away from the root's branch point (B^2 = 4 c6 q)
    u, v = rng.uniform(-1, 1, 50), rng.uniform(-1, 1, 50)
    height, du, dv = morph_surface.quadric_height(c, u, v)
    step = 1e-6
    np.testing.assert_allclose(du, (morph_surface.quadric_height(c, u + step, v)[0] - height) / step, atol=1e-4)
    np.testing.assert_allclose(dv, (morph_surface.quadric_height(c, u, v + step)[0] - height) / step, atol=1e-4)
    quadratic = c[:, 0] + c[:, 1] * u + c[:, 2] * v + 0.5 * c[:, 3] * u * u + c[:, 4] * u * v + 0.5 * c[:, 5] * v * v
    # The height solves h = q + c6 h^2 + c7 u h + c8 v h.
    np.testing.assert_allclose(height, quadratic + c[:, 6] * height ** 2 + (c[:, 7] * u + c[:, 8] * v) * height,
                               atol=1e-12)
