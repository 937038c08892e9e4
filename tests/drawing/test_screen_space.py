# SPDX-License-Identifier: GPL-3.0-or-later
"""Screen-space helpers of the renderer: the box a mirror can cover, the depth bias."""

import numpy as np

from curved_reflections.engine.view import look_at_view


def test_a_box_is_drawn_over_its_projection_and_over_the_whole_view_from_inside_it():
    from curved_reflections.drawing.screen_space import FULL_SCREEN, box_corners, box_on_screen

    shift = np.array([10.0, 0.0, 0.0])  # positions are relative to the geometry's shift
    corners = box_corners(np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0], [0.2, 0.0, 0.3]]))
    assert corners.shape == (8, 4) and len(box_corners(np.zeros((0, 3)))) == 0
    far = look_at_view(shift + (0.0, -30.0, 0.0), shift, fov_y_deg=40.0, width=64, height=48)
    x0, y0, x1, y1 = box_on_screen(corners, far, shift, 64, 48)
    # A 2-unit box 29 units away (its near face): 0.071 x 0.095 of the half-extents, a pixel wider.
    assert np.allclose([x1, y1], [-x0, -y0]) and 0.09 < x1 < 0.11 and 0.12 < y1 < 0.14
    inside = look_at_view(shift + (0.0, -0.9, 0.9), shift, width=64, height=48)
    assert box_on_screen(corners, inside, shift, 64, 48) == FULL_SCREEN
    assert box_on_screen(np.zeros((0, 4)), far, shift, 64, 48) == FULL_SCREEN


def test_a_pixel_box_covers_the_rectangle_with_its_margin_within_the_view():
    from curved_reflections.drawing.screen_space import FULL_SCREEN, pixel_box

    # x from pixel 16 to 48 of 64, y from 12 to 36 of 48, two pixels wider.
    assert pixel_box((-0.5, -0.5, 0.5, 0.5), 64, 48, 2) == (14, 10, 36, 28)
    assert pixel_box((-0.51, -0.49, 0.49, 0.51), 64, 48, 0) == (15, 12, 33, 25)  # partly covered pixels count
    assert pixel_box(FULL_SCREEN, 64, 48, 3) == (0, 0, 64, 48)
    assert pixel_box((0.9, 0.9, 1.0, 1.0), 64, 48, 5) == (55, 40, 9, 8)  # clipped at the border
