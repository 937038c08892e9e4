# SPDX-License-Identifier: GPL-3.0-or-later
"""Operators on the scene's set of reflectors: mark objects, check what the engine sees."""

import bpy
from bpy.props import EnumProperty

from ..engine.errors import SceneInputError
from .capture import SURFACE_TYPES, capture_scene


class CURVED_REFLECTIONS_OT_mark_reflector(bpy.types.Operator):
    """Mark the selected objects as curved mirrors, or unmark them"""

    bl_idname = "curved_reflections.mark_reflector"
    bl_label = "Mark Reflector"
    bl_options = {'REGISTER', 'UNDO'}

    action: EnumProperty(
        name="Action",
        items=(
            ('TOGGLE', "Toggle", "Unmark if all selected objects are reflectors, else mark them all"),
            ('MARK', "Mark", "Mark the selected objects as reflectors"),
            ('CLEAR', "Clear", "Unmark the selected objects"),
        ),
        default='TOGGLE',
    )

    @classmethod
    def poll(cls, context):
        return any(obj.type in SURFACE_TYPES for obj in context.selected_objects)

    def execute(self, context):
        objects = [obj for obj in context.selected_objects if obj.type in SURFACE_TYPES]
        if self.action == 'TOGGLE':
            state = not all(obj.curved_reflections.is_reflector for obj in objects)
        else:
            state = self.action == 'MARK'
        for obj in objects:
            obj.curved_reflections.is_reflector = state
        verb = "Marked" if state else "Unmarked"
        noun = "object" if len(objects) == 1 else "objects"
        self.report({'INFO'}, f"{verb} {len(objects)} {noun} as reflector")
        return {'FINISHED'}


class CURVED_REFLECTIONS_OT_check_scene(bpy.types.Operator):
    """Capture the scene as the reflection engine sees it and report what it found"""

    bl_idname = "curved_reflections.check_scene"
    bl_label = "Check Scene"

    @classmethod
    def poll(cls, context):
        return context.scene is not None and context.view_layer is not None

    def execute(self, context):
        try:
            captured = capture_scene(context.evaluated_depsgraph_get())
        except SceneInputError as error:
            self.report({'ERROR'}, str(error))
            return {'CANCELLED'}
        self.report({'INFO'}, check_summary(captured))
        return {'FINISHED'}


def check_summary(captured) -> str:
    """One line of counts, e.g. ``1 reflector (960 triangles), 2 diffuse meshes (24 triangles)``."""
    def count(n, singular, plural):
        return f"{n:,} {singular if n == 1 else plural}"

    return (
        f"{count(len(captured.reflectors), 'reflector', 'reflectors')} "
        f"({count(captured.reflector_triangles, 'triangle', 'triangles')}), "
        f"{count(len(captured.meshes), 'diffuse mesh', 'diffuse meshes')} "
        f"({count(captured.mesh_triangles, 'triangle', 'triangles')})"
    )


classes = (
    CURVED_REFLECTIONS_OT_mark_reflector,
    CURVED_REFLECTIONS_OT_check_scene,
)
