# SPDX-License-Identifier: GPL-3.0-or-later
"""Curved Reflections: accurate curved-mirror reflections drawn in Blender's viewport.

The repository root is the extension. This module only registers and unregisters;
the Blender layer (``operators``) is imported inside those calls so that
``import curved_reflections.addon`` (the numpy engine) never needs ``bpy``.
"""


def register():
    from . import operators

    operators.register()


def unregister():
    from . import operators

    operators.unregister()
