# SPDX-License-Identifier: GPL-3.0-or-later
"""The "Reflections" tab of the 3D viewport's sidebar (N panel)."""

import bpy

from .capture import SURFACE_TYPES


class VIEW3D_PT_curved_reflections(bpy.types.Panel):
    """Curved mirror reflections: which objects are mirrors, and the method settings"""

    bl_label = "Curved Reflections"
    bl_space_type = 'VIEW_3D'
    bl_region_type = 'UI'
    bl_category = "Reflections"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False

        obj = context.active_object
        if obj is not None and obj.type in SURFACE_TYPES:
            settings = obj.curved_reflections
            column = layout.column(heading=obj.name)
            column.prop(settings, "is_reflector")
            reflectivity = column.row()
            reflectivity.active = settings.is_reflector
            reflectivity.prop(settings, "reflectivity")

        reflectors = [o for o in context.scene.objects if o.curved_reflections.is_reflector]
        box = layout.box()
        if reflectors:
            for reflector in reflectors:
                box.label(text=reflector.name, icon='MOD_MIRROR')
        else:
            box.label(text="No reflector marked", icon='INFO')
        layout.operator("curved_reflections.mark_reflector", icon='MOD_MIRROR')

        scene_settings = context.scene.curved_reflections
        column = layout.column()
        column.prop(scene_settings, "downsample")
        column.prop(scene_settings, "accuracy_px")
        column.prop(scene_settings, "max_order")
        column.prop(scene_settings, "auto_refresh")
        layout.operator("curved_reflections.check_scene", icon='VIEWZOOM')
        layout.operator("curved_reflections.render_image", icon='RENDER_STILL')
        layout.operator_menu_enum("curved_reflections.add_demo_scene", "demo", text="Add Demo Scene",
                                  icon='SCENE_DATA')


classes = (
    VIEW3D_PT_curved_reflections,
)
