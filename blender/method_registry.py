# SPDX-License-Identifier: GPL-3.0-or-later
"""The methods that draw reflectors, one registry entry each.

A reflector's *mode* names one entry, or Auto. An entry says what the method is called
(the mode enum, the panel's line and icon), whether it takes a reflector
(:attr:`Method.offer`: an :class:`Offer` that draws it, with the engine object its pass
needs, or refuses it with the reason), and how its per-frame pass is made
(:attr:`Method.make_pass`: from the engines of every reflector it took, a factory the
renderer calls with its ``frame_pass.PassInputs``). Entries that share a
:attr:`Method.pass_key` share one pass (Morphing and Octree: one ``MorphPass`` holds both
kinds of grid). Runtime has no pass: the sample-based camera of each view draws what no
pass drew, and higher orders.

The plan (:mod:`.method_plan`), the mode enum (``properties.py``), the panel's icons and the
live statistics read this registry, so a method is one engine folder plus one
:func:`register` call; Auto tries the entries with ``in_auto`` in registry order and
takes the first that offers to draw, Runtime last.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..engine.methods.iterative import IterativeReflector
from ..engine.methods.iterative.pieces import IterativePieces, open_refusal, searched_methods
from ..engine.methods.perturbation import AnalyticSurface, PerturbationReflector
from ..drawing.methods.iterative_draw import IterativePass
from ..drawing.methods.morph_pass import MorphPass
from ..drawing.methods.perturbation_pass import PerturbationPass
from ..drawing.methods.traced_pass import TracedMirror, TracedPass
from . import star_maps

AUTO, ITERATIVE, RUNTIME, MORPHING, OCTREE, PERTURBATION, TRACED = (
    'AUTO', 'ITERATIVE', 'RUNTIME', 'MORPHING', 'OCTREE', 'PERTURBATION', 'TRACED')
#: A declared exact surface is used when the mesh's vertices lie this close to it
#: (share of its radius); farther, the mesh itself reflects and the panel says why.
ANALYTIC_TOLERANCE = 0.02


@dataclass(frozen=True)
class PlanInputs:
    """What a method's offer may read: the scene (its objects' settings), the Accuracy,
    the loaded grids ({reflector name: (grid, object matrix)}), for Auto what the live
    check measured of methods passed over ({method: what was measured}), whether the
    frame is Render Image's, the reflector's mode, how many reflectors the scene has and
    the frame's Max Order."""

    scene: object
    accuracy_px: float
    grids: dict
    outside: dict
    #: A frame of Render Image (its animation too), not of the live view: the frame may
    #: take seconds, but the viewport must not stop for them.
    final_render: bool = False
    #: The reflector's mode (AUTO or a method's name).
    mode: str = AUTO
    #: How many reflectors the scene has (the reflector's among them).
    reflectors: int = 1
    #: The frame's Max Order (the scene's, or a render's own).
    max_order: int = 1


@dataclass(frozen=True)
class Offer:
    """A method's answer for one reflector: it draws it (``engine``: what its pass needs
    of it) or not, and the panel's reason either way."""

    draws: bool
    reason: str
    engine: object = None


def refuse(reason: str) -> Offer:
    return Offer(False, reason)


@dataclass(frozen=True)
class Method:
    """One way of drawing a reflector (see the module docstring)."""

    name: str
    label: str
    description: str
    icon: str
    offer: Callable[[PlanInputs, int, object], Offer]
    #: engines -> a pass factory (``FramePass.factory``); None: the sample-based camera draws it.
    make_pass: Callable[[list], Callable] | None = None
    pass_key: str = ""
    in_auto: bool = False
    #: The kind of baked grid it draws from (``MorphSettings.kind``), or None.
    grid: str | None = None
    #: The live statistics' phrase for the reflectors it draws ("{names} {summary}").
    summary: str = ""


_registry: dict[str, Method] = {}
#: The mode enum's items, kept alive for Blender (a dynamic enum's strings must outlive the call).
_enum_items: list = []


def register(method: Method) -> None:
    """Add (or replace) ``method``; Auto tries it in registration order if ``in_auto``."""
    _registry[method.name] = method
    _enum_items[:] = _items()


def unregister(name: str) -> None:
    _registry.pop(name, None)
    _enum_items[:] = _items()


def registered() -> tuple:
    """Every method, in registration order."""
    return tuple(_registry.values())


def get(name: str) -> Method:
    return _registry[name]


def _items() -> list:
    auto = (AUTO, "Auto", "The fastest method that takes the reflector: " + ", ".join(
        m.label for m in _registry.values() if m.in_auto) + ", else Runtime; the panel says which and why", 0)
    return [auto] + [(m.name, m.label, m.description, k) for k, m in enumerate(_registry.values(), 1)]


def enum_items(_self=None, _context=None) -> list:
    """The mode enum's items (``properties.py``): Auto, then every registered method."""
    return _enum_items


def pass_factories(engines_by_method: dict) -> list:
    """The renderer's pass factories for a plan's {method name: engines}: one per pass key,
    in registration order, every registered pass present (empty where no reflector chose
    it, so that the live view's per-pass work is uniform)."""
    shared: dict = {}
    for method in _registry.values():
        if method.make_pass is not None:
            key = method.pass_key or method.name
            maker, engines = shared.get(key, (method.make_pass, []))
            shared[key] = (maker, engines + list(engines_by_method.get(method.name, [])))
    return [maker(engines) for maker, engines in shared.values()]


# --- the built-in methods -----------------------------------------------------------


def _offer_iterative(inputs: PlanInputs, index: int, reflector) -> Offer:
    """A star-shaped mirror's map, or, in Iterative mode only, a closed mirror's pieces
    (``star_maps.piece_maps``): each frame searches every piece (seconds on a CPU
    rasteriser, where the trace costs about a Workbench frame and is exact). A folded
    star-shaped mirror is searched for every image from each of its patches
    (``fold_patches.py``) likewise, in Iterative mode only: Auto leaves it to the trace,
    which draws every image at that cost. In a Render Image frame of several mirrors at
    Max Order 2 or more, Auto leaves every mirror to the trace: their reflections in each
    other would take a sample-based camera built every frame (several Workbench frames
    on a CPU rasteriser), which the trace draws in its one pass."""
    if inputs.mode == AUTO and inputs.final_render and inputs.reflectors > 1 and inputs.max_order > 1:
        return refuse(f"Render Image at Max Order {inputs.max_order} with {inputs.reflectors - 1} other "
                      f"reflector{'s' if inputs.reflectors > 2 else ''}: their reflections in each other would "
                      "take a sample-based camera every frame")
    shape, reflector_map = star_maps.star_map(reflector)
    if reflector_map is None and (shape.crossings or shape.hidden_share > 0):
        if not star_maps.closed_surface(reflector):
            return refuse(open_refusal(reflector.name))
        if inputs.mode != ITERATIVE:
            return refuse(f"{shape.reason}; searched as pieces in Iterative mode (each frame would search each "
                          "piece)")
        pieces, maps = star_maps.piece_maps(reflector)
        if not maps:
            return refuse(pieces.reason)
        return Offer(True, f"not star-shaped: {len(maps)} pieces seen from inside it, each searched on the GPU",
                     IterativePieces.of_maps(index, reflector.name, maps, inputs.accuracy_px, pieces))
    if reflector_map is None:
        return refuse(shape.reason)
    centre = ", ".join(f"{round(float(c), 2) + 0.0:.2f}" for c in shape.centre)  # no "-0.00"
    found = f"star-shaped around ({centre}): iterative search on the GPU"
    if reflector_map.images > 1:
        if inputs.mode != ITERATIVE:
            return refuse(f"star-shaped around ({centre}), but it folds its reflections: every image is searched "
                          "from each of its patches in Iterative mode (each frame would search each patch)")
        reflector_map = star_maps.star_map(reflector, patched=True)[1]
        found = f"{found}, every image (it folds its reflections), from {len(reflector_map.patches)} patches"
    return Offer(True, found, IterativeReflector(index, reflector.name, reflector_map, inputs.accuracy_px))


def _iterative_pass(engines: list):
    searched = searched_methods(engines)
    for method in searched:  # the other searched mirrors (and pieces) may block its reflected segments
        method.occluders = tuple(other.reflector_map for other in searched if other is not method)
    return IterativePass.factory(searched)


def _offer_grid(method: str, label: str):
    def offer(inputs: PlanInputs, index: int, reflector) -> Offer:
        grid = inputs.grids.get(reflector.name)
        if grid is None or grid[0].settings.kind != get(method).grid:
            return refuse("no baked morphing grid" if method == MORPHING else f"no baked {label.lower()} grid")
        return Offer(True, f"its baked {label.lower()} grid draws it", grid)
    return offer


def _offer_perturbation(inputs: PlanInputs, index: int, reflector) -> Offer:
    """With the object's declared exact surface where its mesh lies within
    :data:`ANALYTIC_TOLERANCE` of it, else on the mesh."""
    obj = inputs.scene.objects.get(reflector.name)
    settings = None if obj is None else obj.curved_reflections
    if settings is None or settings.analytic_shape == 'NONE':
        return Offer(True, "Perturbation of traced paths on the mesh's osculating quadrics (Chen & Arvo 2000)",
                     PerturbationReflector(index, reflector.name))
    surface = AnalyticSurface(reflector.name, settings.analytic_shape, np.array(obj.matrix_world),
                              tuple(settings.analytic_radii), settings.analytic_exponent)
    deviation = surface.mesh_deviation(reflector)
    shape = settings.analytic_shape.lower()
    if deviation > ANALYTIC_TOLERANCE:
        return Offer(True, f"the mesh lies up to {100 * deviation:.1f} % of the radius from the declared {shape} "
                           f"(more than {100 * ANALYTIC_TOLERANCE:.0f} %): Perturbation on the mesh; set Radii to "
                           "match it", PerturbationReflector(index, reflector.name))
    return Offer(True, f"Perturbation on the exact {shape} (mesh within {100 * deviation:.2f} % of it)",
                 PerturbationReflector(index, reflector.name, surface))


def _offer_traced(inputs: PlanInputs, index: int, reflector) -> Offer:
    return Offer(True, "each pixel's reflected ray traced on the GPU every frame: every image, to Max Order",
                 TracedMirror(index, reflector.name))


def _offer_runtime(inputs: PlanInputs, index: int, reflector) -> Offer:
    return Offer(True, "a camera per view")


def register_builtin() -> None:
    """The four papers' methods, in the order Auto tries them."""
    register(Method(ITERATIVE, "Iterative (GPU)", "Find every vertex's reflection on the GPU each frame (Roger & "
                    "Holzschuch 2006); star-shaped reflectors, closed ones as pieces seen from inside; open ones "
                    "are ray traced", 'SHADERFX',
                    _offer_iterative, _iterative_pass, in_auto=True, summary="searched on the GPU every frame"))
    register(Method(RUNTIME, "Runtime", "Rebuild the sample-based camera for every new view (SBC paper IV)",
                    'CAMERA_DATA', _offer_runtime))
    register(Method(MORPHING, "Morphing", "Bake a grid of panoramic cameras around the reflector and blend them "
                    "as the view moves (SBC paper VI)", 'LIGHTPROBE_VOLUME', _offer_grid(MORPHING, "Morphing"),
                    MorphPass.factory, pass_key="grids", in_auto=True, grid="tetrahedral",
                    summary="blended from its baked grid every frame"))
    register(Method(OCTREE, "Octree Morphing", "Bake a grid of ray octrees around the reflector and blend the eight "
                    "nodes around the view trilinearly as it moves (Martin & Popescu 2004)", 'LIGHTPROBE_VOLUME',
                    _offer_grid(OCTREE, "Octree"), MorphPass.factory, pass_key="grids", grid="octree",
                    summary="blended from its baked octree grid every frame"))
    register(Method(PERTURBATION, "Perturbation", "Trace a sparse grid of reflection paths per view and move every "
                    "vertex's reflection from the nearest one by its path Jacobian and Hessian (Chen & Arvo 2000); "
                    "any smooth reflector", 'FORCE_HARMONIC', _offer_perturbation, PerturbationPass.factory,
                    summary="by perturbation of paths traced each view"))
    register(Method(TRACED, "Ray Traced (GPU)", "Trace each mirror pixel's reflected ray through the scene on the "
                    "GPU every frame: any mirror, folded or not star-shaped, every image, no bake",
                    'SHADING_RENDERED', _offer_traced, TracedPass.factory, in_auto=True,
                    summary="ray traced on the GPU every frame"))


register_builtin()
