# SPDX-License-Identifier: GPL-3.0-or-later
"""The live view's hooks into Blender: the 3D views' draw handler, the depsgraph, load
and save handlers, and the listener of :mod:`.scene_changes`; attached on register and
all removed on unregister (with the live view's timer, threads and state, ``live.shutdown``).
"""

from __future__ import annotations

import bpy
from bpy.app.handlers import persistent

from ..drawing.shader_cache import release_shaders
from . import live, morph_bake, scene_changes, scene_status, star_maps
from .capture import view_from_region

_draw_handle = None


def _draw_viewport() -> None:
    """POST_VIEW handler of every 3D view."""
    context = bpy.context
    scene, space, region, rv3d = context.scene, context.space_data, context.region, context.region_data
    if scene is None or space is None or rv3d is None or region is None:
        return
    if space.type != 'VIEW_3D' or space.shading.type not in live.SHADING_TYPES or live.state_of(scene) is None:
        return
    if region.width < 2 or region.height < 2:
        return
    live.draw_safely(scene, region.as_pointer(), view_from_region(region, rv3d))



def classify_updates(scene, state: live.LiveScene, updates) -> tuple[bool, bool]:
    """(reflectors changed, diffuse meshes changed) for a depsgraph's ``updates``.

    A reflector changes when one is moved or its geometry edited, when the set of
    marked objects differs from the baked one, or when a method setting changed (a new
    camera for every view); any other object's geometry or transform, a material, a
    world or a collection (objects added, removed, hidden) changes the meshes. Setting
    a property, from the UI or from Python, tags its object (or scene) for the
    depsgraph with geometry and transform updated (checked in the bpy module), so a
    reflector's Reflectivity re-bakes too: the flags cannot tell it from an edit.
    """
    reflectors = live.marked_reflectors(scene) != state.reflector_names or live.scene_settings(scene) != state.settings
    meshes = False
    for update in updates:
        data = update.id
        if isinstance(data, bpy.types.Object):
            if not (update.is_updated_geometry or update.is_updated_transform):
                continue
            if data.original.curved_reflections.is_reflector:
                reflectors = True
            else:
                meshes = True
        elif isinstance(data, (bpy.types.Material, bpy.types.World, bpy.types.Collection)):
            meshes = True
    return reflectors, meshes


@persistent
def on_depsgraph_update(scene, depsgraph) -> None:
    """``depsgraph_update_post``: mark the baked scene's changes for the timer (with a
    window) or process them now (background mode, where timers never run)."""
    state = live.state_of(scene)
    if state is None or not scene.curved_reflections.auto_refresh:
        return
    try:
        reflectors, meshes = classify_updates(scene, state, depsgraph.updates)
        state.dirty_reflectors |= reflectors
        state.dirty_meshes |= meshes
        if not (reflectors or meshes):
            return
        if bpy.app.background:
            live.process(scene, depsgraph, wait=True)
        else:
            live.ensure_timer()
    except Exception as error:  # noqa: BLE001
        state.report('ERROR', f"Live update failed: {type(error).__name__}: {error}")


def on_setting_changed(context, reflectors: bool = False, meshes: bool = False) -> None:
    """The live view's listener of :mod:`.scene_changes` (settings, bakes).

    Setting a property does not reliably reach ``depsgraph_update_post``: in the bpy
    module, after a modifier was added, ticking Reflector from Python produced no
    update at all, and at other times the update came at a later evaluation. So the
    baked scene is told here too; with a window both land in the same timer tick.
    ``reflectors``: the set of reflectors changed (re-bake); ``meshes``: a reflector's
    appearance changed (new renderer only).
    """
    scene = getattr(context, "scene", None)
    state = None if scene is None else live.state_of(scene)
    if state is None or not scene.curved_reflections.auto_refresh:
        return
    state.dirty_reflectors |= reflectors
    state.dirty_meshes |= meshes
    if bpy.app.background:
        live.process(scene, context.evaluated_depsgraph_get(), wait=True)
    else:
        live.ensure_timer()


@persistent
def on_load_pre(*_args) -> None:
    """Loading a file drops every live state and morphing status (no state leaks between files)."""
    live.clear_all()
    scene_status.forget_all()
    star_maps.forget()


@persistent
def on_load_post(*_args) -> None:
    """Re-attach the handlers after a file load (they are persistent; this only repairs)."""
    _attach_app_handlers()


_APP_HANDLERS = (
    ("depsgraph_update_post", on_depsgraph_update),
    ("load_pre", on_load_pre),
    ("load_post", on_load_post),
    ("save_pre", morph_bake.on_save_pre),
    ("save_post", morph_bake.on_save_post),
)


def _same_function(a, b) -> bool:
    """Also true for a handler of an earlier import of this module (an add-on reload)."""
    return a is b or (getattr(a, "__qualname__", None) == b.__qualname__
                      and getattr(a, "__module__", None) == b.__module__)


def _attach_app_handlers() -> None:
    for name, function in _APP_HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        if not any(_same_function(h, function) for h in handlers):
            handlers.append(function)


def register() -> None:
    global _draw_handle
    _attach_app_handlers()
    scene_changes.connect(on_setting_changed)
    if _draw_handle is None:
        _draw_handle = bpy.types.SpaceView3D.draw_handler_add(_draw_viewport, (), 'WINDOW', 'POST_VIEW')


def unregister() -> None:
    """Remove the draw handler, the app handlers and the timer; drop all state and the
    GPU shaders built."""
    global _draw_handle
    scene_changes.disconnect(on_setting_changed)
    if _draw_handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_draw_handle, 'WINDOW')
        _draw_handle = None
    for name, function in _APP_HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        for handler in [h for h in handlers if _same_function(h, function)]:
            handlers.remove(handler)
    live.shutdown()
    scene_status.forget_all()
    star_maps.forget()
    release_shaders()
