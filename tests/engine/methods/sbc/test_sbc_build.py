# SPDX-License-Identifier: GPL-3.0-or-later
"""What ``engine/methods/sbc/sbc_build.py`` says of a view before building: the sealed
mirrors its near plane cuts into (``clip_start_inside``)."""

import numpy as np

from curved_reflections.engine import look_at_view
from curved_reflections.engine.geometry.raytrace import ReflectorSet
from curved_reflections.engine.geometry.sphere import icosphere
from curved_reflections.engine.methods.sbc.sbc_build import clip_start_inside


def test_a_near_plane_cutting_a_sealed_mirror_anywhere_across_the_view_names_it():
    """The ball beside the view's axis: its near plane cuts into it off the middle of the
    image, and the ball is named once sealed (nothing inside it); not before, and not
    when the near plane stops short of it."""
    ball = icosphere((0.6, 0.0, 0.0), 0.5, 3, "Ball")
    reflectors = ReflectorSet([ball])
    view = look_at_view((0.0, -3.0, 0.0), (0.0, 0.0, 0.0), fov_y_deg=40.0, width=64, height=48, near=3.0)
    centre, _ = view.pixel_rays(np.array([[32.0, 24.0]]))
    assert np.linalg.norm(centre[0] - ball.vertices.mean(axis=0)) > 0.5  # the middle of the view misses it
    assert clip_start_inside(reflectors, view) == []  # open: its inside is traced
    reflectors.seal_empty_interiors([])
    assert clip_start_inside(reflectors, view) == ["Ball"]
    short = look_at_view((0.0, -3.0, 0.0), (0.0, 0.0, 0.0), fov_y_deg=40.0, width=64, height=48, near=2.0)
    assert clip_start_inside(reflectors, short) == []
