# SPDX-License-Identifier: GPL-3.0-or-later
"""One point's answers (``engine/methods/perturbation/answers.py``): answers closer than
SAME_IMAGE_PX are one image, the one first in priority kept; images ranked left to right."""

import numpy as np

from curved_reflections.engine.methods.perturbation.answers import SAME_IMAGE_PX, ranked, repeats


def test_answers_of_one_image_repeat_the_first_in_priority():
    point_of = np.array([0, 0, 0, 1, 1])
    pixel = np.array([[10.0, 5.0], [10.0 + 0.5 * SAME_IMAGE_PX, 5.0], [40.0, 5.0], [10.2, 5.0], [10.0, 5.0]])
    # By default the leftmost of a pair is kept; points never merge with each other.
    np.testing.assert_array_equal(repeats(point_of, pixel), [False, True, False, True, False])
    # A priority keeps the earlier answer whichever side it lies on.
    np.testing.assert_array_equal(repeats(point_of, pixel, priority=np.array([4, 0, 1, 2, 3])),
                                  [True, False, False, False, True])


def test_images_are_ranked_left_to_right_per_point():
    point_of = np.array([2, 2, 0, 2])
    pixel = np.array([[30.0, 1.0], [5.0, 1.0], [7.0, 1.0], [5.3, 1.0]])
    first = np.arange(12, dtype=np.float64).reshape(4, 3)
    firsts, lasts = ranked(3, point_of, first, -first, pixel)
    assert len(firsts) == 2 and len(lasts) == 2
    np.testing.assert_array_equal(firsts[0][2], first[1])  # x 5.0 (5.3 is the same image)
    np.testing.assert_array_equal(firsts[1][2], first[0])  # x 30.0
    np.testing.assert_array_equal(firsts[0][0], first[2])
    assert np.isnan(firsts[1][0]).all() and np.isnan(firsts[0][1]).all()
    np.testing.assert_array_equal(lasts[1][2], -first[0])
