# SPDX-License-Identifier: GPL-3.0-or-later
"""Curved Reflections: accurate curved-mirror reflections drawn in Blender's viewport.

The repository root is the extension. This module only registers and unregisters;
the Blender layer (``blender``) is imported inside those calls so that
``import curved_reflections.engine`` (the numpy engine) never needs ``bpy``.
"""


def register():
    from . import blender

    blender.register()


def unregister():
    from . import blender

    blender.unregister()
