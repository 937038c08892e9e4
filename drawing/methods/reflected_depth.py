# SPDX-License-Identifier: GPL-3.0-or-later
"""The depth that orders reflections in the renderer's depth buffer, in numpy.

SBC paper (Popescu, Sacks, Mei 2006), section V-A, visibility cases 2 and 3: a reflected
vertex of order k is drawn at depth (k - 1 + z / D) g, z its distance from the last
reflector point along the reflected ray, D an upper bound of z (the scene's diameter)
and g the depth range of one order, so lower orders lie in front and, within a sheet,
the point nearer the mirror wins. ``glsl/reflection_project_vert.glsl`` writes it on the
GPU; the projection sources that answer on the CPU write the same texels with
:func:`reflected_depth`. Numpy only (no ``gpu``): the live view's worker thread projects
with it (``camera_source.CameraSource``).
"""

from __future__ import annotations

import numpy as np


def reflected_depth(order: int, distance: np.ndarray, setup: dict) -> np.ndarray:
    """The depth of reflections of ``order`` at reflected ``distance``: (k - 1 + z / D) g,
    with 1 / D and g the ``inverse_diameter`` and ``order_range`` of the pass's ``setup``."""
    return (order - 1 + np.clip(distance * setup["inverse_diameter"], 0.0, 1.0)) * setup["order_range"]
