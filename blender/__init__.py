# SPDX-License-Identifier: GPL-3.0-or-later
"""The Blender layer: properties, operators and panels.

As in Blender's bundled ``bl_operators``, each module ends with a ``classes`` tuple;
they are registered in module order and unregistered in reverse.
"""

import bpy

from . import (demo_scenes, live_handlers, live_operators, morph_bake, panel, properties, reflectors, render_image,
               scene_status, star_maps)

_modules = (
    properties,
    reflectors,
    demo_scenes,
    render_image,
    live_operators,
    morph_bake,
    panel,
)


def _classes():
    return [cls for module in _modules for cls in module.classes]


def register():
    for cls in _classes():
        bpy.utils.register_class(cls)
    properties.register_pointers()
    live_handlers.register()


def unregister():
    live_handlers.unregister()
    scene_status.forget_all()
    star_maps.forget()
    properties.unregister_pointers()
    for cls in reversed(_classes()):
        bpy.utils.unregister_class(cls)
