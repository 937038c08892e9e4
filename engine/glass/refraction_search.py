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
draws each diffuse vertex at A (``drawing/methods/refraction_draw.py``), in as many answer
slots as it has images. Convexity is what makes two interfaces the whole path: a ray
inside leaves once and never meets the solid again, unless it meets the surface past the
critical angle, where glass that reflects (a Glass BSDF) reflects it inside and it
leaves farther on. The search draws glass where the scene has more image textures than
the GPU's per-pixel trace samples (``drawing/methods/glass_trace.py``, which draws glass
otherwise); there, glass that is open, not star-shaped or not convex has no search, and
the viewport shows it as a solid object (``blender/glass_layer.py``).
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
#: Starts from the plane's guesses at most per vertex (their sign changes, in order of
#: entry angle).
MAX_STARTS = 4
#: Starts from the pixels' own paths through the glass (``drawing/methods/glass_rays.py``),
#: after the plane's: the pixels whose rays pass a vertex nearest, on a grid of this many
#: across the glass's box on screen, at least this many cells apart. A box's rays
#: reflected inside off a side, and a lens's images off the plane, start there.
PIXEL_STARTS = 2
PIXEL_GRID = 12
PIXEL_APART = 3
#: Answer slots per vertex: every image the starts find (through a ball the paths of a
#: point lie in one plane, and a point near the focus is seen up to three times in it:
#: either side of the axis, and once more across the caustic's cusp).
IMAGES = 4
#: Two answers are one image when their entry points lie within this share of the
#: Accuracy (the mirror search's).
SAME_IMAGE = mirror_search.SAME_IMAGE
#: The mirror search's chart constants serve the same chart here.
DERIVATIVE_STEP = mirror_search.DERIVATIVE_STEP
TRUST_RADIUS = mirror_search.TRUST_RADIUS
HALVINGS = mirror_search.HALVINGS
MAX_CHART = mirror_search.MAX_CHART
#: Largest angle (radians) between the ray leaving the glass and the direction from its
#: exit to the vertex for an answer: the step test converges far below it, so a larger
#: one is a search that stopped on a spurious minimum.
RESIDUAL_TOLERANCE = 1e-3
#: A vertex without an image is still placed where its nearest search stopped, if that
#: search's leaving ray missed it by less than this angle (radians): beside the edge of
#: what the glass shows its triangles are drawn there, and each fragment's ray cast keeps
#: what the pixel truly sees (``drawing/glsl/reflection_mesh_frag.glsl``). Farther, the
#: vertex is not behind the glass, and its triangles would only cost fragments.
PLACED_RESIDUAL = 0.2
#: Plane steps of the exit search: a smooth solid settles in three or four, a flat face in one.
EXIT_STEPS = 8
#: The exit is settled when a plane step moves it by less than this share of the solid's
#: largest radius (float32 holds about 1e-7 of it).
EXIT_TOLERANCE = 1e-6
#: Total reflections inside glass that reflects (a Glass BSDF) followed at most before a
#: path leaves: one, off a box's side, takes the rays entering its top out of its back.
#: Each more repeats the exit search in every path the search evaluates (two cost the
#: glass demo's search half as much again).
INSIDE_REFLECTIONS = 1
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
#: A refracted fragment is kept where its pixel's own path through the glass hits its
#: triangle, or passes at most this many pixels of the drawn triangle outside it: a pixel
#: along a drawn edge whose ray hits the neighbouring triangle a fraction of a pixel away
#: is the neighbour's, which the rasteriser gave to this one
#: (``drawing/glsl/reflection_mesh_frag.glsl``).
OUTSIDE_PX = 1.0
#: Where a fragment's ray misses its triangle (a strong lens magnifies a coarse triangle,
#: whose straight image strays from its true one, and the rays that hit it cross its
#: neighbours' images), the fragment stands in if the ray passes its point of the mesh
#: within this share of the meshes' subdivision limit there (``geometry/subdivision.py``:
#: ``EDGE_FRACTION`` times the larger of the glass's radius and the point's distance from
#: its centre): a triangle drawn in one image is interpolated within its own size, one
#: drawn across two images is passed farther off.
REFRACTION_REACH = 2.0


@dataclass(frozen=True)
class RefractedGlass:
    """One convex glass solid behind the search: its index among the scene's glass (the
    renderer's reflector index), its name, its cube map (``reflector_map``), its index
    of refraction, the Accuracy (px) its search stops at a tenth of, and whether it
    reflects (a Glass BSDF; a Refraction BSDF shows black where it must reflect totally)."""

    index: int
    name: str
    reflector_map: ReflectorMap
    ior: float
    accuracy_px: float = 1.0
    reflects: bool = True


def refracted_glass(glass: Glass, index: int, shape: StarShape, reflector_map: ReflectorMap | None,
                    accuracy_px: float = 1.0) -> tuple[RefractedGlass | None, str]:
    """The search for one glass object from its star-shape verdict and cube map
    (``methods/iterative/star.py``), or None and the reason it has none (for the panel):
    the glass must be a closed solid seen whole from one centre, and convex."""
    if reflector_map is None:
        return None, shape.reason
    if not reflector_map.convex:
        return None, f"{glass.name!r} is not convex: a ray inside it may leave and enter it again"
    return RefractedGlass(index, glass.name, reflector_map, float(glass.ior), float(accuracy_px),
                          bool(glass.reflects)), ""


def search_defines() -> dict:
    """The constants above, as the search shader's ``#define`` s."""
    floats = {"DERIVATIVE_STEP": DERIVATIVE_STEP, "TRUST_RADIUS": TRUST_RADIUS, "MAX_CHART": MAX_CHART,
              "RESIDUAL_TOLERANCE": RESIDUAL_TOLERANCE, "EXIT_TOLERANCE": EXIT_TOLERANCE, "EXIT_START": EXIT_START,
              "FLIP_SINE": FLIP_SINE, "SAME_IMAGE_PER_STOP": SAME_IMAGE / STOP_FRACTION,
              "PLACED_RESIDUAL": PLACED_RESIDUAL}
    ints = {"MAX_ITERATIONS": MAX_ITERATIONS, "GUESS_SAMPLES": GUESS_SAMPLES, "GUESS_BISECTIONS": GUESS_BISECTIONS,
            "IMAGES": IMAGES, "MAX_STARTS": MAX_STARTS, "INSIDE_REFLECTIONS": INSIDE_REFLECTIONS,
            "PIXEL_STARTS": PIXEL_STARTS, "PIXEL_GRID": PIXEL_GRID, "PIXEL_APART": PIXEL_APART, "HALVINGS": HALVINGS, "EXIT_STEPS": EXIT_STEPS,
            "EXIT_BISECTIONS": EXIT_BISECTIONS, "OCCLUSION_SAMPLES": OCCLUSION_SAMPLES}
    return {**{key: f"{value:.9e}" for key, value in floats.items()}, **ints}
