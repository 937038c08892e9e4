# SPDX-License-Identifier: GPL-3.0-or-later
"""The GPU layer's tests: ``bpy`` imported before any of them imports a ``drawing``
module. Those import ``gpu`` and ``mathutils`` at the top, which the ``bpy`` module
provides once it is imported, as Blender has it before any extension loads; drawing
still needs the ``gpu_ready`` fixture (``tests/conftest.py``)."""

import bpy  # noqa: F401  (makes gpu and mathutils importable)
