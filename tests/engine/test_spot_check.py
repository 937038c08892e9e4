# SPDX-License-Identifier: GPL-3.0-or-later
"""The live accuracy check (engine/spot_check.py): a method's answers measured against
exactly traced rays, in pixels."""

import numpy as np
import pytest

from curved_reflections.engine import look_at_view
from curved_reflections.engine.reference.exact import solve_reflections
from curved_reflections.engine.geometry.raytrace import ReflectorSet
from curved_reflections.engine.spot_check import (COVERED_PX, MAX_ERROR_PX, MAX_MISSED_SHARE, SpotCheck, coverage_check,
                                                   near_outline,
                                                  shown_answers, spot_check)
from curved_reflections.engine.geometry.sphere import bumpy_icosphere, icosphere

CENTRE = np.array([0.0, 0.0, 1.0])


@pytest.fixture(scope="module")
def case():
    mirror = icosphere(CENTRE, 1.0, 4, "Ball")
    reflector_set = ReflectorSet([mirror])
    view = look_at_view(CENTRE + np.array([2.5, -3.0, 1.2]), CENTRE, fov_y_deg=40.0, width=320, height=240)
    rng = np.random.default_rng(5)
    directions = rng.normal(size=(1500, 3))  # 1269 answered; 96 checked, 70 exact images sampled
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


def test_no_answer_nothing_checked_and_every_exact_image_missed(case):
    """No answer drawn: nothing to check, so the answers alone pass; the exact images
    they leave out fail the method."""
    reflector_set, view, points, _ = case
    silent = np.full((2, len(points), 3), np.nan)
    check = spot_check(reflector_set, view, 0, points, silent)
    assert check == SpotCheck(0, check.errors) and check.within(1.0)
    assert check.summary() == "no reflection to check in this view"
    coverage = coverage_check(reflector_set, view, 0, points, silent)
    assert coverage.images > 60 and coverage.missed == coverage.images
    covered = check.with_coverage(coverage)
    assert not covered.within(1.0)
    assert covered.shortfall() == f"{coverage.images} of {coverage.images} exact images not drawn"
    # A view where the mirror shows no point at all: nothing to judge, nothing failed.
    assert SpotCheck(0, np.zeros(0), images=0, missed=0).within(1.0)


def test_every_exact_image_drawn_misses_none(case):
    reflector_set, view, points, answers = case
    coverage = coverage_check(reflector_set, view, 0, points, answers)
    assert coverage.images > 60 and coverage.missed == 0 and coverage.group == -1


@pytest.fixture(scope="module")
def folded():
    """A ball with bumps of 15 % of its radius: nearly half the points around it are seen
    two or more times; answers[k] holds each point's k-th exact image."""
    mirror = bumpy_icosphere(CENTRE, 1.0, 4, 0.15, name="Bumpy")
    reflector_set = ReflectorSet([mirror])
    view = look_at_view(CENTRE + np.array([2.5, -3.0, 1.2]), CENTRE, fov_y_deg=40.0, width=320, height=240)
    directions = np.random.default_rng(5).normal(size=(400, 3))
    points = CENTRE + 2.0 * directions / np.linalg.norm(directions, axis=1, keepdims=True)
    exact = solve_reflections(reflector_set, view, points)
    exact = exact.select(exact.visible)
    exact = exact.select(np.argsort(exact.point, kind="stable"))
    slot = np.concatenate([np.arange(n) for n in np.bincount(exact.point, minlength=len(points))])
    answers = np.full((slot.max() + 1, len(points), 3), np.nan)
    answers[slot, exact.point] = exact.position
    return reflector_set, view, points, answers


def test_one_image_per_point_of_a_folded_mirror_is_counted_as_missing_the_others(folded):
    """The iterative search's failure on a folded mirror: every drawn answer exact (the
    spot check alone passes it), but a point's second and third images are not drawn."""
    reflector_set, view, points, answers = folded
    assert (np.isfinite(answers[1, :, 0])).sum() > 0.3 * np.isfinite(answers[0, :, 0]).sum()
    first_only = answers[:1]
    coverage = coverage_check(reflector_set, view, 0, points, first_only)
    images, missed = coverage.images, coverage.missed
    assert images > 100 and 0.3 * images < missed < 0.7 * images
    check = spot_check(reflector_set, view, 0, points, first_only)
    assert check.within(0.05)  # every answer drawn is right ...
    check = check.with_coverage(coverage)
    assert not check.within(0.05)  # ... but the mirror is not drawn right
    assert f"; {missed} of {images} exact images not drawn" in check.summary()
    assert coverage_check(reflector_set, view, 0, points, answers).missed == 0 and coverage.group == -1


def test_an_answer_far_from_the_missing_image_does_not_cover_it(folded):
    reflector_set, view, points, answers = folded
    shifted = answers.copy()
    pixels, _ = view.to_pixels(answers[1])
    moved = pixels + np.array([2.0 * COVERED_PX, 0.0])  # each second image drawn twice too far
    origins, directions = view.pixel_rays(np.nan_to_num(moved))
    hits = reflector_set.intersect(origins, directions)
    shifted[1] = np.where((hits.hit & np.isfinite(moved[:, 0]))[:, None], origins + hits.t[:, None] * directions,
                          np.nan)
    dropped = answers.copy()
    dropped[1] = np.nan
    missing = coverage_check(reflector_set, view, 0, points, dropped).missed
    assert missing > 20 and coverage_check(reflector_set, view, 0, points, shifted).missed >= 0.8 * missing


def test_answers_the_renderer_would_not_show_are_not_checked(case):
    """Answers on the ball's far side (hidden behind its front, which the fragment stage's
    hidden-point test drops), answers whose law of reflection fails at the pixel (dropped
    too), and answers off the image are left out, the exact ones kept."""
    reflector_set, view, points, answers = case
    hidden_fraction, cosine = 0.003, np.cos(np.radians(20.0))
    shown = shown_answers(reflector_set, view, 0, points, answers, cosine, hidden_fraction)
    assert np.array_equal(np.isfinite(shown), np.isfinite(answers))
    far_side = 2.0 * CENTRE - answers  # the antipode of each answer
    assert not np.isfinite(shown_answers(reflector_set, view, 0, points, far_side, cosine, hidden_fraction)).any()
    swapped = answers.copy()
    valid = np.flatnonzero(np.isfinite(answers[0, :, 0]))
    swapped[0, valid] = answers[0, np.roll(valid, len(valid) // 2)]  # another point's image: the law fails
    kept = np.isfinite(shown_answers(reflector_set, view, 0, points, swapped, cosine, hidden_fraction)[0, valid, 0])
    assert kept.mean() < 0.1
    aside = look_at_view(view.eye, CENTRE + np.array([0.0, 0.0, 1.6]), fov_y_deg=40.0, width=320, height=240)
    pixels, _ = aside.to_pixels(answers[0, valid])
    inside = ((pixels >= 0) & (pixels <= (320, 240))).all(axis=1)
    assert 0.2 < inside.mean() < 0.8  # the ball half out of the image
    off = shown_answers(reflector_set, aside, 0, points, answers, cosine, hidden_fraction)
    assert np.array_equal(np.isfinite(off[0, valid, 0]), inside)
    assert spot_check(reflector_set, aside, 0, points, answers).checked == 96
    assert spot_check(reflector_set, aside, 0, points, answers).unconfirmed == 0


def test_one_object_whose_images_are_left_out_fails_however_small(folded):
    """Grouped by object, a method that misses the images of one small object (here
    every second image of the 15 points of group 1) is found there,
    where the whole sample's share would pass it."""
    reflector_set, view, points, answers = folded
    groups = np.zeros(len(points), np.int64)
    seen_twice = np.flatnonzero(np.isfinite(answers[1, :, 0]))
    groups[seen_twice[:15]] = 1
    groups[-40:] = 2
    wrong = answers.copy()
    wrong[1:, groups == 1] = np.nan
    ungrouped = coverage_check(reflector_set, view, 0, points, wrong, sample=96)
    assert ungrouped.group == -1 and ungrouped.missed <= MAX_MISSED_SHARE * ungrouped.images
    grouped = coverage_check(reflector_set, view, 0, points, wrong, groups=groups)
    assert grouped.group == 1 and grouped.missed > 0.3 * grouped.images
    check = SpotCheck(96, np.zeros(96)).with_coverage(grouped, "Cube")
    assert not check.within(1.0) and check.shortfall() == f"{grouped.missed} of {grouped.images} exact images of Cube not drawn"
    assert coverage_check(reflector_set, view, 0, points, answers, groups=groups).group == -1


def test_images_near_the_outline_are_left_to_a_cameras_traced_band(case):
    """A pixel sees the ball's outline within ``radius`` when one of the eight pixels
    that far around it misses the ball; a sample-based camera's answers left out there
    (the band Render Image traces) are not missed with ``band_px``, those inside are."""
    reflector_set, view, points, answers = case
    row = np.array([(x + 0.5, 120.5) for x in range(320)])
    origins, directions = view.pixel_rays(row)
    on_ball = np.flatnonzero(reflector_set.intersect(origins, directions).reflector == 0)
    rim, inner = row[on_ball[0]], row[on_ball[0] + 6]
    assert near_outline(reflector_set, view, 0, np.array([rim, inner]), 2).tolist() == [True, False]
    assert near_outline(reflector_set, view, 0, np.array([rim, inner]), 8).tolist() == [True, True]
    exact = solve_reflections(reflector_set, view, points)
    exact = exact.select(exact.visible)
    banded = near_outline(reflector_set, view, 0, exact.pixel, 3)
    assert 0.02 < banded.mean() < 0.5
    camera = answers.copy()
    camera[0, exact.point[banded]] = np.nan  # the camera reaches nothing along the outline
    without_band = coverage_check(reflector_set, view, 0, points, camera)
    with_band = coverage_check(reflector_set, view, 0, points, camera, band_px=3)
    assert without_band.missed > 0 and with_band.missed == 0 and with_band.images == without_band.images
