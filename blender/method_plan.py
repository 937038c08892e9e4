# SPDX-License-Identifier: GPL-3.0-or-later
"""Which method draws each reflector, and why: the one place that decides.

A reflector's ``obj.curved_reflections.mode`` names a method of the registry
(:mod:`.method_registry`: Iterative, Runtime, Morphing, Octree, Perturbation and any
registered later) or Auto. :func:`plan` asks the mode's method whether it takes the
reflector (its *offer*); a method that refuses (the iterative search on an open mirror
that is not star-shaped, a grid mode without a baked grid) hands the reflector to the
trace per pixel, and the panel line says why. Auto asks the methods marked ``in_auto``
in registry order (the iterative search, a baked morphing grid, then the trace, which
takes any mirror) and falls back to Runtime.

Each drawn method's answers are checked against exactly traced rays, in the live view
when it settles and in Render Image's frames (``blender/accuracy.py``), and a chosen
mode's picture against the trace's (``blender/picture_check.py``); a
reflector whose method failed is passed to Auto's next method, or in an explicit mode to
the trace, until Refresh (:func:`note_measured`, :func:`note_outside`).

Higher orders: the per-frame methods draw first-order reflections (the trace draws every
order its rays reach); reflections of order 2 and more come from the sample-based camera,
which is built for them (and for the reflectors no per-frame pass drew) alone.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from . import method_registry
from .method_registry import AUTO, ITERATIVE, MORPHING, OCTREE, PERTURBATION, RUNTIME, TRACED, PlanInputs  # noqa: F401
from .scene_status import status_of

#: The modes drawn from a baked grid (``morph_bake``; the renderer's ``MorphPass`` draws both).
GRID_MODES = tuple(m.name for m in method_registry.registered() if m.grid is not None)


#: The panel's words for a reflector an explicit mode refused or measured outside the Accuracy.
EXPLICIT_FALLBACK = "ray traced instead"


@dataclass(frozen=True)
class MethodChoice:
    """What draws one reflector, and why (one panel line)."""

    reflector: str
    method: str  # a registered method's name
    reason: str


@dataclass
class MethodPlan:
    """Every reflector's choice, and the engines each method's pass draws them with."""

    choices: list = field(default_factory=list)
    #: {method name: [engine, ...]} in reflector order (``Offer.engine``).
    engines: dict = field(default_factory=dict)

    def engines_of(self, method: str) -> list:
        return self.engines.get(method, [])

    def pass_factories(self) -> list:
        """The renderer's per-frame passes for this plan (``ReflectionRenderer(passes=)``)."""
        return method_registry.pass_factories(self.engines)

    def drawn_grids(self) -> list:
        """The (grid, matrix) pairs the plan draws from baked grids."""
        return [grid for mode in GRID_MODES for grid in self.engines_of(mode)]

    def drawn_by(self, method: str) -> list:
        """The names of the reflectors ``method`` draws."""
        return [choice.reflector for choice in self.choices if choice.method == method]


def mode_of(scene, name: str) -> str:
    """A captured reflector's mode (Auto for an instance, which has no object of its own,
    and for a mode whose method is no longer registered)."""
    obj = scene.objects.get(name)
    mode = AUTO if obj is None else obj.curved_reflections.mode
    return mode if mode in {m.name for m in method_registry.registered()} else AUTO


def _candidates(mode: str) -> list:
    """The methods asked for a reflector in ``mode``, in order (Runtime is the fallback)."""
    if mode == AUTO:
        return [m for m in method_registry.registered() if m.in_auto]
    return [method_registry.get(mode)]


def choose(inputs: PlanInputs, index: int, reflector, mode: str) -> tuple:
    """(MethodChoice, engine) of one reflector in ``mode``: the first candidate that
    offers to draw it and was not measured outside the Accuracy on it
    (``inputs.outside``, :func:`note_measured`); else, in an explicit mode, the trace
    (exact per pixel, every image, about a Workbench frame: a mode that cannot draw the
    mirror right must not leave it wrong, nor wait seconds a view for Runtime's camera);
    else Runtime. The reason lists the refusals first."""
    refusals = []
    for method in _candidates(mode):
        if method.name in inputs.outside:
            refusals.append(f"{method.label}: {inputs.outside[method.name]}")
            continue
        offer = method.offer(inputs, index, reflector)
        if offer.draws:
            reason = "; ".join(refusals + [offer.reason])
            if mode == method.name and method.name == RUNTIME:
                reason = f"Runtime mode: {offer.reason}"
            return MethodChoice(reflector.name, method.name, reason), offer.engine
        refusals.append(offer.reason)
    if mode not in (AUTO, TRACED) and TRACED not in inputs.outside:
        offer = method_registry.get(TRACED).offer(inputs, index, reflector)
        if offer.draws:
            return MethodChoice(reflector.name, TRACED, "; ".join(refusals + [EXPLICIT_FALLBACK])), offer.engine
    fallback = "Runtime" if mode == AUTO else "drawn in Runtime mode"
    return MethodChoice(reflector.name, RUNTIME, "; ".join(refusals + [fallback])), None


def plan(scene, reflectors, accuracy_px: float | None = None, grids: dict | None = None,
         final_render: bool = False, max_order: int | None = None) -> MethodPlan:
    """Every reflector's method. ``grids``: {reflector name: (grid, object matrix)} of the
    loaded baked grids (``morph_bake.load_grids``); ``final_render``: for Render Image's
    frames (``PlanInputs.final_render``); ``max_order``: the frame's (default: the scene's)."""
    max_order = int(scene.curved_reflections.max_order if max_order is None else max_order)
    accuracy = float(scene.curved_reflections.accuracy_px if accuracy_px is None else accuracy_px)
    status = status_of(scene)
    result = MethodPlan()
    for index, reflector in enumerate(reflectors):
        mode = mode_of(scene, reflector.name)
        outside = status.outside_accuracy.get(reflector.name, {})
        inputs = PlanInputs(scene, accuracy, grids or {}, outside, final_render, mode, len(reflectors), max_order)
        choice, engine = choose(inputs, index, reflector, mode)
        result.choices.append(choice)
        if engine is not None:
            result.engines.setdefault(choice.method, []).append(engine)
    status.choices = result.choices
    return result


def grid_kind_wanted(scene, reflector) -> str | None:
    """The kind of baked grid loaded for this reflector (``MorphSettings.kind``), or None:
    its mode's method's grid, or in Auto the grid of the first method Auto would reach
    (a star-shaped mirror is searched, and wants none)."""
    mode = mode_of(scene, reflector.name)
    inputs = PlanInputs(scene, float(scene.curved_reflections.accuracy_px), {}, {}, mode=mode)
    for method in _candidates(mode):
        if method.grid is not None or mode != AUTO:
            return method.grid
        if method.offer(inputs, 0, reflector).draws:
            return None
    return None


def wants_grid(scene, reflector) -> bool:
    """Whether a baked grid is loaded for this reflector (:func:`grid_kind_wanted`)."""
    return grid_kind_wanted(scene, reflector) is not None


def note_measured(scene, measured: dict) -> bool:
    """Keep the checks (``accuracy.measure``: {reflector: Measured}) for the panel; a
    reflector whose per-frame method measured outside the scene's Accuracy
    (``SpotCheck.within``: its checked answers within it, and few exact images missed)
    is drawn by the next method Auto tries, or in an explicit mode by the trace, from
    then on until Refresh (:func:`note_outside`). Returns whether that happened now (the
    caller plans again). A sample-based camera's figures are kept for the panel only:
    the band along a mirror's outline and the cells it marks unreliable, which renders
    trace, are where it leaves images out (Render Image's picture check judges it)."""
    status_of(scene).measured = dict(measured)
    accuracy = float(scene.curved_reflections.accuracy_px)
    replaced = False
    for name, found in measured.items():
        if found.method == RUNTIME or found.check.within(accuracy):
            continue
        replaced |= note_outside(scene, name, found.method,
                                 f"{found.check.shortfall()} in a view (Accuracy {accuracy:g} px)")
    return replaced


def note_outside(scene, name: str, method: str, shortfall: str) -> bool:
    """Pass ``method`` over for reflector ``name`` until Refresh (``shortfall``: what was
    measured and where, for its panel line). Returns whether it was not already."""
    failed = status_of(scene).outside_accuracy.setdefault(name, {})
    if method in failed:
        return False
    failed[method] = shortfall
    return True


def note_picture(scene, name: str, check) -> None:
    """Keep the last check of reflector ``name``'s picture (``picture_check.PictureCheck``)."""
    status_of(scene).pictures[name] = check


def pictures(scene) -> dict:
    """The last picture checks of ``scene`` ({reflector: picture_check.PictureCheck})."""
    return status_of(scene).pictures


def measured(scene) -> dict:
    """The live view's last checks of ``scene`` ({reflector: accuracy.Measured})."""
    return status_of(scene).measured


def forget_measurements(scene) -> None:
    """Drop the checks and give the replaced methods another chance (Refresh)."""
    status = status_of(scene)
    status.measured, status.pictures, status.outside_accuracy = {}, {}, {}


def traced_plan(reflectors) -> MethodPlan:
    """A plan that ray traces every reflector (``picture_check``'s reference)."""
    traced = method_registry.get(TRACED)
    result = MethodPlan()
    for index, reflector in enumerate(reflectors):
        offer = traced.offer(None, index, reflector)
        result.choices.append(MethodChoice(reflector.name, TRACED, offer.reason))
        result.engines.setdefault(TRACED, []).append(offer.engine)
    return result


def last_choices(scene) -> list:
    """The choices of the last :func:`plan` for ``scene`` (the panel's lines)."""
    return status_of(scene).choices


def grid_wanted_by_last_plan(scene, obj) -> bool:
    """:func:`wants_grid` from what is known without checking any geometry (for the
    panel, which must not wait): a grid mode, or Auto not planned as a method without a grid."""
    mode = obj.curved_reflections.mode
    if mode in GRID_MODES:
        return True
    chosen = next((c.method for c in last_choices(scene) if c.reflector == obj.name), None)
    return mode == AUTO and chosen in (MORPHING, OCTREE, RUNTIME)
