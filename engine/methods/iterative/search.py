# SPDX-License-Identifier: GPL-3.0-or-later
"""Where does a point appear in a star-shaped mirror? The iterative search, numpy twin.

Roger & Holzschuch (2006), section 3. A diffuse point V is seen from the eye E at the
reflector point P where the surface normal n bisects the directions to E and to V
(Fermat: the optical path EP + PV is stationary, section 3.1). With the reflector stored
as a cube map around its centre O (:mod:`.reflector_map`), P is a function of one
direction d from O, and the search runs in two dimensions:

1. **First guess** (improving on 3.3.4): the reflection on the sphere around O of the
   map's mean radius, which lies in the plane of O, E and V on the arc between the
   directions to E and to V (Fig. 5; Ofek 1998): a bisection along that arc, with no
   texture fetch. On a sphere it is the answer; on any star-shaped mirror it is close.
2. **Search** in a gnomonic chart of directions around the guess,
   d(x) = normalize(d* + x1 t1 + x2 t2). The residual F(x) is the part of the half
   vector h = e + v (unit directions from P to E and to V) tangent to the surface, in
   chart coordinates: the paper's gradient of the optical path length vanishes exactly
   where F does. The paper's secant triangle (3.3.3) replaces one sample per step; we
   take damped Newton steps instead (the Jacobian from two samples 1e-3 apart, the step
   at most :data:`TRUST_RADIUS` and halved until |F| falls), and where a start fails on
   a non-convex mirror, start again from four points around the guess
   (:data:`RESTARTS`; a convex mirror has one reflection of a point at most, so there a
   failed start means none). A piece of a mirror that is not star-shaped (:mod:`.pieces`)
   starts instead from each of its patches whose normal cone can hold the point's
   reflection (:func:`patch_admits`), until one finds it; a folded star-shaped mirror
   (:mod:`.fold_patches`) from every one of them, keeping every image
   (:func:`search_images`). On a bumpy sphere the secant
   triangle cycles between the roots of neighbouring bumps and misses many of the exact
   solver's reflections; Newton from one start misses fewer, and with the restarts few.
3. **Stop** (3.2, the geometric bound): when a step moves P by less than
   :data:`STOP_FRACTION` of the accuracy in pixels, measured in the view at P; Newton
   steps shrink quadratically, so the answer is then far closer than the step. Or one
   step earlier: when the next step, predicted with this step's Jacobian from the
   residual the line search already sampled (a chord step), would move P by less than
   that and the residual already passes the answer's test; it is then taken along the
   chart's tangents with no new sample. Warm, nearly every vertex stops after one step
   instead of two, at the same accuracy (docs/benchmarks/iterative.md). No convergence
   leaves the point unanswered and counted, never drawn at a wrong place.
4. **Validity**: P must face both E and V (n . e > 0, n . v > 0, with the interpolated
   normal n and with the map surface's own normal, as the exact solver asks of the
   interpolated normal and of the facet's), the residual must
   vanish (the sine of the angle between n and h below :data:`RESIDUAL_TOLERANCE`),
   V and the eye must lie outside the surface, and on a non-convex mirror nothing of
   the mirror may lie between P and the eye or between P and V (samples of both
   segments inside the map's bounding sphere must all be outside the surface; section
   3.3.6 does this with a depth texture of back faces). A start whose root fails these
   tests lets the next start look for another root. Other star-shaped mirrors block the
   segment from P to V the same way (their maps, sampled where it crosses their bounding
   spheres): there the point's reflection is of the other mirror, a higher order.

``drawing/glsl/iterative_search.glsl`` is this module step by step in float32; the tests hold
them to each other.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from ...projection import NOT_PROJECTED, SEARCH_ANSWER, Projection
from ...geometry.vectors import cross, dot, lengths, normalized
from ...view import View
from .reflector_map import ReflectorMap

#: Newton steps per start at most.
MAX_ITERATIONS = 16
#: The search stops when a step moves P by less than this share of the accuracy (pixels).
STOP_FRACTION = 0.1
#: Bisections along the arc of the first guess.
GUESS_BISECTIONS = 7
#: Chart offsets (about radians) of the starts: the guess, then four points around it.
RESTARTS = ((0.0, 0.0), (0.15, 0.0), (-0.15, 0.0), (0.0, 0.15), (0.0, -0.15))
#: Finite-difference step of the Jacobian (chart units: about 1/8 texel of a 256 face).
DERIVATIVE_STEP = 1e-3
#: A Newton step moves at most this far in the chart ...
TRUST_RADIUS = 0.3
#: ... and is halved at most this many times until |F| falls.
HALVINGS = 4
#: The chart is left (a failure) beyond this radius (tan of about 56 degrees).
MAX_CHART = 1.5
#: Largest sine of the angle between the normal and the half vector at an answer.
RESIDUAL_TOLERANCE = 1e-3
#: A piece's patch (``pieces.py``) is searched for a point where the half vector lies
#: within its normals' cone widened by this (radians) beyond the sphere's own slack ...
PATCH_MARGIN = 0.05
#: ... or where the point lies within this many radii of the patch's centre.
NEAR_PATCH = 1.5
#: Two roots of one point closer than this share of the accuracy (pixels, in the view
#: at the root) are one image found twice (``search_images``): each lies within
#: STOP_FRACTION of it.
SAME_IMAGE = 0.5
#: Samples along each segment (P to the eye, P to V) of the occlusion test.
OCCLUSION_SAMPLES = 16

#: What the search says of a point (``SearchResult.status``).
FOUND, NOT_CONVERGED, NO_SURFACE, FACES_AWAY, OCCLUDED, INSIDE = 1, 0, -1, -2, -3, -4


@dataclass(frozen=True)
class SearchResult:
    """One reflector's answers for P points."""

    reflector_points: np.ndarray  # (P, 3), NaN where not found
    status: np.ndarray  # (P,) int8: FOUND, NOT_CONVERGED, NO_SURFACE, FACES_AWAY, OCCLUDED, INSIDE
    iterations: np.ndarray  # (P,) int16 Newton steps taken, every start counted
    #: (P,) bool: the answer is a *flipped* image, the point lying beyond the caustic of
    #: the mirror's reflected rays (:func:`flipped_images`); False where not found.
    flipped: np.ndarray | None = None

    @property
    def found(self) -> np.ndarray:
        return self.status == FOUND


def _camera(view: View) -> tuple[np.ndarray, bool]:
    """The eye (perspective) or the unit direction toward the viewer (orthographic)."""
    return (view.eye, True) if view.is_perspective else (view.backward, False)


def _to_eye(camera: np.ndarray, perspective: bool, positions: np.ndarray) -> np.ndarray:
    if not perspective:
        return np.broadcast_to(camera, positions.shape)
    return normalized(camera - positions)


def _perpendicular(d: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to each unit ``d``: d crossed with its smallest axis."""
    magnitude = np.abs(d)
    axis = np.where((magnitude[:, 0] <= magnitude[:, 1]) & (magnitude[:, 0] <= magnitude[:, 2]), 0,
                    np.where(magnitude[:, 1] <= magnitude[:, 2], 1, 2))
    helper = np.zeros_like(d)
    helper[np.arange(len(d)), axis] = 1.0
    return normalized(cross(d, helper))


def sphere_guess(centre, camera, perspective: bool, points: np.ndarray, radius: float) -> np.ndarray:
    """Unit directions from ``centre`` of the reflections of ``points`` on the sphere of
    ``radius`` around it (shrunk to stay inside the eye and the point), by bisection on
    the arc from the direction toward the eye to the direction toward the point."""
    offset = points - centre
    distance = lengths(offset)
    b = normalized(offset)
    if perspective:
        eye_offset = camera - centre
        a = np.broadcast_to(eye_offset / np.linalg.norm(eye_offset), b.shape)
        reach = np.minimum(distance, np.linalg.norm(eye_offset))
    else:
        a, reach = np.broadcast_to(camera, b.shape), distance
    cosine = np.clip(dot(a, b), -1.0, 1.0)
    theta = np.arccos(cosine)
    c = b - cosine[:, None] * a
    across = lengths(c)
    c = np.where((across > 1e-9)[:, None], normalized(c), _perpendicular(a))
    sphere = np.minimum(radius, 0.999 * reach)
    lo, hi = np.zeros(len(b)), theta
    for _ in range(GUESS_BISECTIONS):
        mid = 0.5 * (lo + hi)
        u = np.cos(mid)[:, None] * a + np.sin(mid)[:, None] * c
        p = centre + sphere[:, None] * u
        balance = dot(_to_eye(camera, perspective, p), u) - dot(normalized(points - p), u)
        lo, hi = np.where(balance > 0, mid, lo), np.where(balance > 0, hi, mid)
    phi = 0.5 * (lo + hi)
    return np.cos(phi)[:, None] * a + np.sin(phi)[:, None] * c


class _Chart:
    """The gnomonic chart around each point's first guess, and the residual there."""

    def __init__(self, rmap: ReflectorMap, camera, perspective: bool, points: np.ndarray, guess: np.ndarray):
        self.rmap, self.camera, self.perspective, self.points = rmap, camera, perspective, points
        self.axis = guess
        self.t1 = _perpendicular(guess)
        self.t2 = cross(guess, self.t1)

    def aim(self, rows: np.ndarray, axis: np.ndarray) -> None:
        """Centre the chart of the points ``rows`` on unit directions ``axis``."""
        self.axis[rows] = axis
        self.t1[rows] = _perpendicular(self.axis[rows])
        self.t2[rows] = cross(self.axis[rows], self.t1[rows])

    def evaluate(self, rows: np.ndarray, x: np.ndarray):
        """Residual (K, 2), position (K, 3), normal (K, 3), half vector (K, 3) and
        validity (K,) at chart points ``x`` (K, 2) of the points ``rows``."""
        d = normalized(self.axis[rows] + x[:, :1] * self.t1[rows] + x[:, 1:] * self.t2[rows])
        radius, normal, valid = self.rmap.surface(d)
        position = self.rmap.centre + radius[:, None] * d
        half = _to_eye(self.camera, self.perspective, position) + normalized(self.points[rows] - position)
        tangent = half - dot(half, normal)[:, None] * normal
        residual = np.stack([dot(tangent, self.t1[rows]), dot(tangent, self.t2[rows])], axis=1)
        return residual, position, normal, half, valid


def _solve_2x2(jacobian: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """x with J x = rhs for (K, 2, 2) J (columns the partial derivatives) and (K, 2) rhs;
    zero where J is singular."""
    det = jacobian[:, 0, 0] * jacobian[:, 1, 1] - jacobian[:, 0, 1] * jacobian[:, 1, 0]
    safe = np.where(np.abs(det) > 1e-300, det, np.inf)
    return np.stack([(jacobian[:, 1, 1] * rhs[:, 0] - jacobian[:, 0, 1] * rhs[:, 1]) / safe,
                     (jacobian[:, 0, 0] * rhs[:, 1] - jacobian[:, 1, 0] * rhs[:, 0]) / safe], axis=1)


def flipped_images(camera, perspective: bool, points, position, normal, position_u, position_v, normal_u,
                   normal_v) -> np.ndarray:
    """(K,) bool: whether each point is seen in a *flipped* image at its reflection point:
    beyond the caustic of the reflected rays, where the map (u, v, t) -> P(u, v) + t R(u, v)
    from the chart and the distance along the reflected ray R reverses orientation
    (det [Q_u, Q_v, R] < 0). Near the mirror (t = 0) every image is direct, and a convex
    mirror's caustic is virtual, so there none is flipped; where a fold of a non-convex
    mirror crowds two images of one region, one of them is flipped. A reflected triangle
    whose corners disagree joins two images across the fold: it is not drawn
    (``drawing/glsl/iterative_mesh_vert.glsl``). ``position_u``, ``position_v`` (and their
    normals) are the surface a chart step along each chart axis from ``position``."""
    def reflected(at, n):
        e = _to_eye(camera, perspective, at)
        return 2.0 * dot(n, e)[:, None] * n - e

    r = reflected(position, normal)
    t = lengths(points - position)[:, None]
    q_u = position_u - position + t * (reflected(position_u, normal_u) - r)
    q_v = position_v - position + t * (reflected(position_v, normal_v) - r)
    return dot(cross(q_u, q_v), r) < 0.0


def _newton(chart: _Chart, view: View, rows: np.ndarray, start, accuracy_px: float, give_up_stalled: bool = False):
    """Damped Newton from chart point ``start`` (2,) for the points ``rows``: converged
    (K,) bool, left (K,) bool (off the map or the chart), position, normal, half vector
    (K, 3) of the last sample, the map surface's outward normal there (from the last
    Jacobian's samples, not unit), the steps taken (K,) and whether a converged image is
    flipped (K,) (:func:`flipped_images`, from the last Jacobian's samples).
    ``give_up_stalled``: a start whose line search finds no smaller |F| fails there (a
    search for every image, :func:`search_images`: near a fold |F| has minima that are
    no roots, and a start there would take every step it is allowed)."""
    k = len(rows)
    x = np.broadcast_to(np.asarray(start, dtype=np.float64), (k, 2)).copy()
    f, position, normal, half, ok = chart.evaluate(rows, x)
    face = np.zeros((k, 3))
    flipped = np.zeros(k, dtype=bool)
    converged = np.zeros(k, dtype=bool)
    left = ~ok
    steps = np.zeros(k, np.int16)
    live = np.flatnonzero(ok)
    for step in range(MAX_ITERATIONS):
        if len(live) == 0:
            break
        r, xl, fl = rows[live], x[live], f[live]
        fu, pu, nu = chart.evaluate(r, xl + (DERIVATIVE_STEP, 0.0))[:3]
        fv, pv, nv = chart.evaluate(r, xl + (0.0, DERIVATIVE_STEP))[:3]
        # The map surface's own normal (its facets', smoothed over a texel): the ray
        # from the eye must meet its front and the reflected ray leave it (as exact.py).
        facet = cross(pu - position[live], pv - position[live])
        face[live] = facet * np.sign(dot(facet, position[live] - chart.rmap.centre))[:, None]
        jacobian = np.stack([fu - fl, fv - fl], axis=2) / DERIVATIVE_STEP
        delta = -_solve_2x2(jacobian, fl)
        delta *= np.minimum(1.0, TRUST_RADIUS / np.maximum(lengths(delta), 1e-300))[:, None]
        # Line search: scales 1, 1/2, ... until |F| falls; the last one is taken regardless.
        current = lengths(fl)
        scale = np.ones(len(live))
        accepted = np.zeros(len(live), dtype=bool)
        new_x, new_f, new_p, new_n, new_h = xl.copy(), fl.copy(), position[live].copy(), normal[live].copy(), \
            half[live].copy()
        new_ok = np.zeros(len(live), dtype=bool)
        for halving in range(HALVINGS + 1):
            trying = np.flatnonzero(~accepted)
            trial_x = xl[trying] + scale[trying, None] * delta[trying]
            trial = chart.evaluate(r[trying], trial_x)
            new_x[trying] = trial_x
            new_f[trying], new_p[trying], new_n[trying], new_h[trying], new_ok[trying] = trial
            accepted[trying] = trial[4] & (lengths(trial[0]) < current[trying])
            scale[trying] *= 0.5
        moved = lengths(new_p - position[live])
        tolerance = STOP_FRACTION * accuracy_px * view.pixel_size_at(new_p)
        lost = ~new_ok | (lengths(new_x) > MAX_CHART) | (give_up_stalled & ~accepted)
        # The step after this one, predicted with this step's Jacobian (a chord step):
        # where it would move P by less than the tolerance it is taken without new
        # samples (P moved along the chart's tangents), and the search ends a step early.
        following = -_solve_2x2(jacobian, new_f)
        predicted = ((pu - position[live]) * following[:, :1] + (pv - position[live]) * following[:, 1:]) \
            / DERIVATIVE_STEP
        # Only where the residual already passes the answer's test (a singular Jacobian
        # predicts no step at all).
        settled = ~lost & (lengths(predicted) < tolerance) & _residual_passes(new_n, new_h)
        finished = ~lost & (moved < tolerance) | settled
        # Only a converged answer's parity is read: from this step's samples, before they move.
        done = live[finished]
        flipped[done] = flipped_images(chart.camera, chart.perspective, chart.points[r[finished]], position[done],
                                       normal[done], pu[finished], pv[finished], nu[finished], nv[finished])
        new_p[settled] += predicted[settled]
        x[live], f[live], position[live], normal[live], half[live] = new_x, new_f, new_p, new_n, new_h
        steps[live] = step + 1
        left[live[lost]] = True
        converged[live[finished]] = True
        live = live[~(lost | finished)]
    return converged, left, position, normal, half, face, steps, flipped


def search_reflections(rmap: ReflectorMap, view: View, points, accuracy_px: float = 1.0,
                       previous: np.ndarray | None = None, occluders=()) -> SearchResult:
    """The reflection point of every point (P, 3) on the mapped reflector, seen from
    ``view``'s eye (or, orthographic, its direction). ``previous`` (P, 3), NaN where
    none: last frame's answers, tried first (a view that moved a little). ``occluders``:
    the maps of the other star-shaped reflectors, which may block a reflected segment
    (its reflection there is another mirror's: a higher order)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = len(points)
    status = np.full(n, NO_SURFACE, np.int8)
    iterations = np.zeros(n, np.int16)
    flipped = np.zeros(n, dtype=bool)
    answer = np.full((n, 3), np.nan)
    camera, perspective = _camera(view)
    active, inside = _searched(rmap, camera, perspective, points)
    status[inside] = INSIDE
    if len(active) == 0:
        return SearchResult(answer, status, iterations, flipped)
    pending = active
    if previous is not None:
        resumed = pending[np.isfinite(previous[pending]).all(axis=1)]
        axis = np.zeros((n, 3))
        axis[resumed] = normalized(previous[resumed] - rmap.centre)
        converged, left, position, normal, half, face, steps, image_flipped = _newton(
            _Chart(rmap, camera, perspective, points, axis), view, resumed, (0.0, 0.0), accuracy_px)
        iterations[resumed] += steps
        verdict = np.full(len(resumed), NOT_CONVERGED, np.int8)
        verdict[converged] = _check(rmap, camera, perspective, points[resumed[converged]], position[converged],
                                    normal[converged], half[converged], face[converged])
        status[resumed[verdict == FOUND]] = FOUND
        answer[resumed[verdict == FOUND]] = position[verdict == FOUND]
        flipped[resumed[verdict == FOUND]] = image_flipped[verdict == FOUND]
        pending = np.setdiff1d(pending, resumed[verdict == FOUND])
    chart = _Chart(rmap, camera, perspective, points, np.tile((0.0, 0.0, 1.0), (n, 1)))
    if rmap.patches is None:
        chart.aim(pending, sphere_guess(rmap.centre, camera, perspective, points[pending], rmap.mean_radius))
        # On a convex mirror a point has one reflection at most: a start that fails has none.
        starts = [(pending, start) for start in (RESTARTS[:1] if rmap.convex else RESTARTS)]
    else:
        starts = _patch_starts(rmap, chart, pending)
    for attempt, (rows, start) in enumerate(starts):
        if len(pending) == 0:
            break
        rows = np.intersect1d(rows, pending, assume_unique=True)
        if len(rows) == 0:
            continue
        converged, left, position, normal, half, face, steps, image_flipped = _newton(chart, view, rows, start,
                                                                                      accuracy_px)
        iterations[rows] += steps
        verdict = np.where(left, NO_SURFACE, NOT_CONVERGED).astype(np.int8)
        verdict[converged] = _check(rmap, camera, perspective, points[rows[converged]], position[converged],
                                    normal[converged], half[converged], face[converged])
        # A later start keeps its verdict only where it found the answer.
        keep = (verdict == FOUND) | (attempt == 0)
        status[rows[keep]] = verdict[keep]
        answer[rows[verdict == FOUND]] = position[verdict == FOUND]
        flipped[rows[verdict == FOUND]] = image_flipped[verdict == FOUND]
        pending = np.setdiff1d(pending, rows[verdict == FOUND], assume_unique=True)
    _block(SearchResult(answer, status, iterations, flipped), points, occluders)
    return SearchResult(answer, status, iterations, flipped)


def _searched(rmap: ReflectorMap, camera, perspective: bool, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(indices of the points to search, (P,) bool of those INSIDE the mirror): a point
    that is not finite is neither; with the eye inside, every finite point is inside."""
    finite = np.isfinite(points).all(axis=1)
    safe_points = np.where(finite[:, None], points, rmap.centre)
    inside = finite & (lengths(safe_points - rmap.centre) <= 1e-9 * max(rmap.max_radius, 1e-300))
    inside |= finite & rmap.inside(safe_points)
    if perspective and rmap.inside(camera[None])[0]:
        inside = finite
    return np.flatnonzero(finite & ~inside), inside


def _block(result: SearchResult, points: np.ndarray, occluders) -> None:
    """Mark OCCLUDED (in place) the answers whose segment to their point an occluder's
    map blocks (another mirror's surface: a higher order)."""
    found = np.flatnonzero(result.status == FOUND)
    for occluder in occluders:
        found = found[result.status[found] == FOUND]  # a blocked answer is NaN now
        blocked = found[_segment_blocked(occluder, result.reflector_points[found], points[found],
                                         dense_near_start=False)]
        result.status[blocked] = OCCLUDED
        result.reflector_points[blocked] = np.nan
        result.flipped[blocked] = False


def search_images(rmap: ReflectorMap, view: View, points, accuracy_px: float = 1.0, occluders=()) -> list:
    """Every image of every point (P, 3) in a folded mirror's map (``rmap.images`` > 1,
    with ``patches``, :mod:`.fold_patches`): Newton from the first guess and from every
    patch that admits a point, each distinct root kept (:data:`SAME_IMAGE`) in the order
    the starts find them, up to ``rmap.images``. A list of ``rmap.images`` SearchResults,
    slot k holding each point's k-th image (status NO_SURFACE where it has fewer;
    iterations: every start's steps, counted in slot 0)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n, slots = len(points), rmap.images
    camera, perspective = _camera(view)
    results = [SearchResult(np.full((n, 3), np.nan), np.full(n, NO_SURFACE, np.int8), np.zeros(n, np.int16),
                            np.zeros(n, dtype=bool)) for _ in range(slots)]
    answers = np.full((slots, n, 3), np.nan)
    active, inside = _searched(rmap, camera, perspective, points)
    for result in results:
        result.status[inside] = INSIDE
    count = np.zeros(n, np.int64)
    chart = _Chart(rmap, camera, perspective, points, np.tile((0.0, 0.0, 1.0), (n, 1)))
    for rows, start in _image_starts(rmap, chart, active):
        rows = rows[count[rows] < slots]
        if len(rows) == 0:
            continue
        converged, _, position, normal, half, face, steps, image_flipped = _newton(
            chart, view, rows, start, accuracy_px, give_up_stalled=True)
        results[0].iterations[rows] += steps
        found = np.flatnonzero(converged)
        found = found[_check(rmap, camera, perspective, points[rows[found]], position[found], normal[found],
                             half[found], face[found]) == FOUND]
        rows, position, image_flipped = rows[found], position[found], image_flipped[found]
        apart = np.linalg.norm(answers[:, rows] - position, axis=2)
        same = SAME_IMAGE * accuracy_px * view.pixel_size_at(position)
        new = ~(apart < same).any(axis=0)
        rows, position, image_flipped = rows[new], position[new], image_flipped[new]
        slot_of = count[rows]
        answers[slot_of, rows] = position
        for k in np.unique(slot_of):
            into = slot_of == k
            slot = results[k]
            slot.reflector_points[rows[into]], slot.status[rows[into]] = position[into], FOUND
            slot.flipped[rows[into]] = image_flipped[into]
        count[rows] += 1
    for result in results:
        _block(result, points, occluders)
    return results


def patch_admits(patch: np.ndarray, camera, perspective: bool, points: np.ndarray) -> np.ndarray:
    """(K,) bool: the patch (a row of ``ReflectorMap.patches``, its sphere's centre made
    absolute) may hold the reflection of ``points``: the half vector between the
    directions from the patch to the eye and to the point lies within the cone of its
    normals, widened by :data:`PATCH_MARGIN` and by the angles its bounding sphere of
    radius r subtends from the eye and from the point (the half vector of any of its
    points differs by at most their sum); or the point lies within :data:`NEAR_PATCH`
    radii of it. With no trigonometry, as the GPU tests every patch for every vertex:
    asin(r / d) <= pi r / (2 d), and 1 - cos x <= x^2 / 2, so the test only admits more."""
    axis, cone, centre, radius = patch[0, :3], float(patch[0, 3]), patch[1, :3], float(patch[1, 3])
    to_point = points - centre
    point_distance = np.maximum(lengths(to_point), 1e-300)
    if perspective:
        to_eye = camera - centre
        eye_distance = max(float(np.linalg.norm(to_eye)), 1e-300)
        eye_slack, to_eye = radius / eye_distance, to_eye / eye_distance
    else:
        to_eye, eye_slack = camera, 0.0
    half = normalized(to_point / point_distance[:, None] + to_eye)
    reach = cone + PATCH_MARGIN + 0.5 * np.pi * (eye_slack + radius / point_distance)
    return (1.0 - half @ axis <= 0.5 * reach * reach) | (point_distance < NEAR_PATCH * radius)


def _patch_starts(rmap: ReflectorMap, chart: _Chart, pending: np.ndarray) -> Iterator:
    """The starts on a piece's map, patch after patch (``ReflectorMap.patches``): (the
    points of ``pending`` the patch admits, chart offset 0), their chart aimed at the
    patch's start direction as it comes (a generator: the caller leaves out the points
    an earlier patch found)."""
    for patch in rmap.patches.astype(np.float64):
        centred = patch.copy()
        centred[1, :3] += rmap.centre
        rows = pending[patch_admits(centred, chart.camera, chart.perspective, chart.points[pending])]
        chart.aim(rows, np.broadcast_to(patch[2, :3], (len(rows), 3)))
        yield rows, (0.0, 0.0)


def _image_starts(rmap: ReflectorMap, chart: _Chart, active: np.ndarray) -> Iterator:
    """The starts of a search for every image: the one-image search's first guess (so it
    finds what that search finds first), then every patch (:func:`_patch_starts`)."""
    chart.aim(active, sphere_guess(rmap.centre, chart.camera, chart.perspective, chart.points[active],
                                   rmap.mean_radius))
    yield active, RESTARTS[0]
    yield from _patch_starts(rmap, chart, active)


def _residual_passes(normal: np.ndarray, half: np.ndarray) -> np.ndarray:
    """(K,) bool: the residual vanishes, the sine of the angle between the normal and the
    half vector below :data:`RESIDUAL_TOLERANCE`."""
    return lengths(cross(normal, half)) / np.maximum(lengths(half), 1e-300) < RESIDUAL_TOLERANCE


def _check(rmap: ReflectorMap, camera, perspective: bool, points, position, normal, half, face) -> np.ndarray:
    """FOUND where a converged sample is an answer, else why not: FACES_AWAY, OCCLUDED,
    or NOT_CONVERGED for a stationary point of |F| that is no root."""
    to_eye = _to_eye(camera, perspective, position)
    to_point = normalized(points - position)
    facing = ((dot(normal, to_eye) > 0) & (dot(normal, to_point) > 0)
              & (dot(face, to_eye) > 0) & (dot(face, to_point) > 0))
    verdict = np.where(_residual_passes(normal, half), np.where(facing, FOUND, FACES_AWAY),
                       NOT_CONVERGED).astype(np.int8)
    if not rmap.convex:
        check = np.flatnonzero(verdict == FOUND)
        verdict[check[_occluded(rmap, camera, perspective, position[check], points[check])]] = OCCLUDED
    return verdict


def _sphere_chord(start: np.ndarray, direction: np.ndarray, length: np.ndarray, centre, radius: float):
    """Where a segment (unit ``direction``, ``length``) runs inside a sphere: distances
    (t0, t1) along it, t1 <= t0 where it misses."""
    offset = start - centre
    b = dot(offset, direction)
    disc = b * b - (dot(offset, offset) - radius * radius)
    root = np.sqrt(np.maximum(disc, 0.0))
    return np.maximum(-b - root, 0.0), np.where(disc > 0, np.minimum(-b + root, length), -1.0)


def _segment_blocked(rmap: ReflectorMap, starts: np.ndarray, ends: np.ndarray, dense_near_start: bool,
                     towards: np.ndarray | None = None) -> np.ndarray:
    """(K,) bool: one of :data:`OCCLUSION_SAMPLES` samples of each segment, where it runs
    inside the map's bounding sphere, lies inside the surface. ``dense_near_start``:
    samples quadratically denser next to the start (a neighbouring bump hiding a grazing
    answer of the mirror itself), else uniform over the chord. ``towards``: unit
    directions of segments of infinite length instead of ``ends``."""
    if len(starts) == 0:
        return np.zeros(0, dtype=bool)
    if towards is None:
        direction, length = normalized(ends - starts), lengths(ends - starts)
    else:
        direction, length = towards, np.full(len(starts), np.inf)
    t0, t1 = _sphere_chord(starts, direction, length, rmap.centre, rmap.max_radius)
    k = np.arange(OCCLUSION_SAMPLES)
    fractions = ((k + 1.0) / OCCLUSION_SAMPLES) ** 2 if dense_near_start else (k + 0.5) / OCCLUSION_SAMPLES
    t = t0[:, None] + (t1 - t0)[:, None] * fractions
    samples = starts[:, None] + t[:, :, None] * direction[:, None]
    inside = rmap.inside(samples.reshape(-1, 3)).reshape(len(starts), -1)
    return (inside & (t1 > t0)[:, None]).any(axis=1)


def _occluded(rmap: ReflectorMap, camera, perspective: bool, positions: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(K,) bool: the mirror itself lies between P and the eye, or between P and V."""
    if perspective:
        toward_eye = _segment_blocked(rmap, positions, np.broadcast_to(camera, positions.shape), True)
    else:
        toward_eye = _segment_blocked(rmap, positions, None, True, towards=np.broadcast_to(camera, positions.shape))
    return toward_eye | _segment_blocked(rmap, positions, points, True)


@dataclass
class IterativeReflector:
    """The iterative method for one reflector, behind the common interface: ``project``
    answers where points appear reflected in a view (one group, the reflector's own
    first-order history)."""

    index: int  # the reflector's index in the scene's reflector list
    name: str
    reflector_map: ReflectorMap
    accuracy_px: float = 1.0
    #: The other star-shaped reflectors' maps: they may block a reflected segment.
    occluders: tuple = ()
    #: Which piece of its mirror the map holds (``pieces.py``; 0 for a star-shaped mirror).
    piece: int = 0

    @property
    def groups(self) -> list:
        return [(self.index,)]

    def search(self, view: View, points) -> SearchResult:
        """The first answer slot (the only one but on a folded mirror)."""
        return self.search_slots(view, points)[0]

    def search_slots(self, view: View, points) -> list:
        """The SearchResult of each answer slot: one, or ``reflector_map.images`` for a
        folded mirror (:func:`search_images`)."""
        if self.reflector_map.images > 1:
            return search_images(self.reflector_map, view, points, self.accuracy_px, occluders=self.occluders)
        return [search_reflections(self.reflector_map, view, points, self.accuracy_px, occluders=self.occluders)]

    def project(self, view: View, points) -> Projection:
        """Where ``points`` appear, one row of the projection per answer slot."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        rows = [_projected(view, points, found) for found in self.search_slots(view, points)]
        return Projection(groups=self.groups * len(rows),
                          **{name: np.stack([row[name] for row in rows]) for name in rows[0]})


def _projected(view: View, points: np.ndarray, found: SearchResult) -> dict:
    """One answer slot as a Projection's rows (its answers in the view)."""
    valid = found.found & view.in_view(np.nan_to_num(found.reflector_points))
    reflector_points = np.where(valid[:, None], found.reflector_points, np.nan)
    pixels, _ = view.to_pixels(np.nan_to_num(reflector_points))
    pixels[~valid] = np.nan
    distance = np.where(valid, lengths(points - np.nan_to_num(reflector_points)), np.nan)
    return {"reflector_points": reflector_points, "valid": valid, "pixels": pixels, "ray_distance": distance,
            "leaf_kind": np.where(valid, SEARCH_ANSWER, NOT_PROJECTED).astype(np.int8)}
