# SPDX-License-Identifier: GPL-3.0-or-later
"""Start, Refresh and Clear: start, renew and stop the live reflections of a scene.

**Start** captures the scene and builds a sample-based camera (SBC paper, section IV)
for every 3D view of the screen showing Solid or Material Preview shading; the cameras
build on a worker thread (:mod:`.live`), so the operator returns at once. Without a 3D
view (background mode) it builds, in the calling thread, the scene camera's view.
**Refresh** does the same for the views already live; **Clear** forgets them all.
Problems (no reflector, a reflector without faces, the view inside a reflector) are
reported with the object's name, and shown in the panel's status line.
"""

import bpy

from ..engine.errors import SceneInputError
from . import live, method_registry
from .capture import view_from_region


def viewport_views(context) -> dict:
    """{region pointer: View} of the screen's 3D views that live reflections draw in."""
    screen = getattr(context, "screen", None)
    views = {}
    if screen is None:
        return views
    for area in screen.areas:
        if area.type != 'VIEW_3D':
            continue
        space = area.spaces.active
        if space.shading.type not in live.SHADING_TYPES or space.region_3d is None:
            continue
        for region in area.regions:
            if region.type == 'WINDOW' and region.width > 1 and region.height > 1:
                views[region.as_pointer()] = view_from_region(region, space.region_3d)
    return views


def _summary(state) -> str:
    if state.preparing is not None:  # big reflectors made ready on the worker: the status counts the seconds
        return state.status
    stats = state.stats
    drawn = [(state.plan.drawn_by(method.name), method.summary) for method in method_registry.registered()
             if method.summary and method.grid is None]
    searched = "; ".join(f"{', '.join(names)} {summary}" for names, summary in drawn if names)
    if "rays" not in stats:
        return searched or "building in the background"
    if not stats["rays"] and searched:
        return searched
    camera = (f"{stats['rays']:,} rays, {stats['leaves']:,} leaves, built in {stats['build_ms']:.0f} ms, "
              f"{stats['memory_mb']:.1f} MB")
    return f"{camera}; {searched}" if searched else camera


class _LiveOperator:
    refresh_only = False

    @classmethod
    def poll(cls, context):
        return context.scene is not None

    def execute(self, context):
        scene = context.scene
        # Background mode has screens but never draws them: the scene camera is the view.
        views = None if bpy.app.background else viewport_views(context) or None
        if self.refresh_only and live.state_of(scene) is None:
            self.report({'WARNING'}, "Nothing to refresh: Start first")
            return {'CANCELLED'}
        try:
            # Without a window nothing would collect a worker's result: build here.
            state = live.start(scene, context.evaluated_depsgraph_get(), views, wait=bpy.app.background)
        except SceneInputError as error:
            self.report({'ERROR'}, str(error))
            return {'CANCELLED'}
        if state.level == 'ERROR':
            self.report({'ERROR'}, state.status)
            return {'CANCELLED'}
        if state.level == 'WARNING':
            self.report({'WARNING'}, state.status)
        else:
            self.report({'INFO'}, f"{'Refreshed' if self.refresh_only else 'Started'} reflections: {_summary(state)}")
        live.tag_redraw()
        return {'FINISHED'}


class CURVED_REFLECTIONS_OT_start_live(_LiveOperator, bpy.types.Operator):
    """Capture the scene and draw live curved reflections in the 3D views"""

    bl_idname = "curved_reflections.start_live"
    bl_label = "Start"
    bl_options = {'REGISTER'}


class CURVED_REFLECTIONS_OT_refresh(_LiveOperator, bpy.types.Operator):
    """Capture the scene again and rebuild the reflections of every live view now"""

    bl_idname = "curved_reflections.refresh"
    bl_label = "Refresh"
    bl_options = {'REGISTER'}
    refresh_only = True


class CURVED_REFLECTIONS_OT_clear(bpy.types.Operator):
    """Stop drawing live reflections and free their memory"""

    bl_idname = "curved_reflections.clear"
    bl_label = "Clear"
    bl_options = {'REGISTER'}

    @classmethod
    def poll(cls, context):
        return context.scene is not None

    def execute(self, context):
        if live.clear(context.scene):
            self.report({'INFO'}, "Cleared the live reflections")
        return {'FINISHED'}


classes = (
    CURVED_REFLECTIONS_OT_start_live,
    CURVED_REFLECTIONS_OT_refresh,
    CURVED_REFLECTIONS_OT_clear,
)
