# SPDX-License-Identifier: GPL-3.0-or-later
"""The live view's accuracy check of the last view drawn, once it has settled.

The answers the view drew are read back from the GPU on the drawing thread and measured
(``accuracy.measure``: their error and the exact images they missed) on a worker: exact
solves take tenths of a second, which the viewport must not wait for. A later call of
the timer takes the figures up for the panel, and Auto plans again where a method
measured outside the Accuracy (``method_plan.note_measured``). Once that check has
started, the next draw of the resting view compares a chosen mode's picture with the
same view ray traced (``picture_check.py``), once per renderer: two frames drawn
offscreen, on the drawing thread (the GPU's).
"""

from __future__ import annotations

from concurrent.futures import Future

from . import accuracy, live_workers, method_plan
from .live_state import LiveScene
from .picture_check import check_picture, judged


def check_when_settled(state: LiveScene, scene, now: float, wait: bool) -> tuple[bool, bool]:
    """Start the check of the last view once it has not changed for
    ``accuracy.SETTLE_SECONDS`` (at once, and measured here, with ``wait``), and take up
    a finished one (:func:`_take_check`). Returns (whether a check is still to come or
    the plan changed, whether one landed: redraw)."""
    if state.checking is not None:
        return _take_check(state, scene)
    if state.last_view is None or state.last_view[3] or state.renderer is None:
        return False, False
    view, since, camera, _ = state.last_view
    if not wait and now - since < accuracy.SETTLE_SECONDS:
        return True, False
    state.last_view = (view, since, camera, True)
    renderer, plan, reflector_set = state.renderer, state.plan, state.reflector_set
    answered = renderer.answered()

    def check() -> dict:
        drawn = accuracy.drawn_answers(reflector_set, renderer, camera, answered=answered)
        return accuracy.measure(plan, reflector_set, renderer, view, camera, drawn=drawn)

    if wait:
        future = Future()
        try:
            future.set_result(check())
        except Exception as error:  # noqa: BLE001 - reported by _take_check
            future.set_exception(error)
    else:
        future = live_workers.tracer().submit(check)
    state.checking = (future, renderer)
    return _take_check(state, scene)


def _take_check(state: LiveScene, scene) -> tuple[bool, bool]:
    """The finished check's figures for the panel; Auto plans again when a method
    measured outside the Accuracy. A check of a renderer the scene has replaced since is
    dropped. Returns as :func:`check_when_settled`."""
    future, renderer = state.checking
    if not future.done():
        return True, False
    state.checking = None
    if renderer is not state.renderer:
        return False, False
    try:
        found = future.result()
    except Exception as error:  # noqa: BLE001 - a failed check must not stop the live view's timer
        state.report('WARNING', f"Accuracy check failed: {type(error).__name__}: {error}")
        return False, False
    state.counts["checks"] += 1
    if method_plan.note_measured(scene, found):
        state.dirty_reflectors = True  # plan again: the replaced method's reflector changes hands
    return state.dirty_reflectors, True


def check_picture_at_rest(state: LiveScene, scene, view, camera) -> bool:
    """Draw ``view`` (with ``camera``, the sample-based camera it was drawn with, or None)
    offscreen and compare a chosen mode's picture with the trace's
    (``picture_check.check_picture``) once per renderer, when the view has rested (its
    accuracy check started). Returns whether a method was passed over: the timer plans
    again."""
    if state.picture_checked is state.renderer or state.last_view is None or not state.last_view[3]:
        return False
    state.picture_checked = state.renderer
    if not judged(scene, state.plan):
        return False
    image = state.renderer.render(view, camera, state.world)
    if not check_picture(scene, state, view, image):
        return False
    state.dirty_reflectors = True
    return True
