# SPDX-License-Identifier: GPL-3.0-or-later
"""Live reflections in the 3D viewport: per-scene state, draw handler, timers, depsgraph handler.

The frame pipeline of :mod:`.frame_pipeline` (the same stages, and the same rule for
when a view needs a sample-based camera, as Render Image), scheduled by what changes
how often (SBC paper, Popescu, Sacks, Mei 2006, section IV: the sample-based camera
belongs to one view; V: projection runs per draw on the GPU):

- **capture** (main thread, needs ``bpy``): the evaluated scene as reflectors and
  diffuse meshes (:mod:`.capture`), and a :class:`ReflectionRenderer` holding the
  meshes' GPU batches, with the reflectors' colour, reflectivity, Fresnel and fade
  distance (:func:`.render_inputs.reflector_properties`, SBC V-D). Moving or editing a
  *diffuse* object re-captures and re-uploads only this, and re-projects once: the
  cameras stay valid (unless the object leaves the camera's scene box, which ends its
  reflected rays: then they are rebuilt).
- **camera** per view (worker thread, bpy-free, :mod:`.live_workers`): the ray map and
  BSP trees of ``build_sample_based_camera``. A view change asks for a new one,
  debounced (:data:`DEBOUNCE_SECONDS` after the last change); while it builds, the
  previous camera keeps drawing. Editing a *reflector* (geometry, transform, marking
  or unmarking one) captures the reflectors again and rebuilds every view's camera.
  Reflectors of more than :data:`BACKGROUND_TRIANGLES` are made ready for tracing (BVH, seal) on
  the worker too (:class:`.live_state.Preparing`): the last reflections draw, and the
  status line counts the seconds, until they land.
- **projection** (once per camera and per mesh change): the meshes' vertices
  projected with the camera, kept by the renderer as reflected triangles whose
  vertices sit at their *first reflector points in world space*
  (``camera_pass.CameraPass``). A new camera's is made on the worker right
  after it, with numpy (``camera_source.CameraSource``), and only put on the GPU by
  the first draw after it landed; after a mesh change the next draw projects on the
  GPU (main thread). Not on every redraw.
- **per-frame passes** (the iterative search, baked morphing grids, perturbation: one
  per registered method, ``method_registry.py``): drawn by the renderer on every
  redraw; a view change builds nothing for their reflectors, and the runtime camera,
  when another reflector or a higher order still needs one, leaves their first-order
  sheets out. A view outside a reflector's grid draws it in runtime mode, and the panel
  says so. Work a pass does off the drawing thread (morphing nodes around the eye) runs
  on a worker between redraws (``FramePass.prefetch``).
- **traced pixels** (worker thread, :mod:`.live_traces`): once a camera's own view is
  drawn, the mirror pixels of the cells where it marks its projection unreliable; once
  any view rests, the band Render Image traces (reflections' edges, mirrors'
  silhouettes). They are ray traced and drawn over the reflections of that view only.
- **draw** (``SpaceView3D`` POST_VIEW handler, every redraw): the reflections of the
  region's view over the reflectors (``reflectors_only``), with the last camera built
  for that region: the cached reflected triangles placed by the current view's
  matrices, so while a new camera builds after the view moved, the reflection stays on
  the mirror (the old camera's reflector points in world space), nearly right, instead
  of lagging as an image of the old view. Exceptions never escape a redraw: they stop
  drawing for the scene and become its status line in the panel.

Background mode (``blender -b``, ``import bpy``) has neither 3D views nor a running
timer loop, so everything also works with explicit views (:class:`~..engine.view.View`
from the scene camera or from matrices) and ``wait=True`` (the camera is built in the
calling thread); there the depsgraph handler processes a change at once instead of
leaving it to the timer. Nothing here keeps a ``bpy`` object: state is keyed by the
scene's ``session_uid`` and holds numpy arrays and GPU resources only, and all of it is
dropped when a file is loaded.
"""

from __future__ import annotations

import time
from concurrent.futures import Future

import bpy
import numpy as np

from ..engine.errors import SceneInputError
from ..engine.heap import release_freed_memory
from ..engine.methods.iterative.pieces import searched_methods
from ..engine.methods.morphing.morphing import ViewOutsideGrid
from ..engine.scene import scene_bounds
from ..engine.view import View
from ..drawing.methods.sbc_gpu import SBCTextures
from . import live_check, live_status, live_traces, live_workers, method_plan, method_registry, morph_bake
from .capture import capture_scene, view_from_camera
from .frame_pipeline import settings_of
from .live_state import CameraBuild, LiveScene, Preparing, ViewCamera
from .scene_status import status_of

#: Seconds after the last view change before its camera is rebuilt.
DEBOUNCE_SECONDS = 0.15
#: Interval of the timer that starts debounced builds, collects finished ones and
#: processes scene edits; it unregisters itself when nothing is pending.
POLL_SECONDS = 0.05
#: Viewport shading modes drawn over (Wireframe and Rendered are left alone).
SHADING_TYPES = frozenset({'SOLID', 'MATERIAL'})
#: Cameras kept per scene (one per 3D view region); the least recently drawn goes first.
MAX_VIEWS = 8
#: Seconds between read-backs of the iterative search's unanswered vertices (panel stats).
COUNT_SECONDS = 2.0
#: Reflectors of more triangles than this (all together) are made ready for tracing on
#: the worker when the viewport should not wait: a million-triangle mirror's BVH and seal
#: take seconds (docs/benchmarks/cliffs.md), which the main thread must not spend.
BACKGROUND_TRIANGLES = 100_000
#: Key of the view a Start or Refresh uses when there is no 3D view (background mode).
CAMERA_KEY = "scene camera"


_states: dict[int, LiveScene] = {}


def state_of(scene) -> LiveScene | None:
    """The live state of ``scene``, or ``None`` when it is not started."""
    return _states.get(scene.session_uid)


def scene_settings(scene):
    """The live view's frame settings of ``scene`` (``frame_pipeline.settings_of``)."""
    return settings_of(scene, live=True)


# --- capture (main thread) -----------------------------------------------------------


def _capture(state: LiveScene, scene, depsgraph, reflectors: bool, wait: bool = True) -> bool:
    """Capture the scene into ``state``: a new renderer; with ``reflectors`` also a new
    reflector set (a new generation: every camera is rebuilt). Reflectors of more than
    BACKGROUND_TRIANGLES together are made ready for tracing on the worker unless
    ``wait``: returns False then, the capture landing later (``_finish_preparing``)."""
    remesh = not (reflectors or state.reflector_set is None)
    captured = capture_scene(depsgraph, reflectors_as_before=state.captured.reflectors if remesh else None)
    if remesh and [r.name for r in captured.reflectors] != [r.name for r in state.captured.reflectors]:
        # A reflector hidden, shown or renamed sends no update of its own: the meshes'
        # capture finds it, and the reflectors are captured again with them.
        remesh = False
        captured = capture_scene(depsgraph)
    scene_bounds(captured.reflectors, captured.meshes)  # bad input raises here, before any work
    if not captured.reflectors:  # glass alone: no mirror to prepare or build cameras for
        state.glass_alone(scene, captured)
        state.generation += 1
        state.counts["captures"] += 1
        state.drawing = True
        return True
    if remesh:
        state.counts["remeshes"] += 1
        _renew_renderer(state, scene, captured, seal=True)
        return True
    triangles = captured.reflector_triangles
    if wait or triangles <= BACKGROUND_TRIANGLES:
        _adopt(state, scene, captured, live_workers.prepare_reflectors(captured.reflectors, captured.meshes))
        return True
    future = live_workers.builder().submit(live_workers.prepare_reflectors, captured.reflectors, captured.meshes)
    state.preparing = Preparing(future, captured, time.monotonic(), triangles)
    _report_preparing(state)
    return False


def _capture_failed(state: LiveScene, error: SceneInputError) -> None:
    """The scene cannot be captured (its only mirror deleted, hidden or unmarked, a
    mirror left without faces...): the last renderer holds mirrors the scene no longer
    has, so nothing is drawn, and cameras on their way are dropped (a new generation),
    until a capture succeeds; the status line says why."""
    state.report('ERROR', str(error))
    state.drawing = False
    state.generation += 1


def _adopt(state: LiveScene, scene, captured, reflector_set) -> None:
    """Make ``captured``'s reflectors, ready for tracing in ``reflector_set``, the state's."""
    state.reflector_set = reflector_set
    state.reflector_names = marked_reflectors(scene)
    state.plan_reflectors(scene, captured)
    state.generation += 1
    state.counts["captures"] += 1
    _renew_renderer(state, scene, captured, seal=False)


def _renew_renderer(state: LiveScene, scene, captured, seal: bool) -> None:
    # A new renderer has no projection: the next draw projects with the view's camera
    # once (SBC V-A), and later draws reuse it until a camera lands or the meshes change.
    state.new_renderer(scene, captured, seal=seal)
    state.drawing = True


def _report_preparing(state: LiveScene) -> None:
    preparing = state.preparing
    names = ", ".join(repr(r.name) for r in preparing.captured.reflectors)
    state.report('INFO', f"Preparing {names} for ray tracing ({preparing.triangles:,} triangles, "
                         f"{time.monotonic() - preparing.started:.0f} s); the last reflections draw meanwhile")


def _finish_preparing(state: LiveScene, scene, wait: bool) -> bool:
    """Adopt the capture prepared on the worker once ready (with ``wait``, now): returns
    whether it landed (the status shows the progress until then)."""
    preparing = state.preparing
    if not (wait or preparing.future.done()):
        _report_preparing(state)
        return False
    state.preparing = None
    _adopt(state, scene, preparing.captured, preparing.future.result())
    state.report('INFO', "Building reflections...")
    return True


def _restart_stale(state: LiveScene, reflectors: bool, wait: bool) -> None:
    """Rebuild the cameras a new capture made stale: all after new reflectors, those
    whose bounds no longer hold the scene after new meshes."""
    if state.renderer is None:  # glass alone: no camera to build
        state.cameras.clear()
        return
    stale = {key: c.view for key, c in state.cameras.items() if reflectors or not _inside(state.bounds, c.bounds)}
    for key, view in stale.items():
        if key not in state.requests:
            _start_camera(state, key, view, wait)


def _covering_grids(state: LiveScene, view: View) -> list:
    """The grids whose reflector ``view`` can be drawn from in morphing mode; each
    reflector's panel line says which mode draws it and why. A grid whose cache was
    found damaged is not used (its line names the file; a bake repairs it)."""
    covering = []
    for grid, matrix in state.grids:
        if grid.failure is not None:
            morph_bake.note_cache_fault(state.scene_status, grid.reflector_name, grid.failure)
            continue
        try:
            grid.check_view(view, matrix)
        except ViewOutsideGrid as error:
            morph_bake.note_runtime_fallback(state.scene_status, error)
            continue
        morph_bake.note_morphing_active(state.scene_status, grid.reflector_name)
        covering.append((grid, matrix))
    return covering


def marked_reflectors(scene) -> frozenset:
    return frozenset(o.name for o in scene.objects if o.curved_reflections.is_reflector)


def _inside(bounds, camera_bounds) -> bool:
    return bool(np.all(bounds[0] >= camera_bounds[0]) and np.all(bounds[1] <= camera_bounds[1]))


# --- cameras (worker thread) ---------------------------------------------------------


def _start_camera(state: LiveScene, key, view: View, wait: bool) -> None:
    """Build ``view``'s camera, if it needs one: on the worker, or here and now with ``wait``."""
    state.requests.pop(key, None)
    job, covering = state.camera_job(view), _covering_grids(state, view)
    maker = state.renderer.camera_pass.maker
    future = Future()
    if job is None:
        future.set_result((None, None))
    elif wait:
        try:
            future.set_result(live_workers.build_camera(job, maker))
        except Exception as error:  # noqa: BLE001 - reported as the status line
            future.set_exception(error)
    else:
        future = live_workers.builder().submit(live_workers.build_camera, job, maker)
    bounds = state.camera_bounds() if job is None else job.bounds
    state.jobs[key] = CameraBuild(future, view, bounds, state.settings, state.generation, covering, maker)
    if future.done():
        _collect(state)


def _collect(state: LiveScene) -> bool:
    """Store the cameras that finished; returns whether any did."""
    finished = False
    for key, build in list(state.jobs.items()):
        future = build.future
        if not future.done():
            continue
        del state.jobs[key]
        finished = True
        try:
            sbc, projected = future.result()
        except Exception as error:  # noqa: BLE001 - a bug must not stop the viewport either
            message = str(error) if isinstance(error, SceneInputError) else (
                f"Building the reflections failed: {type(error).__name__}: {error}")
            state.report('ERROR', message)
            # Nothing is drawn for this view, and it is not retried until it changes.
            state.cameras.pop(key, None)
            state.failed[key] = build.view
            continue
        if build.generation != state.generation:
            continue  # built for reflectors that have changed since
        state.failed.pop(key, None)
        state.cameras[key] = ViewCamera(build.view, sbc, build.bounds, build.settings, build.generation,
                                        build.covering, last_drawn=time.monotonic(),
                                        projected=None if projected is None else (build.maker, projected))
        state.counts["builds"] += 1
        live_status.update_stats(state, sbc, build.covering)
        live_status.report_visibility(state, build.view, sbc)
    while len(state.cameras) > MAX_VIEWS:
        oldest = min(state.cameras, key=lambda k: state.cameras[k].last_drawn)
        del state.cameras[oldest]
    if finished:
        release_freed_memory()  # the build's ray map and trees, freed on the worker
    return finished


# --- the public operations ------------------------------------------------------------


def start(scene, depsgraph, views: dict | None = None, wait: bool = False) -> LiveScene:
    """Capture ``scene`` and build a camera for each of ``views`` ({key: View}).

    Without views, the regions already drawn keep their keys and get new cameras; with
    none at all (background mode), the scene camera's view under :data:`CAMERA_KEY`.
    Bad input raises :class:`SceneInputError` (also kept as the status line).
    """
    state = _states.setdefault(scene.session_uid, LiveScene())
    state.settings = scene_settings(scene)
    state.scene_status = status_of(scene)
    state.dirty_reflectors = state.dirty_meshes = False
    try:
        ready = _capture(state, scene, depsgraph, reflectors=True, wait=wait)
        if views is None:
            views = {key: camera.view for key, camera in state.cameras.items()}
            views.update({key: build.view for key, build in state.jobs.items()})
            views.update(state.failed)
            if not views:
                views = {CAMERA_KEY: view_from_camera(scene.camera, scene, depsgraph)}
    except SceneInputError as error:
        _capture_failed(state, error)
        raise
    state.failed.clear()
    if not ready:  # the views' cameras are built once the reflectors are ready
        state.requests.update({key: (view, 0.0) for key, view in views.items()})
        ensure_timer()
        return state
    if state.renderer is None:  # glass alone: drawn per frame, nothing to build
        state.report('INFO', "Reflections up to date")
        return state
    state.report('INFO', "Building reflections...")
    for key, view in views.items():
        _start_camera(state, key, view, wait)
    if not wait:
        ensure_timer()
    return state


def refresh(scene, depsgraph, views: dict | None = None, wait: bool = False) -> LiveScene:
    """Re-capture the scene and rebuild every view's camera now (what **Refresh** does);
    Auto tries again the methods a live check passed over."""
    method_plan.forget_measurements(scene)
    return start(scene, depsgraph, views, wait)


def clear(scene) -> bool:
    """Forget ``scene``'s live state: nothing is drawn until the next bake."""
    state = _states.pop(scene.session_uid, None)
    if state is not None:
        for build in state.jobs.values():
            build.future.cancel()
    tag_redraw()
    return state is not None


def clear_all() -> None:
    for state in _states.values():
        for build in state.jobs.values():
            build.future.cancel()
    _states.clear()


def request_view(state: LiveScene, key, view: View) -> None:
    """Ask for ``view``'s camera after the debounce delay (a newer request restarts it)."""
    previous = state.requests.get(key)
    if previous is None or not previous[0].same_as(view):
        state.requests[key] = (view, time.monotonic())
    ensure_timer()


def process(scene, depsgraph, wait: bool = False, now: float | None = None) -> bool:
    """One step of live work for ``scene``: edits, due view requests, finished cameras.

    What the timer runs; returns whether work is still pending.
    """
    state = state_of(scene)
    if state is None:
        return False
    now = time.monotonic() if now is None else now
    try:
        settings = scene_settings(scene)
        if settings != state.settings:  # a method setting changed: new cameras for every view
            state.settings = settings
            state.dirty_reflectors = True
        if state.preparing is not None and _finish_preparing(state, scene, wait):
            _restart_stale(state, True, wait)
        # Edits made while reflectors are prepared wait for them (the capture then is stale).
        if state.preparing is None and (state.dirty_reflectors or state.dirty_meshes):
            reflectors = state.dirty_reflectors
            state.dirty_reflectors = state.dirty_meshes = False
            if _capture(state, scene, depsgraph, reflectors, wait):
                _restart_stale(state, reflectors, wait)
        for key, (view, asked) in list(state.requests.items()):
            if state.renderer is None:  # glass alone
                state.requests.pop(key)
            elif state.preparing is None and (wait or (now - asked >= DEBOUNCE_SECONDS and key not in state.jobs)):
                _start_camera(state, key, view, wait)
    except SceneInputError as error:
        _capture_failed(state, error)
    except Exception as error:  # noqa: BLE001 - the worker's preparation failed: say so, draw the last
        state.preparing = None
        state.report('ERROR', f"Preparing the reflectors failed: {type(error).__name__}: {error}")
    passes = () if state.renderer is None else state.renderer.passes
    traced, tracing = live_traces.traces_landed(state)
    if _collect(state) or any(frame_pass.prefetched for frame_pass in passes) or traced:
        tag_redraw()
    checking, landed = live_check.check_when_settled(state, scene, now, wait)
    if live_traces.want_band_when_settled(state, now):
        landed = tracing = True  # the next draw picks the band's pixels
    if landed:
        tag_redraw()
    if checking and not wait:
        ensure_timer()  # the check runs on a worker: the timer takes it up
    return bool(state.jobs or state.requests or state.dirty_meshes or state.dirty_reflectors or tracing
                or state.preparing is not None or any(frame_pass.prefetching for frame_pass in passes) or checking)


def draw(scene, key, view: View) -> bool:
    """Draw ``scene``'s reflections of ``view`` over its reflectors into the bound
    framebuffer (viewport = the view's rectangle), with the camera built for ``key``.

    A view that differs from the camera's asks for a new camera (with Auto Refresh);
    meanwhile the old one draws: its reflected triangles are cached in world space
    (``camera_pass.CameraPass``), so any view, of any size, places them. The
    projection runs on the first draw with a camera (one landed, or the renderer is new
    after a mesh change) and is reused by later draws. Returns whether anything was
    drawn. Raises what drawing raises (the callers catch it).
    """
    state = state_of(scene)
    if state is None or not state.drawing:
        return False
    if state.renderer is None:  # glass alone
        return _draw_glass(state, view, exact=False) if state.glass is not None else False
    failed = state.failed.get(key)
    if failed is not None and failed.same_as(view):
        return False  # the status line says why; a new view or a Refresh tries again
    if state.camera_job(view) is None:
        # Every reflector is drawn by a per-frame pass: nothing to build when the view changes.
        covering = _covering_grids(state, view)
        state.stats["morphing"] = ", ".join(grid.reflector_name for grid, _ in covering)
        inside = _reflector_around(state, view)
        if inside is not None:
            state.report('ERROR', f"{inside!r}: the view is inside this reflector; move the view outside it")
            return False
        if state.level == 'ERROR' and "the view is inside" in state.status:
            state.report('INFO', "Reflections up to date")
        drawn = _draw_with(state, scene, view, None)
        damaged = [grid for grid, _ in covering if grid.failure is not None]
        for grid in damaged:  # the panel names the file
            morph_bake.note_cache_fault(state.scene_status, grid.reflector_name, grid.failure)
        if damaged:
            request_view(state, key, view)  # their reflectors need a camera now
        return drawn
    camera = state.cameras.get(key)
    current = (camera is not None and camera.generation == state.generation and camera.settings == state.settings
               and camera.first_orders_drawn(state.renderer.per_frame_reflectors))
    if (camera is None or not current or not camera.view.same_as(view)) and key not in state.jobs:
        if scene.curved_reflections.auto_refresh or camera is None:
            request_view(state, key, view)
    if camera is None:
        return False
    camera.last_drawn = time.monotonic()
    return _draw_with(state, scene, view, camera)


def _projection_source(state: LiveScene, camera: ViewCamera | None):
    """What ``camera`` draws with (``None`` without a sample-based camera): its source
    while the renderer keeps that projection, or while it is the camera's GPU textures;
    else the worker's projection, put on the GPU now, while it was made for this
    renderer and its per-frame passes; else (the meshes changed since, or it was
    dropped) the camera's GPU textures, which project on this draw."""
    if camera is None or camera.sbc is None:
        return None
    camera_pass = state.renderer.camera_pass
    if (camera.source is not None and camera.source.on_gpu) or camera_pass.holds(camera.source):
        return camera.source
    projected, camera.projected = camera.projected, None
    if projected is not None and projected[0] is camera_pass.maker and camera_pass.adopt(projected[1]):
        camera.source = projected[1].source
    else:
        camera.source = SBCTextures(camera.sbc)
    return camera.source


def _draw_with(state: LiveScene, scene, view: View, camera: ViewCamera | None) -> bool:
    """One draw of ``view`` with ``camera``'s projection (``None``: the per-frame passes
    alone); then the morphing nodes around the eye are prefetched, and at rest a chosen
    mode's picture is checked (``live_check.check_picture_at_rest``)."""
    start = time.perf_counter()
    projections = state.renderer.counts["projections"]  # a projection made or adopted now counts
    sbc = None if camera is None else camera.sbc
    source = _projection_source(state, camera)
    camera_traced, tracing = live_traces.camera_traced(state, camera, view)
    band = live_traces.band_traced(state, view, sbc)
    # A camera's own view rests (it is built once the view stops): drawn exactly too.
    resting = live_traces.resting(state, view, sbc) or (camera is not None and view.same_as(camera.view))
    targets = state.renderer.draw(view, source, state.world, reflectors_only=True, camera=sbc,
                                  accuracy_px=state.settings.accuracy_px, exact=resting,
                                  traced=camera_traced if band is None else band)
    _draw_glass(state, view, resting)
    if live_traces.start_band(state, view, targets, sbc, source) or tracing:
        ensure_timer()  # it redraws once they land
    if state.last_view is None or not state.last_view[0].same_as(view) or state.last_view[2] is not sbc:
        state.last_view = (view, time.monotonic(), sbc, False)
        ensure_timer()  # the timer checks it once it settles
    elif live_check.check_picture_at_rest(state, scene, view, sbc):
        ensure_timer()  # the timer plans again
    for frame_pass in state.renderer.passes:
        frame_pass.collect()
        if frame_pass.prefetch(view, live_workers.prefetcher().submit):
            ensure_timer()  # it redraws when the work is ready, which uploads it and starts the next
    if state.renderer.counts["projections"] != projections:
        state.counts["projections"] += 1
        state.stats["projection_ms"] = 1000.0 * state.renderer.stats.get("projection_seconds", 0.0)
    state.stats["draw_ms"] = 1000.0 * (time.perf_counter() - start)
    state.counts["draws"] += 1
    if time.monotonic() - state.stats.get("counted_at", -COUNT_SECONDS) >= COUNT_SECONDS:
        # The vertices the passes left unanswered, read back now and then (not every frame).
        counts = {index: found for frame_pass in state.renderer.passes
                  for index, found in frame_pass.status_counts().items()}
        state.stats["unanswered"] = sum(c["unanswered"] for c in counts.values())
        state.stats["searched"] = sum(c["found"] + c["unanswered"] for c in counts.values())
        state.stats["counted_at"] = time.monotonic()
    return True


def _draw_glass(state: LiveScene, view: View, exact: bool) -> bool:
    """The glass's own overlay (``glass_layer.GlassLayer.draw``): the refracted images
    on the glass over its reflections, placed exactly with ``exact`` (a resting view).
    Returns whether there was glass."""
    if state.glass is None:
        return False
    state.glass.draw(view, state.world, state.settings.accuracy_px, exact)
    return True


def _reflector_around(state: LiveScene, view: View) -> str | None:
    """The name of the searched reflector the (perspective) view's eye is inside, if any:
    a lookup in each reflector's map, no tracing."""
    if not view.is_perspective:
        return None
    eye = view.eye[None]
    searched = searched_methods(state.plan.engines_of(method_registry.ITERATIVE))
    return next((m.name for m in searched if m.reflector_map.inside(eye)[0]), None)


# --- Blender callbacks ---------------------------------------------------------------


def draw_safely(scene, key, view: View) -> bool:
    """:func:`draw` for a draw handler: an exception stops drawing for the scene and
    becomes its status line (one message, not a traceback on every redraw)."""
    state = state_of(scene)
    if state is None or not state.drawing:
        return False
    try:
        return draw(scene, key, view)
    except Exception as error:  # noqa: BLE001
        state.drawing = False
        state.report('ERROR', f"Drawing stopped: {type(error).__name__}: {error} (Refresh to retry)")
        return False


def _tick():
    """The timer: process the context scene's live work; unregisters when idle."""
    try:
        context = bpy.context
        scene = context.scene
        pending = False
        for uid, state in list(_states.items()):
            if scene is not None and scene.session_uid == uid:
                pending |= process(scene, context.evaluated_depsgraph_get())
            elif _collect(state):
                tag_redraw()
                pending |= bool(state.jobs)
        return POLL_SECONDS if pending else None
    except Exception as error:  # noqa: BLE001 - a timer that raises is dropped by Blender silently
        for state in _states.values():
            state.report('ERROR', f"Live update failed: {type(error).__name__}: {error}")
        return None


def ensure_timer() -> None:
    if not bpy.app.timers.is_registered(_tick):
        bpy.app.timers.register(_tick, first_interval=POLL_SECONDS)


def tag_redraw() -> None:
    window_manager = getattr(bpy.context, "window_manager", None)
    if window_manager is None:
        return
    for window in window_manager.windows:
        for area in window.screen.areas:
            if area.type == 'VIEW_3D':
                area.tag_redraw()


def shutdown() -> None:
    """Drop every state and stop the worker threads (the extension is unregistered)."""
    if bpy.app.timers.is_registered(_tick):
        bpy.app.timers.unregister(_tick)
    clear_all()
    live_workers.shutdown()
