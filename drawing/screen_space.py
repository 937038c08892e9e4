# SPDX-License-Identifier: GPL-3.0-or-later
"""Where the renderer's geometry lands on the screen: the view's matrix for positions
relative to the geometry's shift, the eye, the overlay's depth bias, and the part of
the screen a bounding box can cover (``reflection_draw.py``)."""

from __future__ import annotations

import numpy as np
from mathutils import Matrix

#: A viewport overlay's mirror pixels are depth-tested against the scene's depth as if
#: this share of their distance nearer (:func:`depth_bias`): 1 cm at 10 m.
SCENE_DEPTH_BIAS = 1e-3
#: ... in an orthographic view, this share (to twice it) of the clipping range.
ORTHOGRAPHIC_DEPTH_BIAS = 1e-5
#: The composite's rectangle covering the whole view (normalised device coordinates).
FULL_SCREEN = (-1.0, -1.0, 1.0, 1.0)


def box_corners(points: np.ndarray) -> np.ndarray:
    """(8, 4) homogeneous corners of the bounding box of ``points`` (none: (0, 4))."""
    if len(points) == 0:
        return np.zeros((0, 4))
    lo, hi = points.min(axis=0), points.max(axis=0)
    corners = np.array([[(hi if (k >> a) & 1 else lo)[a] for a in range(3)] for k in range(8)], dtype=np.float64)
    return np.c_[corners, np.ones(8)]


def view_projection(view, shift):
    """The view's projection times view matrix, applied to positions relative to ``shift``
    (folded in float64, so that large world coordinates keep their precision in float32)."""
    translate = np.eye(4)
    translate[:3, 3] = shift
    return Matrix((np.asarray(view.projection_matrix) @ np.asarray(view.view_matrix) @ translate).tolist())


def depth_bias(view) -> tuple:
    """(anchor, scale) of the overlay composite's depth bias: a window depth z is brought
    to z - scale (anchor - z). In perspective, z = a + b / d at distance d with
    a = (1 - P[2][2]) / 2 (OpenGL's depth range [0, 1]), and z - s (a - z) is to first
    order the depth at d (1 - s): the mirror drawn :data:`SCENE_DEPTH_BIAS` of its
    distance nearer, which the scene's depth of the same surface (another tessellation
    of it, 24-bit) cannot beat, while a real object in front still does. In an
    orthographic view depth is linear: anchor 2 makes the bias between 1 and 2 times
    the scale, a share of the clipping range."""
    projection = np.asarray(view.projection_matrix, dtype=np.float64)
    if abs(projection[3, 3] - 1.0) < 1e-12:  # orthographic
        return 2.0, ORTHOGRAPHIC_DEPTH_BIAS
    return 0.5 * (1.0 - projection[2, 2]), SCENE_DEPTH_BIAS


def camera_position(view, shift) -> tuple:
    """The pre-pass's ``camera``: the eye relative to ``shift`` (w 1), or for an
    orthographic view the unit direction toward the viewer (w 0)."""
    inverse = np.linalg.inv(np.asarray(view.view_matrix, dtype=np.float64))
    if abs(float(np.asarray(view.projection_matrix)[3, 3]) - 1.0) < 1e-12:  # orthographic
        return (*inverse[:3, 2], 0.0)
    return (*(inverse[:3, 3] - shift), 1.0)


def box_on_screen(corners: np.ndarray, view, shift, width: int, height: int) -> tuple:
    """The screen rectangle (normalised device coordinates x0, y0, x1, y1) holding the
    box of ``corners`` ((8, 4) homogeneous, relative to ``shift``, :func:`box_corners`)
    in ``view``, a pixel wider; :data:`FULL_SCREEN` when a corner is behind the eye or
    there is no box."""
    if len(corners) == 0:
        return FULL_SCREEN
    clip = corners @ np.asarray(view_projection(view, shift), dtype=np.float64).T
    if (clip[:, 3] <= 1e-9).any():
        return FULL_SCREEN
    ndc = clip[:, :2] / clip[:, 3:]
    pixel = 2.0 / np.array([width, height])
    low = np.clip(ndc.min(axis=0) - pixel, -1.0, 1.0)
    high = np.clip(ndc.max(axis=0) + pixel, -1.0, 1.0)
    return (*low, *high)


def pixel_box(rect: tuple, width: int, height: int, margin: int) -> tuple:
    """(x, y, width, height) of the pixels of a ``width`` x ``height`` view that ``rect``
    (normalised device coordinates x0, y0, x1, y1) touches, ``margin`` pixels wider on
    each side and clipped to the view: a scissor box."""
    x0, y0, x1, y1 = rect
    left = max(0, int(np.floor((x0 + 1.0) * 0.5 * width)) - margin)
    bottom = max(0, int(np.floor((y0 + 1.0) * 0.5 * height)) - margin)
    right = min(width, int(np.ceil((x1 + 1.0) * 0.5 * width)) + margin)
    top = min(height, int(np.ceil((y1 + 1.0) * 0.5 * height)) + margin)
    return left, bottom, max(0, right - left), max(0, top - bottom)
