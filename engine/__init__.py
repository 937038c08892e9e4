# SPDX-License-Identifier: GPL-3.0-or-later
"""The Curved Reflections engine: numpy only, no bpy.

Everything here takes and returns numpy arrays and small dataclasses, so the hard parts
(ray tracing of reflectors, the exact reference solver, every projection method) are
tested with plain pytest. The package holds what every part shares: the scene model
(:mod:`.scene`), views (:mod:`.view`), the one interface every method answers with
(:mod:`.projection`), the engine's error, the sRGB transfer function (:mod:`.srgb`) and
the live spot check; the rest is grouped by concept: :mod:`.geometry`, :mod:`.reference`
(the exact first-order solver), :mod:`.methods` (one sub-package per method) and
:mod:`.baking` (the grid methods' preprocess).
"""

from .errors import SceneInputError
from .scene import DiffuseMesh, Reflector, scene_bounds
from .view import View, look_at_view

__all__ = ["DiffuseMesh", "Reflector", "SceneInputError", "View", "look_at_view", "scene_bounds"]
