# SPDX-License-Identifier: GPL-3.0-or-later
"""A node's images, regular and extended-frustum, polished on the mirror its camera was built from.

Remedy 2 of the morphing blend (SBC paper VI, ``morphing.py``) asks a node camera's
leaf for an image its rays do not bracket: the leaf's chart widened by
``EXTENDED_CHART``, its ray patch extrapolated. Those images lie off the mirror's true
reflection points by up to a few hundredths of the mirror's size, and they make most of
the blend's error over a pixel. Polished here, each is the exact reflection point on the
surface model the reference solver uses (flat triangles, interpolated normals), once per
node and point set, not per frame.

The node's regular images, interpolated between its rays (0.5 face pixels), are off
too, most where the node sees the mirror at a grazing angle; every one of them is
polished. The blend's surface is fitted to the images of a whole cube of nodes
(``MorphingGrid.locate_view``), and with polished images the fit's pull toward a
sphere, which damps the cameras' interpolation error, can be 100 times weaker
(``morph_surface.POLISHED_RIDGE``). Figures: docs/benchmarks/morphing.md and
docs/benchmarks/octree.md.

The scene's *Polish Node Images* (``MorphingGrid.mirror``, on by default) turns this
on. This is the numpy twin, which the engine's own projection (``MorphingGrid.project``)
and the tests use; it costs about a second a node, more than the node's projection
itself. The renderer polishes with its GPU twin (``drawing/methods/polish_gpu.py``,
milliseconds a node; docs/benchmarks/morphing.md), and the viewport's worker threads
leave the polish to it (``MorphingGrid.unpolished_images``).
"""

from __future__ import annotations

import numpy as np

from ...geometry.closed_surfaces import reflects_outside
from ...geometry.raytrace import ReflectorSet
from .morph_surface import law_normals
from ...reference.exact import INSIDE_TOLERANCE, newton_in_triangles
from ...view import look_at_view

#: Triangles tried per image: the one the ray from the node through the image meets,
#: then the ones through Newton's root while it lies outside the triangle it was found in.
POLISH_ROUNDS = 3
#: Triangles tried per blended image polished each frame (``MorphingGrid.polish_frames``):
#: a blend on a mirror that is not a quadric (a rounded box) lands tens of pixels off,
#: several triangles from its root, where POLISH_ROUNDS would leave some images unplaced.
FRAME_POLISH_ROUNDS = 8
#: Newton iterations per triangle: the images start within a triangle or two of their
#: root, where the reference solver's 24 (from a triangle's centroid) are rarely needed.
POLISH_ITERATIONS = 8
#: The rays are first traced this far past the image (a fraction of the mirror's
#: diagonal), a far smaller BVH descent than to infinity, and on only where they found
#: nothing (an image off the surface toward the eye, seen at a grazing angle); also how
#: far off the surface the fallback's normal line starts.
RAY_REACH = 0.05


def polish_regular(mirror: ReflectorSet, eye: np.ndarray, points: np.ndarray, images: np.ndarray,
                   polish=None) -> np.ndarray:
    """(P, K, 3) a node's regular ``images`` seen from ``eye``, polished (by ``polish``,
    of :func:`polish_images`' signature: by default that function); one the polish does
    not place stays as it is (the node's camera saw it: a reflection is there, only not
    where Newton's method started)."""
    polished = (polish or polish_images)(mirror, eye, points, images)
    return np.where(np.isfinite(polished[..., :1]), polished, images)


def polish_images(mirror: ReflectorSet, eye: np.ndarray, points: np.ndarray, images: np.ndarray,
                  rounds: int = POLISH_ROUNDS) -> np.ndarray:
    """(P, K, 3) ``images`` of ``points`` (P, 3) seen from ``eye``, each moved to the
    mirror's reflection point of its point near it, NaN where none is found.

    Newton's method on the law of reflection in a triangle's barycentric coordinates
    (``reference.exact.newton_in_triangles``) starts where the ray from the eye through
    the image meets the mirror (:func:`_triangles_under`); where its root lies outside
    that triangle, the ray through the root (or where Newton gave up) picks the next
    one, among its ring first, up to ``rounds``. An image not placed by then has
    no reflection near it: the widened chart extrapolated past the node's horizon, and
    the blend leaves that node out (remedy 3) rather than mix in a point off the
    mirror's law.
    """
    eye = np.asarray(eye, dtype=np.float64)
    rows, slots = np.nonzero(np.isfinite(images[..., 0]))
    polished = np.full(images.shape, np.nan)
    if len(rows) == 0:
        return polished
    view = look_at_view(eye, eye + np.array([1.0, 0.0, 0.0]), name="node")
    target = images[rows, slots].copy()
    pending = np.arange(len(rows))
    triangle = None
    for _ in range(rounds):
        found, triangle, start = _triangles_under(mirror, eye, points[rows[pending]], target[pending], triangle)
        pending, triangle, start = pending[found], triangle[found], start[found]
        if len(pending) == 0:
            break
        uv, converged, _ = newton_in_triangles(mirror, view, points[rows[pending]], triangle, start,
                                               iterations=POLISH_ITERATIONS)
        root, normal = mirror.surface(triangle, np.column_stack([1.0 - uv.sum(axis=1), uv]))
        inside = converged & (uv.min(axis=1) >= -INSIDE_TOLERANCE) & (uv.sum(axis=1) <= 1 + INSIDE_TOLERANCE)
        placed = inside & reflects_outside(mirror, triangle, root, normal, eye, points[rows[pending]])
        polished[rows[pending[placed]], slots[pending[placed]]] = root[placed]
        target[pending] = root
        # Newton gives up on a root far outside its triangle, where it left it heading.
        pending, triangle = pending[~inside], triangle[~inside]
        if len(pending) == 0:
            break
    return polished


def _triangles_under(mirror: ReflectorSet, eye, points, targets, near):
    """(found (R,), triangle (R,), barycentric (u, v) (R, 2)) of the mirror under each
    target: where the ray from the eye through it meets the mirror (the ring of ``near``
    first, where given), else, for a target off the surface past the mirror's silhouette
    as seen from the eye, where the line along the normal the law of reflection gives it
    (the bisector of the directions to the eye and to the point) does."""
    offset = targets - eye
    reach = np.linalg.norm(offset, axis=1)
    origins, directions = np.tile(eye, (len(offset), 1)), offset / np.maximum(reach, 1e-300)[:, None]
    if near is None:
        hits = mirror.intersect(origins, directions, t_guess=reach + RAY_REACH * mirror.scale)
    else:
        hits = mirror.intersect_near(origins, directions, near_triangles=near)
    found, triangle, start = hits.hit.copy(), hits.triangle.copy(), hits.barycentric[:, 1:].copy()
    missed = np.flatnonzero(~found)
    if len(missed):
        normal = law_normals(eye, points[missed], targets[missed])
        back = RAY_REACH * mirror.scale
        along = mirror.intersect(targets[missed] + back * normal, -normal, t_max=2.0 * back)
        found[missed], triangle[missed], start[missed] = along.hit, along.triangle, along.barycentric[:, 1:]
    return found, triangle, start

