# SPDX-License-Identifier: GPL-3.0-or-later
"""The live view's ray-traced pixels: what the drawn reflections cannot place, traced on
a worker and drawn over the view they were traced for (``drawing/traced_pixels.py``).

Two kinds, both on the live view's tracing thread (``live_workers.tracer``):

- **a camera's doubtful cells**, as soon as the camera's own view is drawn: the cells
  where it marks its projection unreliable (a crumpled mirror shows a point many times,
  and the camera places some images only), and those it cannot reach
  (``traced_pixels.trace_doubtful``).
- **the band of a resting view**: once a view has not changed for
  ``accuracy.SETTLE_SECONDS``, the next draw of it picks the same pixels Render Image
  traces (``ReflectionRenderer.band_selection``: along each reflection's edge, next to a
  searched mirror's silhouette, where the near plane cuts a mirror), and they are traced
  for that view. The resting view's reflections are drawn placed exactly too, not
  snapped within the Accuracy. So the viewport at rest shows Render Image's picture,
  while a moving view keeps the snapping and the composite's cheap fill, which no frame
  waits for. Its pixels include a
  camera's doubtful cells, and are drawn instead of them once they land.
"""

from __future__ import annotations

import weakref
from concurrent.futures import Future
from dataclasses import dataclass

from ..drawing.reflection_draw import MAX_TRACED_FRACTION
from ..drawing.traced_pixels import TracedPixels, trace_doubtful, traced_rgba
from ..engine.view import View
from . import accuracy, live_workers
from .live_state import LiveScene, Tracing, ViewCamera


@dataclass
class BandTrace:
    """The band of one resting view: asked for by the timer, its pixels picked by the
    next draw of that view, traced on the worker (``future`` -> TracedPixels or None)."""

    view: View
    #: The renderer it is traced for (its meshes and passes), weakly: a replaced
    #: renderer's GPU textures must not outlive it here.
    renderer: weakref.ref
    camera: object  # the sample-based camera the view was drawn with (None: none)
    future: Future | None = None  # None until a draw has picked the pixels
    redrawn: bool = False  # whether its landing asked for a redraw


def want_band_when_settled(state: LiveScene, now: float) -> bool:
    """Ask for the band of the last view drawn once it has not changed for
    ``accuracy.SETTLE_SECONDS`` (by the clock, ``now``). Returns whether it was asked
    for now: the caller redraws, and that draw picks the pixels (:func:`start_band`)."""
    if state.last_view is None or state.renderer is None:
        return False
    view, since, camera = state.last_view[:3]
    if now - since < accuracy.SETTLE_SECONDS or resting(state, view, camera):
        return False
    state.band = BandTrace(view, weakref.ref(state.renderer), camera)
    return True


def resting(state: LiveScene, view: View, camera) -> bool:
    """Whether ``view``, drawn with the sample-based ``camera`` (None: none), is the
    resting view whose band was asked for: its reflections are then drawn placed
    exactly, as Render Image places them, not snapped within the Accuracy (the speed
    of a moving view: ``reflected_meshes.SNAP_SHARE``)."""
    band = state.band
    return (band is not None and band.renderer() is state.renderer and band.camera is camera
            and band.view.same_as(view))


def start_band(state: LiveScene, view: View, targets, camera, source) -> bool:
    """After a draw of ``view`` into ``targets`` (``ReflectionRenderer.draw``), with the
    sample-based ``camera`` and its projection ``source`` (both None without one): pick
    the band's pixels and start tracing them when this view's band was asked for and is
    not picked yet. Returns whether it started (the timer then polls for it)."""
    band, renderer = state.band, state.renderer
    if not resting(state, view, camera) or band.future is not None:
        return False
    max_order = max((len(history) for history in source.groups), default=1) if source is not None else 1
    radius = 0 if source is None else source.downsample
    if camera is not None and not view.same_as(camera.ray_map.view):
        camera = None  # its ray map's cells are another view's pixels
    selection = renderer.band_selection(view, targets, max_order, radius, ray_map=None if camera is None
                                        else camera.ray_map, camera=camera)
    if selection is None:
        band.future = Future()
        band.future.set_result(None)
        return False
    pixels, surface = selection
    world, source = state.world, renderer.tracer_source
    # The renderer's tracer (a tree of the diffuse meshes) is made on the worker too; the
    # job holds nothing of the GPU (see ``band_trace.TracerSource``).
    band.future = live_workers.tracer().submit(
        lambda: TracedPixels(view, pixels, traced_rgba(source.get(), view, pixels, max_order, world, surface)))
    return True


def camera_traced(state: LiveScene, camera: ViewCamera | None, view: View):
    """The pixels of ``camera``'s unreliable cells, traced, when ``view`` is the camera's
    own and they are ready for this renderer (its meshes); else None, and unless they
    are being traced, they start on the worker (``traced_pixels.trace_doubtful``).
    Returns (the traced pixels or None, whether a trace started: the timer polls)."""
    if camera is None or camera.sbc is None or not view.same_as(camera.view):
        return None, False
    started = False
    if camera.tracing is None or camera.tracing.renderer() is not state.renderer:
        source, sbc = state.renderer.tracer_source, camera.sbc
        max_order, world = camera.settings.max_order, state.world
        # The renderer's tracer (a tree of the diffuse meshes) is made on the worker too.
        future = live_workers.tracer().submit(
            lambda: trace_doubtful(source.get(), sbc, max_order, world, MAX_TRACED_FRACTION))
        camera.tracing, started = Tracing(weakref.ref(state.renderer), future), True
    future = camera.tracing.future
    if not future.done():
        return None, started
    try:
        return future.result(), started
    except Exception as error:  # noqa: BLE001 - the camera's own answers keep drawing
        camera.tracing = Tracing(weakref.ref(state.renderer), Future(), redrawn=True)
        camera.tracing.future.set_result(None)
        state.report('WARNING', f"Tracing the reflections failed: {type(error).__name__}: {error}")
        return None, started


def band_traced(state: LiveScene, view: View, camera) -> TracedPixels | None:
    """The resting band of ``view``, when it is traced for this renderer and the
    sample-based ``camera`` drawing it."""
    band = state.band
    if not resting(state, view, camera) or band.future is None or not band.future.done():
        return None
    try:
        return band.future.result()
    except Exception as error:  # noqa: BLE001 - the drawn reflections keep drawing
        band.future = Future()
        band.future.set_result(None)
        state.report('WARNING', f"Tracing the reflections failed: {type(error).__name__}: {error}")
        return None


def traces_landed(state: LiveScene) -> tuple[bool, bool]:
    """(whether some traced pixels landed since the last call: redraw, whether some are
    still being traced: keep polling)."""
    landed = pending = False
    tracings = [camera.tracing for camera in state.cameras.values()]
    if state.band is not None and state.band.future is not None:
        tracings.append(state.band)
    for tracing in tracings:
        if tracing is not None and not tracing.redrawn:
            if tracing.future.done():
                tracing.redrawn = landed = True
            else:
                pending = True
    return landed, pending



def wait_for_traces(state: LiveScene, timeout: float = 60.0) -> int:
    """Block until every trace under way has landed (background mode: what a viewport
    shows once the worker caught up). Returns how many pixels the last view's band and
    the cameras traced, together."""
    traced = 0
    tracings = [camera.tracing for camera in state.cameras.values()] + [state.band]
    for tracing in tracings:
        if tracing is not None and tracing.future is not None:
            result = tracing.future.result(timeout=timeout)
            traced += 0 if result is None else len(result.pixels)
    return traced
