# SPDX-License-Identifier: GPL-3.0-or-later
"""Images polished on the true reflected rays of the reflector mesh.

A sample-based camera answers from rays traced at ray-map resolution and interpolated in
between (SBC paper, Popescu, Sacks, Mei 2006, sections III-IV). Where the reflected ray
field is smooth the interpolation is within a fraction of a pixel; near a caustic, where
neighbouring rays cross, the interpolated field passes through points that no true ray
reaches there, and a ray-list leaf (IV-C) or a fold cell answers with an image pixels
away from the true one, or with one that does not exist. Measured on the teapot demo
(d = 2, accuracy 1 px): 95 % of the images more than 1 px off came from ray-list
leaves, and they lay 2-25 px from true images.

Such answers are polished as Roger and Holzschuch (2006, section 3.2) find reflections:
by iterating on the true geometry. The answer's desired-view pixel q starts Gauss-Newton
on the exact first-order reflection law: trace the view ray through q to the reflector
(first hit x, interpolated normal n), reflect it (r), and drive the part of p - x
perpendicular to r to zero; the 3x2 Jacobian comes from two more traced rays a quarter
pixel away, on the side that stays on the mirror (or on its smooth piece) next to an
edge. An image is kept where the iteration converges to a ray that meets the group's
reflector, reflects off its front and reaches p ahead of the mirror, within
:data:`MAX_SHIFT_CELLS` ray-map cells of where it started; it then carries the exact
first reflector point x and distance s. A point whose answer does not converge has no
image in that group (as a point that no ray reaches has none). A higher-order image is
polished the same way along its whole path: the view ray bounces off each reflector of
the history in turn, and the last reflected ray must pass the point unblocked. Near the
edge of a higher order's footprint, where Gauss-Newton from a ray a cell away overshoots,
an image is found by continuation from such a ray instead (``polish_by_continuation``).

Only the first and the last ray of an image are traced through the BVH; the iterations
in between intersect the ring of triangles around the previous hit
(``ReflectorSet.intersect_near``), since a step moves a few pixels at most. A final ray
that then meets another part of the mirror first, or passes the point farther than
the iteration's tolerance, has no image. That makes the polish several times faster than
tracing every iteration's ray through the BVH, with the same images bar a few.
"""

from __future__ import annotations

import numpy as np

from ..geometry.raytrace import ReflectorSet, reflect, reflection_valid
from ..view import View

#: Gauss-Newton iterations at most (each traces three rays per unconverged image).
ITERATIONS = 10
#: A step whose ray leaves the path (off the mirror, or past a silhouette of a
#: later mirror in the history) is halved at most this many times, from where it started.
HALVINGS = 3
#: Finite-difference step of the Jacobian, desired-view pixels: at first, and at most.
STEP_PX = 0.25
#: Later, FD_SCALE times the last step, down to MIN_STEP_PX: where the path bends fast (a
#: grazing bounce), a quarter pixel's difference crosses the bend and the Jacobian leads
#: astray (on four two-mirror scenes this found 0.3-2 % more second-order images, faster).
FD_SCALE = 0.5
MIN_STEP_PX = 1.0 / 64.0
#: A step shorter than this (pixels) ends an image's iteration: converged.
CONVERGED_PX = 0.01
#: A converged image's ray passes within this many pixels (at the point) of the point.
RESIDUAL_PX = 0.05
#: Longest step of one iteration (pixels): far from the root the linear model is poor.
MAX_STEP_PX = 4.0
#: A step turning back on the last one (cosine below this) is halved: near the edge of a
#: higher order's footprint the image moves as the square root of the distance to the
#: edge, and full Gauss-Newton steps on sqrt(x) jump between x and -x.
REVERSAL_COSINE = -0.5
#: A polished image may end at most this many ray-map cells from where it started.
MAX_SHIFT_CELLS = 12.0
#: Steps of the target in a continuation polish (``polish_by_continuation``).
CONTINUATION_STAGES = 4


def _history(reflector) -> tuple:
    """A reflection history: the reflectors a path meets in order (an int: first order)."""
    return (int(reflector),) if np.ndim(reflector) == 0 else tuple(int(r) for r in reflector)


def trace_history(reflector_set: ReflectorSet, view: View, reflector, pixels, near=None, pieces=None, guess=None):
    """The view rays through ``pixels`` bounced through the history ``reflector`` (an
    index, or the tuple of a higher order): per pixel the last reflected ray's tail and
    unit direction, the first reflector point, whether the path is valid (each bounce
    off the next reflector of the history, off its front; the first on one of its smooth
    ``pieces``, if given) and (P, bounces) the triangles each bounce hits (-1: none).
    With ``near`` (P, bounces) triangles, each bounce is intersected with their rings
    only (``ReflectorSet.intersect_near``), else with the whole mesh, where ``guess`` (P,)
    triangles, if given, are where the view ray's nearest hit is looked for first."""
    history = _history(reflector)
    origins, directions = view.pixel_rays(pixels)
    triangles = np.full((len(origins), len(history)), -1, dtype=np.int64)
    valid = np.ones(len(origins), dtype=bool)
    for bounce, mirror in enumerate(history):
        sources = hits.triangle if bounce else None
        if near is not None:
            hits = reflector_set.intersect_near(origins, directions, near[:, bounce], source_triangles=sources)
        else:
            hits = reflector_set.intersect(origins, directions, source_triangles=sources,
                                           near_triangles=None if bounce else guess)
        if bounce == 0:
            first = hits.position
        triangles[:, bounce] = hits.triangle
        normal = np.where(hits.hit[:, None], hits.normal, 0.0)
        valid &= (hits.hit & (hits.reflector == mirror)
                  & reflection_valid(directions, normal, np.where(hits.hit[:, None], hits.face_normal, 0.0)))
        if bounce == 0 and pieces is not None:
            valid &= np.isin(reflector_set.piece[np.maximum(hits.triangle, 0)], pieces)
        origins, directions = np.where(valid[:, None], hits.position, origins), reflect(directions, normal)
    return origins, directions, first, valid, triangles


def _true_residual(reflector_set: ReflectorSet, view: View, reflector, pixels, points, near=None, pieces=None,
                   guess=None):
    """Per pixel: (P, 3) offset of the point from the true reflected ray of the history
    ``reflector`` (perpendicular part), the first reflector point, the distance along the
    last reflected ray, whether the path is valid (``trace_history``) and reaches the
    point, and (P, bounces) the triangles each bounce hits. ``near``, ``pieces`` and
    ``guess`` as in ``trace_history``; without ``near``, a higher order's last segment
    is also checked for other parts of the mirrors before the point."""
    origins, directions, first, valid, triangles = trace_history(reflector_set, view, reflector, pixels, near, pieces,
                                                                 guess)
    offset = points - origins
    distance = np.einsum("ij,ij->i", offset, directions)
    residual = offset - distance[:, None] * directions
    valid &= distance > 0
    if triangles.shape[1] > 1 and near is None and valid.any():
        # The last segment may pass another part of the mirrors on its way to the point.
        check = np.flatnonzero(valid)
        valid[check] = ~reflector_set.occluded(origins[check], directions[check], distance[check],
                                               triangles[check, -1])
    return np.nan_to_num(residual), first, distance, valid, triangles


def polish_on_true_rays(reflector_set: ReflectorSet, view: View, reflector, pixels: np.ndarray,
                        points: np.ndarray, cell_px: float, spacing_px: np.ndarray | None = None,
                        pieces: np.ndarray | None = None, near_triangles: np.ndarray | None = None):
    """Polish images of ``points`` in ``reflector`` starting at ``pixels``: first-order
    images for a reflector index, or of a higher order for a history (a tuple of indices).

    Returns (pixels (P, 2), first reflector points (P, 3), distances along the reflected
    ray (P,), ok (P,)); rows not ok are left as given. ``cell_px`` is the ray map's cell
    size in pixels (its down-sampling), the unit of :data:`MAX_SHIFT_CELLS`.
    ``spacing_px`` (P,), where known, is how far apart (world units) the traced rays of
    neighbouring pixels pass at the point: an answer whose true ray already passes
    within :data:`RESIDUAL_PX` of such spacings is kept after one traced ray, with no
    Jacobian (most answers, away from caustics). With ``pieces``, an image must lie on
    one of those smooth pieces of the reflector (``ReflectorSet.piece``): the answer of
    a tree built over one piece does not slide over a sharp edge onto another piece,
    whose own tree answers that image. ``near_triangles`` (P,), -1 where unknown, are
    triangles the view rays through ``pixels`` likely hit (the ray map's, at the answer's
    cell): the first trace looks there first (``ReflectorSet.intersect``), for the same hits.
    """
    pixels = np.asarray(pixels, dtype=np.float64)
    points = np.asarray(points, dtype=np.float64)
    n = len(pixels)
    f, position, distance, valid, triangle = _true_residual(reflector_set, view, reflector, pixels, points,
                                                            pieces=pieces, guess=near_triangles)
    converged = np.zeros(n, dtype=bool)
    if spacing_px is not None:
        converged = valid & (np.linalg.norm(f, axis=1) < RESIDUAL_PX * np.asarray(spacing_px))
    polished, converged, tolerance = _iterate(reflector_set, view, reflector, pixels, points, triangle, converged,
                                              pieces)
    moved = np.flatnonzero(np.any(polished != pixels, axis=1))
    f, position[moved], distance[moved], valid[moved], _ = _true_residual(reflector_set, view, reflector,
                                                                          polished[moved], points[moved],
                                                                          pieces=pieces, guess=triangle[moved, 0])
    # Traced against the whole mesh, the final ray still reaches the point (no other part
    # of the mirror in front of the rings the iteration saw).
    valid[moved] &= np.linalg.norm(f, axis=1) < 2.0 * tolerance[moved]
    inside = ((polished >= 0).all(axis=1) & (polished[:, 0] <= view.width) & (polished[:, 1] <= view.height))
    near = np.linalg.norm(polished - pixels, axis=1) <= MAX_SHIFT_CELLS * cell_px
    ok = converged & valid & inside & near
    return np.where(ok[:, None], polished, pixels), position, distance, ok


def _iterate(reflector_set: ReflectorSet, view: View, reflector, pixels, points, triangle, converged, pieces):
    """Gauss-Newton from ``pixels`` for the images not yet ``converged``, tracing against
    the rings around the hits (``triangle`` (P, bounces), updated in place). Returns
    (pixels, converged, the residual each converged image's ray must stay within)."""
    n = len(pixels)
    polished = pixels.copy()
    converged = converged.copy()
    tolerance = np.zeros(n)  # residual (world units) a converged image's ray must stay within
    active = np.flatnonzero(~converged)
    last_step = np.zeros((n, 2))
    halvings = np.zeros(n, dtype=np.int64)
    for _ in range(ITERATIONS):
        if len(active) == 0:
            break
        q, p, m = polished[active], points[active], len(active)
        # The pixel and its two finite-difference neighbours, traced in one batch against
        # the triangles around the pixel's last hit (steps are a few pixels at most); the
        # final answer is traced against the whole mesh below.
        near = np.tile(triangle[active], (3, 1))
        h = np.where(last_step[active].any(axis=1),
                     np.clip(FD_SCALE * np.linalg.norm(last_step[active], axis=1), MIN_STEP_PX, STEP_PX), STEP_PX)
        offsets = np.concatenate([np.zeros((m, 2)), np.c_[h, np.zeros(m)], np.c_[np.zeros(m), h]])
        f, _, _, reflects, hit = _true_residual(reflector_set, view, reflector, np.tile(q, (3, 1)) + offsets,
                                                np.tile(p, (3, 1)), near, pieces)
        # Next to an edge of the mirror (or of a smooth piece) a neighbour may leave it,
        # where the residual jumps: that derivative is taken on the other side instead.
        back = np.flatnonzero(~reflects[m:] & np.tile(reflects[:m], 2))
        if len(back):
            offsets[m + back] *= -1.0
            f[m + back], _, _, _, _ = _true_residual(reflector_set, view, reflector, q[back % m] + offsets[m + back],
                                                     p[back % m], near[m + back], pieces)
        f, fu, fv, reflects = f[:m], f[m:2 * m], f[2 * m:], reflects[:m]
        triangle[active] = hit[:m]
        ju, jv = (fu - f) / offsets[m:2 * m, :1], (fv - f) / offsets[2 * m:, 1:]
        # Normal equations of the 3x2 least-squares step.
        a, b, c = np.einsum("ij,ij->i", ju, ju), np.einsum("ij,ij->i", ju, jv), np.einsum("ij,ij->i", jv, jv)
        gu, gv = np.einsum("ij,ij->i", ju, f), np.einsum("ij,ij->i", jv, f)
        det = a * c - b * b
        usable = reflects & (np.abs(det) > 1e-300)
        det = np.where(usable, det, 1.0)
        step = np.stack([(c * gu - b * gv) / det, (a * gv - b * gu) / det], axis=1)
        length = np.linalg.norm(step, axis=1)
        step *= np.minimum(1.0, MAX_STEP_PX / np.maximum(length, 1e-300))[:, None]
        turn = np.einsum("ij,ij->i", step, last_step[active])
        step[turn < REVERSAL_COSINE * length * np.linalg.norm(last_step[active], axis=1)] *= 0.5
        polished[active] = q - np.where(usable[:, None], step, 0.0)
        # A step that left the path is halved instead (near a silhouette the path bends
        # fast, and a full step there leaves second-order images unfound).
        lost = ~reflects & (halvings[active] < HALVINGS) & last_step[active].any(axis=1)
        back_off = active[lost]
        last_step[back_off] *= 0.5
        polished[back_off] = q[lost] + last_step[back_off]
        halvings[back_off] += 1
        last_step[active[usable]], halvings[active[usable]] = step[usable], 0
        # Converged on a root, not on the closest approach of rays that miss the point.
        limit = RESIDUAL_PX * np.sqrt(np.minimum(a, c))
        done = usable & (length < CONVERGED_PX) & (np.linalg.norm(f, axis=1) < limit)
        converged[active[done]] = True
        tolerance[active[done]] = limit[done]
        active = active[(usable & ~done) | lost]
    return polished, converged, tolerance


def polish_by_continuation(reflector_set: ReflectorSet, view: View, reflector, pixels: np.ndarray,
                           points: np.ndarray, cell_px: float, stages: int = CONTINUATION_STAGES,
                           pieces: np.ndarray | None = None, near_triangles: np.ndarray | None = None):
    """Polish images of ``points`` from seed ``pixels`` (traced rays of the history that
    pass near the points, a ray map's rays) by continuation: the target moves from the
    point of the seed's true ray nearest each point to the point in ``stages`` equal
    steps, each polished (``polish_on_true_rays``) from the image of the step before.

    Near the edge of a higher order's footprint, where a path leaves a mirror past its
    silhouette, the image moves as the square root of the distance to that edge: a
    Gauss-Newton step from a ray a cell away overshoots out of the footprint, or along a
    mirror's rim, and is halved until it gives up. A step of the target moves the image
    little, and each stage starts where the last one converged. Returns as
    ``polish_on_true_rays``, with the last stage's answers; rows not ok keep the seed.
    """
    pixels = np.asarray(pixels, dtype=np.float64)
    points = np.asarray(points, dtype=np.float64)
    f, position, distance, ok, triangle = _true_residual(reflector_set, view, reflector, pixels, points,
                                                         pieces=pieces, guess=near_triangles)
    start = points - f  # on each seed's ray, level with the point
    current = pixels.copy()
    rows = np.flatnonzero(ok)
    for t in np.arange(1, stages) / stages:
        # Intermediate targets are iterated on the rings only; the last stage is polished in full.
        ring = triangle[rows]
        polished, converged, _ = _iterate(reflector_set, view, reflector, current[rows],
                                          start[rows] + t * (points[rows] - start[rows]), ring,
                                          np.zeros(len(rows), dtype=bool), pieces)
        current[rows[converged]], triangle[rows] = polished[converged], ring
    current[rows], position[rows], distance[rows], ok[rows] = polish_on_true_rays(
        reflector_set, view, reflector, current[rows], points[rows], cell_px, pieces=pieces,
        near_triangles=triangle[rows, 0])
    return np.where(ok[:, None], current, pixels), position, distance, ok
