# SPDX-License-Identifier: GPL-3.0-or-later
"""The Curved Reflections engine: numpy only, no bpy.

Everything here takes and returns numpy arrays and small dataclasses, so the hard
parts (ray tracing of reflectors, the exact reference solver, sample-based cameras)
are tested with plain pytest.
"""

from .errors import SceneInputError
from .sbc import SampleBasedCamera
from .sbc_build import build_sample_based_camera
from .scene import DiffuseMesh, Reflector, scene_bounds
from .view import View, look_at_view

__all__ = [
    "DiffuseMesh", "Reflector", "SampleBasedCamera", "SceneInputError", "View",
    "build_sample_based_camera", "look_at_view", "scene_bounds",
]
