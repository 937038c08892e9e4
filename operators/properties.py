# SPDX-License-Identifier: GPL-3.0-or-later
"""Settings stored in the .blend: per object and per scene PropertyGroups."""

import bpy
from bpy.props import BoolProperty, FloatProperty, IntProperty, PointerProperty


class CurvedReflectionsObjectSettings(bpy.types.PropertyGroup):
    """Per-object settings, as ``obj.curved_reflections``."""

    is_reflector: BoolProperty(
        name="Reflector",
        description="Treat this object as a curved mirror: nearby objects are reflected in it",
        default=False,
    )
    reflectivity: FloatProperty(
        name="Reflectivity",
        description="Share of the reflected image in the mirror's colour (1 = perfect mirror)",
        default=1.0, min=0.0, max=1.0, subtype='FACTOR',
    )


class CurvedReflectionsSceneSettings(bpy.types.PropertyGroup):
    """Per-scene method settings, as ``scene.curved_reflections``."""

    downsample: IntProperty(
        name="Down-sampling",
        description="Ray map resolution divisor: one traced ray per d x d pixels",
        default=2, min=1, max=16,
    )
    accuracy_px: FloatProperty(
        name="Accuracy (px)",
        description="Largest projection error allowed, in pixels of the view",
        default=1.0, min=0.05, max=16.0,
    )
    max_order: IntProperty(
        name="Max Order",
        description="Highest number of mirror bounces drawn",
        default=1, min=1, max=4,
    )
    auto_refresh: BoolProperty(
        name="Auto Refresh",
        description="Rebuild reflections when the view or the scene changes",
        default=True,
    )


classes = (
    CurvedReflectionsObjectSettings,
    CurvedReflectionsSceneSettings,
)


def register_pointers():
    bpy.types.Object.curved_reflections = PointerProperty(type=CurvedReflectionsObjectSettings)
    bpy.types.Scene.curved_reflections = PointerProperty(type=CurvedReflectionsSceneSettings)


def unregister_pointers():
    del bpy.types.Scene.curved_reflections
    del bpy.types.Object.curved_reflections
