# SPDX-License-Identifier: GPL-3.0-or-later
"""The per-vertex search of refracted paths through convex glass: what it needs, and when.

Roger & Holzschuch (2006) find each vertex's reflection point on a star-shaped mirror by
a Newton search on its cube map (``methods/iterative``); Chen & Arvo (2000, section VI)
name refraction paths as the direct extension of their path perturbation. Through a
closed *convex* glass solid a point behind it is seen along a path with two interfaces:
the eye's ray enters at A, is bent (Snell's law), leaves at B, is bent again and passes
through the point. The search (``drawing/glsl/refraction_search.glsl``) takes A's two
coordinates on the glass's cube map as its unknowns, follows the path from A to B on the
same map, and drives the leaving ray onto the point; the reflected-mesh renderer then
draws each diffuse vertex at A (``drawing/methods/refraction_draw.py``). Convexity is what
makes two interfaces the whole path: a ray inside leaves once and never meets the solid
again. Glass that is open, not star-shaped or not convex has no search, and the viewport
shows it as a solid object; Render Image traces all glass per pixel
(``blender/glass_layer.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

from ..methods.iterative import search as mirror_search
from ..methods.iterative.reflector_map import ReflectorMap
from ..methods.iterative.star import StarShape
from .paths import Glass

#: Newton steps at most per start (as the mirror search's).
MAX_ITERATIONS = mirror_search.MAX_ITERATIONS
#: A search stops when its step moves A by less than this share of the Accuracy, as the
#: mirror search's.
STOP_FRACTION = mirror_search.STOP_FRACTION
#: Samples of the entry angle across the part of the map the eye may see: a ball's signed
#: miss changes sign once per image, and an image spans several degrees of it (16 lose
#: a box's images out of its sides).
GUESS_SAMPLES = 24
#: Bisections of the guess's entry angle between two samples (1/128 of a sample's span).
GUESS_BISECTIONS = 7
#: Starts tried at most per vertex (the guesses' sign changes, in order of entry angle).
MAX_STARTS = 2
#: The mirror search's chart constants serve the same chart here.
DERIVATIVE_STEP = mirror_search.DERIVATIVE_STEP
TRUST_RADIUS = mirror_search.TRUST_RADIUS
HALVINGS = mirror_search.HALVINGS
MAX_CHART = mirror_search.MAX_CHART
#: Largest angle (radians) between the ray leaving the glass and the direction from its
#: exit to the vertex for an answer: the step test converges far below it, so a larger
#: one is a search that stopped on a spurious minimum.
RESIDUAL_TOLERANCE = 1e-3
#: Plane steps of the exit search: a smooth solid settles in three or four, a flat face in one.
EXIT_STEPS = 8
#: The exit is settled when a plane step moves it by less than this share of the solid's
#: largest radius (float32 holds about 1e-7 of it).
EXIT_TOLERANCE = 1e-6
#: Bisections of the exit where the plane steps do not settle (a ray along an edge of a
#: box): 2^-24 of the bounding sphere's chord, float32's resolution.
EXIT_BISECTIONS = 24
#: The bisection's inner end, a share of the chord: just inside the entry.
EXIT_START = 1e-4
#: A vertex is a flipped image where the leaving rays' cross-section there, against its
#: orientation at the glass, turns over by more than this sine: clearly between two
#: focal lines, not the noise of a focus (``drawing/glsl/refraction_search.glsl``).
FLIP_SINE = 0.1
#: Samples of the segments into and out of the glass tested against the other glass.
OCCLUSION_SAMPLES = mirror_search.OCCLUSION_SAMPLES


@dataclass(frozen=True)
class RefractedGlass:
    """One convex glass solid behind the search: its index among the scene's glass (the
    renderer's reflector index), its name, its cube map (``reflector_map``), its index
    of refraction and the Accuracy (px) its search stops at a tenth of."""

    index: int
    name: str
    reflector_map: ReflectorMap
    ior: float
    accuracy_px: float = 1.0


def refracted_glass(glass: Glass, index: int, shape: StarShape, reflector_map: ReflectorMap | None,
                    accuracy_px: float = 1.0) -> tuple[RefractedGlass | None, str]:
    """The search for one glass object from its star-shape verdict and cube map
    (``methods/iterative/star.py``), or None and the reason it has none (for the panel):
    the glass must be a closed solid seen whole from one centre, and convex."""
    if reflector_map is None:
        return None, shape.reason
    if not reflector_map.convex:
        return None, f"{glass.name!r} is not convex: a ray inside it may leave and enter it again"
    return RefractedGlass(index, glass.name, reflector_map, float(glass.ior), float(accuracy_px)), ""


def search_defines() -> dict:
    """The constants above, as the search shader's ``#define`` s."""
    floats = {"DERIVATIVE_STEP": DERIVATIVE_STEP, "TRUST_RADIUS": TRUST_RADIUS, "MAX_CHART": MAX_CHART,
              "RESIDUAL_TOLERANCE": RESIDUAL_TOLERANCE, "EXIT_TOLERANCE": EXIT_TOLERANCE, "EXIT_START": EXIT_START,
              "FLIP_SINE": FLIP_SINE}
    ints = {"MAX_ITERATIONS": MAX_ITERATIONS, "GUESS_SAMPLES": GUESS_SAMPLES, "GUESS_BISECTIONS": GUESS_BISECTIONS,
            "MAX_STARTS": MAX_STARTS, "HALVINGS": HALVINGS, "EXIT_STEPS": EXIT_STEPS,
            "EXIT_BISECTIONS": EXIT_BISECTIONS, "OCCLUSION_SAMPLES": OCCLUSION_SAMPLES}
    return {**{key: f"{value:.9e}" for key, value in floats.items()}, **ints}
