# SPDX-License-Identifier: GPL-3.0-or-later
"""The blend's local surface (``engine/methods/morphing/morph_surface.py``): a quadric
fitted to the nodes' images is exact on quadric mirrors, where the quadratic height field
it extends erred, and its slopes are the derivatives of its height."""

import numpy as np
import pytest

from curved_reflections.tools.surfaces import sphere_reflection
from curved_reflections.engine.methods.morphing import morph_surface


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


def _refined_with_penalty(penalty, images, nodes, points, eye, weights):
    """refine_on_local_surface with ``penalty`` (9, 9) added to the fit's normal equations."""
    refined, ok, _, _ = morph_surface.refine_on_local_surface(images, np.ones(weights.shape, bool), nodes,
                                                              points, eye, weights, penalty)
    return refined, ok


def _error_p99(refined, ok, truth):
    return np.percentile(np.linalg.norm(refined - truth, axis=1)[ok], 99)


def test_quadric_fit_finds_the_exact_reflection_on_a_sphere():
    images, nodes, points, eye, weights, truth = _sphere_case(np.random.default_rng(5))
    present = np.ones(weights.shape, bool)
    refined, ok, normal, _ = morph_surface.refine_on_local_surface(images, present, nodes, points, eye, weights)
    assert ok.mean() > 0.95 and ok.sum() > 150
    # The default pulls the quadric's three terms toward a sphere, which a sphere meets:
    # exact, as unheld.
    assert _error_p99(refined, ok, truth) < 1e-4
    np.testing.assert_allclose(normal[ok], refined[ok], atol=1e-2)  # the sphere's normal is radial
    free = _refined_with_penalty(1e-10 * np.eye(9), images, nodes, points, eye, weights)
    assert _error_p99(*free, truth) < 1e-4
    # The blend alone is far off; the quadratic height field (the three terms pinned to
    # zero) is 10x off, and a pull toward zero of the default's weight about 1e-3 of the
    # radius (the pull that biased close views by 1.5 px on bench_morphing.py's ball).
    blend = np.einsum("qn,qnd->qd", weights, images)
    assert np.percentile(np.linalg.norm(blend - truth, axis=1), 50) > 1e-2
    quadratic = _refined_with_penalty(np.diag([1e-10] * 6 + [1e12] * 3), images, nodes, points, eye, weights)
    assert _error_p99(*quadratic, truth) > 1e-3
    toward_zero = _refined_with_penalty(np.diag([1e-10] * 6 + [morph_surface.QUADRIC_RIDGE] * 3), images, nodes,
                                        points, eye, weights)
    assert _error_p99(*toward_zero, truth) > 5e-4


def test_sphere_prior_penalises_only_what_a_sphere_is_not():
    """c6 - (c3 + c5) / 4, c7 and c8 are zero for every sphere in any frame; the penalty
    of any coefficients is that weight times their squares."""
    penalty = morph_surface.sphere_prior(2.0)
    sphere_like = np.array([0.3, -0.2, 0.1, 0.8, 0.0, 0.8, 0.4, 0.0, 0.0])
    assert sphere_like @ penalty @ sphere_like == pytest.approx(1e-10 * sphere_like @ sphere_like, abs=1e-12)
    flattened = sphere_like * np.array([1, 1, 1, 1, 1, 1, 0, 1, 1])  # the paraboloid: c6 = 0
    assert flattened @ penalty @ flattened == pytest.approx(2.0 * 0.4 ** 2, rel=1e-6)
    tilted = sphere_like + np.array([0, 0, 0, 0, 0, 0, 0, 0.3, 0])
    assert tilted @ penalty @ tilted == pytest.approx(2.0 * 0.3 ** 2, rel=1e-6)
    np.testing.assert_allclose(penalty, penalty.T)


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
