# SPDX-License-Identifier: GPL-3.0-or-later
"""The "Reflections" tab of the 3D viewport's sidebar (N panel), laid out as Blender's own.

The main panel holds the live view (:mod:`.live`): **Start**, **Refresh**, **Clear**,
*Auto Refresh* and the status line, then Render Reflections Image and the demo scenes.
Its sub-panels, as in Blender's property editors (a mixin for the shared ``bl_*``, one
``VIEW3D_PT_`` class each, registered after the parent):

- *Mirror*: the active object's settings, its *Reflector* checkbox in the header;
- *Reflectors*: each reflector with the method drawing it, why, and its measured accuracy;
- *Quality*: the scene's method settings;
- *Morphing Grids* (closed by default): the grids' settings, baking and their status;
- *Statistics* (closed by default): the live view's rays, leaves, timings and memory.

Settings that do not apply are greyed, not hidden, so the layout does not jump.
"""

import textwrap

import bpy

from . import accuracy, live, method_plan, method_registry, morph_bake
from .capture import SURFACE_TYPES
from .material_ior import glass_ior

_STATUS_ICONS = {'INFO': 'INFO', 'WARNING': 'ERROR', 'ERROR': 'CANCEL'}

#: Characters per line of a reflector's reason in the panel (labels do not wrap by themselves).
REASON_WIDTH = 52


def _reflectors(scene) -> list:
    """The scene's objects marked as reflectors."""
    return [o for o in scene.objects if o.curved_reflections.is_reflector]


def _morphing(scene) -> bool:
    """Whether a reflector wants a morphing grid: the grid settings apply only then."""
    return any(method_plan.grid_wanted_by_last_plan(scene, o) for o in _reflectors(scene))


def _surface_object(context):
    """The active object when it can be a mirror (a mesh, curve, surface, text or metaball)."""
    obj = context.active_object
    return obj if obj is not None and obj.type in SURFACE_TYPES else None


def _object_toggle(layout, context, name: str) -> None:
    """A sub-panel header's checkbox: the active object's setting ``name``, where it has a surface."""
    obj = _surface_object(context)
    if obj is not None:
        layout.prop(obj.curved_reflections, name, text="")


def _split_property(layout):
    """Names in a left column, fields in a right one, as Blender's property panels."""
    layout.use_property_split = True
    layout.use_property_decorate = False  # no animation


def _wrapped(layout, text: str, icon: str) -> None:
    """``text`` over as many labels as it needs, the icon on the first."""
    for k, line in enumerate(textwrap.wrap(text, REASON_WIDTH)):
        layout.label(text=line, icon=icon if k == 0 else 'BLANK1')


def _reflector_method(layout, reflector, choice, found) -> None:
    """One reflector with the method drawing it and why (the last plan: Start or Render),
    and its accuracy measured in the live view once the view settled."""
    if choice is None:
        layout.label(text=f"{reflector.name}: {reflector.curved_reflections.mode.title()} (not started yet)",
                     icon='MOD_MIRROR')
        return
    method = method_registry.get(choice.method)
    layout.label(text=f"{reflector.name}: {method.label}", icon=method.icon)
    _wrapped(layout, choice.reason, 'BLANK1')
    if found is not None:
        _wrapped(layout, accuracy.panel_line(found), 'DRIVER_DISTANCE')


def _statistic(layout, name: str, value: str) -> None:
    """A name and its value, aligned like a property with ``use_property_split``."""
    split = layout.split(factor=0.4)
    row = split.row()
    row.alignment = 'RIGHT'
    row.label(text=name)
    split.label(text=value)


class _SidebarPanel:
    """Where every panel of the tab lives (as bl_ui's ``RenderButtonsPanel`` mixins)."""

    bl_space_type = 'VIEW_3D'
    bl_region_type = 'UI'
    bl_category = "Reflections"


class _SubPanel(_SidebarPanel):
    """A sub-panel of the main panel: drawn below its content, opened and closed on its own."""

    bl_parent_id = "VIEW3D_PT_curved_reflections"


class VIEW3D_PT_curved_reflections(_SidebarPanel, bpy.types.Panel):
    """Curved mirror reflections: build, refresh and clear the live reflections, render an image"""

    bl_label = "Curved Reflections"

    def draw(self, context):
        layout = self.layout
        _split_property(layout)
        scene = context.scene
        row = layout.row(align=True)
        row.operator("curved_reflections.start_live", icon='RENDER_STILL')
        row.operator("curved_reflections.refresh", icon='FILE_REFRESH')
        row.operator("curved_reflections.clear", icon='X')
        layout.prop(scene.curved_reflections, "auto_refresh")
        state = live.state_of(scene)
        if state is None:
            layout.label(text="Not started: no live reflections", icon='INFO')
        else:
            if state.jobs or state.requests:
                layout.label(text="Updating...", icon='SORTTIME')
            if state.status:
                _wrapped(layout, state.status, _STATUS_ICONS.get(state.level, 'INFO'))
        layout.separator()
        column = layout.column(align=True)
        column.operator("curved_reflections.render_image", icon='RENDER_STILL')
        column.operator_menu_enum("curved_reflections.add_demo_scene", "demo", text="Add Demo Scene",
                                  icon='SCENE_DATA')


class VIEW3D_PT_curved_reflections_mirror(_SubPanel, bpy.types.Panel):
    """The active object as a mirror: reflectivity, Fresnel, fading and the method that draws it"""

    bl_label = "Mirror"

    def draw_header(self, context):
        _object_toggle(self.layout, context, "is_reflector")

    def draw(self, context):
        layout = self.layout
        _split_property(layout)
        obj = context.active_object
        if obj is None:
            layout.label(text="No active object", icon='INFO')
            return
        if obj.type not in SURFACE_TYPES:
            layout.label(text=f"{obj.name}: a {obj.type.lower()} object cannot be a mirror", icon='INFO')
            return
        settings = obj.curved_reflections
        layout.label(text=obj.name, icon='OBJECT_DATA')
        column = layout.column()
        column.active = settings.is_reflector
        column.prop(settings, "reflectivity")
        column.prop(settings, "use_fresnel")
        facing = column.column()
        facing.active = settings.use_fresnel
        facing.prop(settings, "fresnel_f0")
        column.prop(settings, "attenuation_distance")
        column.separator()
        column.prop(settings, "mode")
        exact = column.column()
        exact.active = settings.mode == 'PERTURBATION'
        exact.prop(settings, "analytic_shape")
        radii = exact.column()
        radii.active = settings.analytic_shape != 'NONE'
        radii.prop(settings, "analytic_radii")
        exponent = exact.column()
        exponent.active = settings.analytic_shape == 'SUPERQUADRIC'
        exponent.prop(settings, "analytic_exponent")


class VIEW3D_PT_curved_reflections_glass(_SubPanel, bpy.types.Panel):
    """The active object as glass: its index of refraction and what draws it"""

    bl_label = "Glass"
    bl_options = {'DEFAULT_CLOSED'}

    def draw_header(self, context):
        _object_toggle(self.layout, context, "is_refractor")

    def draw(self, context):
        layout = self.layout
        _split_property(layout)
        obj = _surface_object(context)
        if obj is None:
            layout.label(text="No active object with a surface", icon='INFO')
            return
        settings = obj.curved_reflections
        column = layout.column()
        column.active = settings.is_refractor
        column.prop(settings, "ior")
        if settings.ior <= 0.0:
            column.label(text=f"From the material: {glass_ior(obj):.3f}", icon='MATERIAL')
        if settings.is_refractor:
            _wrapped(layout, glass_note(obj.name, live.state_of(context.scene)), 'INFO')


#: How mirrors show glass (``drawing/methods/traced_pass.py`` refracts through it).
IN_MIRRORS = ("Mirrors drawn by the trace (Ray Traced) show what lies behind it, refracted, without its own "
              "reflection; mirrors drawn by other methods reflect it as a solid object.")


def glass_note(name: str, state) -> str:
    """What draws glass object ``name`` in the viewport (the live ``state``'s glass layer,
    None before a Start) and in Render Image, and why."""
    layer = None if state is None else state.glass
    if layer is None or name not in {glass.name for glass in layer.glass.glasses}:
        return ("Render Image ray traces it (refraction, total internal reflection, Fresnel); the viewport does "
                "once reflections are started.")
    if layer.traced:
        return ("The viewport and Render Image trace it on the GPU every frame: each pixel's path through the glass "
                "(any shape, glass behind glass too) and what its rays meet, mirrors' reflections too, mixed by "
                f"Fresnel. {IN_MIRRORS}")
    rendered = ("The scene's image textures are more than the GPU's trace holds (some 64 million texels): Render "
                "Image ray traces it on the CPU (refraction, total internal reflection, Fresnel).")
    if name in layer.unsearched:
        return f"The viewport shows it as a solid object: {layer.unsearched[name]}. {rendered} {IN_MIRRORS}"
    return ("The viewport draws what lies behind it by the refraction search (a convex solid), mixed by Fresnel with "
            f"what it reflects, drawn as a mirror's; mirrors behind it show as solid objects. {rendered} {IN_MIRRORS}")


class VIEW3D_PT_curved_reflections_reflectors(_SubPanel, bpy.types.Panel):
    """The scene's reflectors: the method drawing each, why, and its accuracy measured in the view"""

    bl_label = "Reflectors"

    def draw(self, context):
        layout = self.layout
        scene = context.scene
        reflectors = _reflectors(scene)
        if not reflectors:
            layout.label(text="No reflector marked", icon='INFO')
        choices = {c.reflector: c for c in method_plan.last_choices(scene)}
        measured = method_plan.measured(scene)
        for reflector in reflectors:
            _reflector_method(layout.box().column(align=True), reflector, choices.get(reflector.name),
                              measured.get(reflector.name))
        row = layout.row(align=True)
        row.operator("curved_reflections.mark_reflector", icon='MOD_MIRROR')
        row.operator("curved_reflections.check_scene", icon='VIEWZOOM')


class VIEW3D_PT_curved_reflections_quality(_SubPanel, bpy.types.Panel):
    """How accurate and how fast: mirror bounces, traced rays, the error allowed, the morphing polish"""

    bl_label = "Quality"

    def draw(self, context):
        layout = self.layout
        _split_property(layout)
        settings = context.scene.curved_reflections
        column = layout.column()
        column.prop(settings, "max_order")
        column.prop(settings, "downsample")
        column.prop(settings, "accuracy_px")
        layout.separator()
        morph = layout.column(heading="Polish")
        morph.active = _morphing(context.scene)
        morph.prop(settings, "morph_polish_nodes", text="Node Images")
        frames = morph.column()
        frames.active = settings.morph_polish_nodes
        frames.prop(settings, "morph_polish_frames", text="Every Frame")
        morph.prop(settings, "morph_gpu_budget_mb")


class VIEW3D_PT_curved_reflections_grids(_SubPanel, bpy.types.Panel):
    """Morphing grids: their nodes, margin and cache folder, baking them (also in ranges on a farm)"""

    bl_label = "Morphing Grids"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        layout = self.layout
        _split_property(layout)
        scene = context.scene
        settings = scene.curved_reflections
        morphing = _morphing(scene)
        column = layout.column()
        column.active = morphing
        column.prop(settings, "morph_grid")
        column.prop(settings, "morph_margin")
        column.prop(settings, "morph_cache_dir")
        nodes = settings.morph_grid[0] * settings.morph_grid[1] * settings.morph_grid[2]
        _statistic(column, "Nodes", f"{nodes} a grid, numbered 0-{nodes - 1}")  # a farm bakes ranges of them
        row = layout.row(align=True)
        bake = row.row(align=True)
        bake.active = morphing
        bake.operator("curved_reflections.bake_morphing", icon='LIGHTPROBE_VOLUME')
        row.operator("curved_reflections.clear_morphing", icon='TRASH')
        bake_line = morph_bake.morph_status(scene, per_reflector=False)
        if bake_line:
            _wrapped(layout, bake_line, 'INFO')
        for name, mode in morph_bake.reflector_modes(scene):
            _wrapped(layout, f"{name}: {mode}", 'LIGHTPROBE_VOLUME' if mode.startswith("morphing") else 'INFO')


class VIEW3D_PT_curved_reflections_statistics(_SubPanel, bpy.types.Panel):
    """The live reflections' cost: traced rays, camera leaves, build and draw times, memory"""

    bl_label = "Statistics"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        layout = self.layout
        scene = context.scene
        state = live.state_of(scene)
        if state is None:
            layout.label(text="Not started: no statistics", icon='INFO')
            return
        stats = state.stats
        if "rays" in stats:
            column = layout.column(align=True)
            for name, value in (
                ("Rays", f"{stats['rays']:,}"),
                ("Leaves", f"{stats['leaves']:,}"),
                ("Build", f"{stats['build_ms']:.0f} ms"),
                ("Draw", f"{stats['draw_ms']:.1f} ms" if "draw_ms" in stats else "-"),
                ("Memory", f"{stats['memory_mb']:.1f} MB"),
                ("Views", f"{stats['views']}"),
            ):
                _statistic(column, name, value)
        if "unanswered" in stats:
            _wrapped(layout, f"Searched on the GPU: {stats['searched'] - stats['unanswered']:,} of "
                             f"{stats['searched']:,} vertex reflections found", 'SHADERFX')
        for frame_pass in () if state.renderer is None else state.renderer.passes:
            for line in frame_pass.statistics():
                layout.label(text=line, icon='MEMORY')


classes = (
    VIEW3D_PT_curved_reflections,
    VIEW3D_PT_curved_reflections_mirror,
    VIEW3D_PT_curved_reflections_glass,
    VIEW3D_PT_curved_reflections_reflectors,
    VIEW3D_PT_curved_reflections_quality,
    VIEW3D_PT_curved_reflections_grids,
    VIEW3D_PT_curved_reflections_statistics,
)
