# SPDX-License-Identifier: GPL-3.0-or-later
"""The "Reflections" tab of the 3D viewport's sidebar (N panel).

Top to bottom: the active object's reflector settings, the scene's reflectors, the
method settings, the live reflections (**Bake**, **Refresh**, **Clear**, their stats and
a status line, :mod:`.live`), then the scene checks and the offscreen render. Settings
that do not apply are greyed, not hidden, so the layout does not jump.
"""

import textwrap

import bpy

from . import accuracy, live, methods, morph_bake
from .capture import SURFACE_TYPES

_STATUS_ICONS = {'INFO': 'INFO', 'WARNING': 'ERROR', 'ERROR': 'CANCEL'}


def _reflector_settings(layout, obj) -> None:
    settings = obj.curved_reflections
    column = layout.column(heading=obj.name)
    column.prop(settings, "is_reflector")
    details = column.column()
    details.active = settings.is_reflector
    details.prop(settings, "reflectivity")
    details.prop(settings, "use_fresnel")
    facing = details.row()
    facing.active = settings.is_reflector and settings.use_fresnel
    facing.prop(settings, "fresnel_f0")
    details.prop(settings, "attenuation_distance")
    details.prop(settings, "mode")
    if settings.mode == 'PERTURBATION':
        details.prop(settings, "analytic_shape")
        radii = details.row()
        radii.active = settings.analytic_shape != 'NONE'
        radii.prop(settings, "analytic_radii")
        if settings.analytic_shape == 'SUPERQUADRIC':
            details.prop(settings, "analytic_exponent")


#: Characters per line of a reflector's reason in the panel.
REASON_WIDTH = 52
_METHOD_ICONS = {methods.ITERATIVE: 'SHADERFX', methods.MORPHING: 'LIGHTPROBE_VOLUME', methods.RUNTIME: 'CAMERA_DATA',
                 methods.PERTURBATION: 'FORCE_HARMONIC', methods.OCTREE: 'LIGHTPROBE_VOLUME'}


def _reflector_methods(box, scene, reflectors) -> None:
    """Each reflector with the method drawing it and why (the last plan: Bake or Render),
    and its accuracy measured in the live view once the view settled."""
    choices = {c.reflector: c for c in methods.last_choices(scene)}
    measured = methods.measured(scene)
    for reflector in reflectors:
        choice = choices.get(reflector.name)
        if choice is None:
            box.label(text=f"{reflector.name}: {reflector.curved_reflections.mode.title()} (not baked yet)",
                      icon='MOD_MIRROR')
            continue
        box.label(text=f"{reflector.name}: {choice.method.title()}", icon=_METHOD_ICONS[choice.method])
        for line in textwrap.wrap(choice.reason, REASON_WIDTH):  # labels do not wrap by themselves
            box.label(text=line)
        found = measured.get(reflector.name)
        if found is not None:
            for k, line in enumerate(textwrap.wrap(accuracy.panel_line(found), REASON_WIDTH)):
                box.label(text=line, icon='DRIVER_DISTANCE' if k == 0 else 'BLANK1')


def _live_section(layout, scene) -> None:
    row = layout.row(align=True)
    row.operator("curved_reflections.bake", icon='RENDER_STILL')
    row.operator("curved_reflections.refresh", icon='FILE_REFRESH')
    row.operator("curved_reflections.clear", icon='X')
    state = live.state_of(scene)
    if state is None:
        layout.label(text="Not baked: no live reflections", icon='INFO')
        return
    stats = state.stats
    if "rays" in stats:
        grid = layout.grid_flow(row_major=True, columns=2, even_columns=True, align=True)
        for label, text in (
            ("Rays", f"{stats['rays']:,}"),
            ("Leaves", f"{stats['leaves']:,}"),
            ("Build", f"{stats['build_ms']:.0f} ms"),
            ("Draw", f"{stats['draw_ms']:.1f} ms" if "draw_ms" in stats else "-"),
            ("Memory", f"{stats['memory_mb']:.1f} MB"),
            ("Views", f"{stats['views']}"),
        ):
            grid.label(text=label)
            grid.label(text=text)
    if "unanswered" in stats:
        layout.label(text=f"Searched on the GPU: {stats['searched'] - stats['unanswered']:,} of "
                          f"{stats['searched']:,} vertex reflections found", icon='SHADERFX')
    if state.jobs or state.requests:
        layout.label(text="Updating...", icon='SORTTIME')
    if state.status:
        layout.label(text=state.status, icon=_STATUS_ICONS.get(state.level, 'INFO'))


def _morphing_section(layout, scene) -> None:
    row = layout.row(align=True)
    row.operator("curved_reflections.bake_morphing", icon='LIGHTPROBE_VOLUME')
    row.operator("curved_reflections.clear_morphing", icon='TRASH')
    bake_line = morph_bake.morph_status(scene, per_reflector=False)
    if bake_line:
        layout.label(text=bake_line, icon='INFO')
    state = live.state_of(scene)
    if state is not None and state.renderer is not None and state.renderer.morph.grids:
        nodes = state.renderer.morph.nodes
        layout.label(text=f"Nodes on the GPU: {len(nodes)} ({nodes.nbytes / 2 ** 20:.0f} of "
                          f"{nodes.budget_bytes / 2 ** 20:.0f} MB)", icon='MEMORY')
    for name, mode in morph_bake.reflector_modes(scene):
        layout.label(text=f"{name}: {mode}", icon='LIGHTPROBE_VOLUME' if mode.startswith("morphing") else 'INFO')


class VIEW3D_PT_curved_reflections(bpy.types.Panel):
    """Curved mirror reflections: which objects are mirrors, the method settings and live drawing"""

    bl_label = "Curved Reflections"
    bl_space_type = 'VIEW_3D'
    bl_region_type = 'UI'
    bl_category = "Reflections"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        scene = context.scene

        obj = context.active_object
        if obj is not None and obj.type in SURFACE_TYPES:
            _reflector_settings(layout, obj)

        reflectors = [o for o in scene.objects if o.curved_reflections.is_reflector]
        box = layout.box()
        if reflectors:
            _reflector_methods(box, scene, reflectors)
        else:
            box.label(text="No reflector marked", icon='INFO')
        layout.operator("curved_reflections.mark_reflector", icon='MOD_MIRROR')

        scene_settings = scene.curved_reflections
        column = layout.column()
        column.prop(scene_settings, "downsample")
        column.prop(scene_settings, "accuracy_px")
        column.prop(scene_settings, "max_order")
        column.prop(scene_settings, "auto_refresh")
        morphing = any(methods.grid_wanted_by_last_plan(scene, o) for o in reflectors)
        morph = column.column()
        morph.active = morphing
        morph.prop(scene_settings, "morph_grid")
        morph.prop(scene_settings, "morph_margin")
        morph.prop(scene_settings, "morph_polish_nodes")
        polish_frames = morph.row()
        polish_frames.active = scene_settings.morph_polish_nodes
        polish_frames.prop(scene_settings, "morph_polish_frames")
        morph.prop(scene_settings, "morph_gpu_budget_mb")
        if morphing:
            _morphing_section(layout.box(), scene)

        _live_section(layout.box(), scene)

        layout.operator("curved_reflections.check_scene", icon='VIEWZOOM')
        layout.operator("curved_reflections.render_image", icon='RENDER_STILL')
        layout.operator_menu_enum("curved_reflections.add_demo_scene", "demo", text="Add Demo Scene",
                                  icon='SCENE_DATA')


classes = (
    VIEW3D_PT_curved_reflections,
)
