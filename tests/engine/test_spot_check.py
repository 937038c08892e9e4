# SPDX-License-Identifier: GPL-3.0-or-later
"""The live accuracy check (engine/spot_check.py): a method's answers measured against
exactly traced rays, in pixels."""

import numpy as np
import pytest

from curved_reflections.engine import look_at_view
from curved_reflections.engine.reference.exact import solve_reflections
from curved_reflections.engine.geometry.raytrace import ReflectorSet
from curved_reflections.engine.spot_check import MAX_ERROR_PX, SpotCheck, spot_check
from curved_reflections.engine.geometry.sphere import icosphere

CENTRE = np.array([0.0, 0.0, 1.0])


@pytest.fixture(scope="module")
def case():
    mirror = icosphere(CENTRE, 1.0, 4, "Ball")
    reflector_set = ReflectorSet([mirror])
    view = look_at_view(CENTRE + np.array([2.5, -3.0, 1.2]), CENTRE, fov_y_deg=40.0, width=320, height=240)
    rng = np.random.default_rng(5)
    directions = rng.normal(size=(3000, 3))
    points = CENTRE + 2.0 * directions / np.linalg.norm(directions, axis=1, keepdims=True)
    exact = solve_reflections(reflector_set, view, points)
    exact = exact.select(exact.visible)
    answers = np.full((1, len(points), 3), np.nan)
    answers[0, exact.point] = exact.position
    return reflector_set, view, points, answers


def test_exact_answers_measure_zero(case):
    reflector_set, view, points, answers = case
    check = spot_check(reflector_set, view, 0, points, answers)
    assert check.checked == 96 and check.confirmed == 96
    assert check.percentile(95) < 0.02 and check.within(0.05)


def test_answers_moved_along_the_mirror_measure_how_far(case):
    """Answers moved across the mirror by a known number of pixels measure that many."""
    reflector_set, view, points, answers = case
    pixels, depth = view.to_pixels(answers[0])
    shifted = pixels + np.array([2.0, 0.0])
    origins, directions = view.pixel_rays(np.nan_to_num(shifted))
    hits = reflector_set.intersect(origins, directions)
    moved = np.where((hits.hit & np.isfinite(pixels[:, 0]))[:, None], origins + hits.t[:, None] * directions, np.nan)
    check = spot_check(reflector_set, view, 0, points, moved[None])
    assert check.confirmed >= 0.9 * check.checked > 50
    assert 1.9 < check.percentile(50) < 2.1
    assert not check.within(1.0) and check.within(2.5)
    assert check.summary().startswith("p95 2.")


def test_reflections_drawn_where_there_is_none_are_unconfirmed(case):
    """An answer far from any true reflection of its point does not converge within
    MAX_ERROR_PX: counted as unconfirmed, so it fails any accuracy."""
    reflector_set, view, points, answers = case
    rng = np.random.default_rng(9)
    valid = np.flatnonzero(np.isfinite(answers[0, :, 0]))
    wrong = answers.copy()
    wrong[0, valid] = answers[0, rng.permutation(valid)]  # each point answered with another point's image
    check = spot_check(reflector_set, view, 0, points, wrong)
    assert check.unconfirmed > 0.8 * check.checked
    assert not check.within(MAX_ERROR_PX)
    assert "more than 12 px off or not there" in check.summary()


def test_no_answer_nothing_checked(case):
    reflector_set, view, points, _ = case
    check = spot_check(reflector_set, view, 0, points, np.full((2, len(points), 3), np.nan))
    assert check == SpotCheck(0, check.errors) and not check.within(1.0)
    assert check.summary() == "no reflection to check in this view"
