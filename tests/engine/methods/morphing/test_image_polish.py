# SPDX-License-Identifier: GPL-3.0-or-later
"""A node's images polished on the mirror (``engine/methods/morphing/image_polish.py``):
they land on the reference solver's reflection points, images with no reflection near
them are dropped, and only grazing regular images are touched."""

import numpy as np
import pytest

from curved_reflections.engine.methods.morphing import image_polish as P

CENTRE = np.array([0.0, 0.0, 1.0])
EYE = np.array([0.3, -3.0, 1.6])


@pytest.fixture(scope="module")
def case(sphere_reflections):
    """The sphere mesh, points around it and their exact reflection points seen from EYE."""
    assert np.array_equal(sphere_reflections.eye, EYE) and np.array_equal(sphere_reflections.centre, CENTRE)
    return sphere_reflections.mirror, sphere_reflections.points, sphere_reflections.truth


def _cosines(truth):
    """Cosine of each exact reflection's angle to the eye (the sphere's normal is radial)."""
    to_eye = EYE - truth
    normal = (truth - CENTRE) / np.linalg.norm(truth - CENTRE, axis=1)[:, None]
    return np.einsum("pd,pd->p", normal, to_eye) / np.linalg.norm(to_eye, axis=1)


def test_images_near_a_reflection_land_on_the_reference_solvers(case):
    mirror, points, truth = case
    has = np.isfinite(truth[:, 0])
    assert has.sum() > 200
    # Off by up to 0.05 radii, as the widened charts extrapolate (0.07 at p99 on the demo ball).
    rough = truth + np.random.default_rng(2).uniform(-0.05, 0.05, truth.shape)
    polished = P.polish_images(mirror, EYE, points, rough[:, None])[:, 0]
    placed = np.isfinite(polished[:, 0])
    assert not placed[~has].any()
    np.testing.assert_allclose(polished[placed], truth[placed], atol=1e-8)
    # Measured: all but 4 of 450, seen 75-82 degrees off the normal, whose Newton left
    # for a triangle beyond the ring it can reach.
    assert placed[has & (_cosines(truth) > 0.3)].all()
    assert placed[has].mean() > 0.98


def test_an_image_past_the_horizon_is_dropped(case):
    mirror, _, _ = case
    # A point right behind the sphere seen from EYE has no reflection; an image on the
    # far rim, as an extrapolated chart would give, finds none to polish to.
    behind = CENTRE + (CENTRE - EYE) / np.linalg.norm(CENTRE - EYE) * 2.0
    rim = CENTRE + np.cross(CENTRE - EYE, [0.0, 0.0, 1.0]) / np.linalg.norm(np.cross(CENTRE - EYE, [0.0, 0.0, 1.0]))
    polished = P.polish_images(mirror, EYE, behind[None], rim[None, None])
    assert np.isnan(polished).all()


def test_every_regular_image_is_polished_and_kept_where_no_polish_lands(case):
    mirror, points, truth = case
    has = np.flatnonzero(np.isfinite(truth[:, 0]))
    rough = truth[has] + np.random.default_rng(3).uniform(-0.01, 0.01, (len(has), 3))
    cosine = _cosines(truth[has])
    assert (cosine > 0.6).sum() > 50 and (cosine < 0.4).sum() > 20  # facing and grazing both
    polished = P.polish_regular(mirror, EYE, points[has], rough[:, None])[:, 0]
    np.testing.assert_allclose(polished, truth[has], atol=1e-8)
    # A polish that places nothing leaves the camera's images as they were.
    untouched = P.polish_regular(mirror, EYE, points[has], rough[:, None],
                                 polish=lambda m, e, p, images: np.full(images.shape, np.nan))[:, 0]
    np.testing.assert_array_equal(untouched, rough)
