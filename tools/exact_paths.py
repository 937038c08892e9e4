# SPDX-License-Identifier: GPL-3.0-or-later
"""The exact reference solver for second-order reflections: paths E -> x1 -> x2 -> p.

SBC paper (Popescu, Sacks, Mei 2006) section III-B traces view rays on through the
reflectors; a point p seen after two reflections appears where the view ray meets the
first reflector point x1 of a light path eye -> x1 (on reflector A) -> x2 (on reflector
B) -> p that obeys the law of reflection at both points, on our surface model (flat
triangles with interpolated normals, two-sided, as ``engine/reference/exact.py``):

    normalize(d(x1 -> E) + d(x1 -> x2)) = n(x1),   normalize(d(x2 -> x1) + d(x2 -> p)) = n(x2).

That is four equations in the barycentric unknowns (u1, v1, u2, v2) of a triangle pair,
solved by Newton's method (4x4 Jacobian by forward differences, backtracking line search,
an active set of unfinished pairs; a pair whose full step aims far outside its triangles
twice running is dropped, its root belonging to a neighbouring pair) for every candidate
(point, triangle pair) at once, from two starts (both centroids, and x2 at p's foot).

Candidates are found in two stages:

1. per view: triangle pairs (t1, t2) where t1 may reflect the eye toward t2 (a BVH
   descent per t1 with the half-vector cones of ``exact._may_reflect`` generalised from
   points to bounding spheres: the direction from any x in a sphere of radius r1 to any
   y in a sphere of radius r2 turns at most asin((r1 + r2) / distance) from the
   centre-to-centre direction), keeping only t2 with a corner on the eye's side of t1's
   plane (the ray must leave t1's front);
2. per point: the direction D of the middle segment x1 -> x2 must lie in three cones at
   once: the eye's rays reflected by t1 (a normal cone of half-angle a reflects into
   one of 2a), the rays t2 reflects toward p (likewise), and the directions from t1 to
   t2; a triple is kept where the cones meet pairwise.

x1 is sought only on facets a view ray through some pixel centre hits, and their
one-ring (``_seen_facets``): mirrors being two-sided, the cones alone keep the hidden
back of every closed mirror, whose pairs with its own front outnumber all others.

A solution is *visible* when x1 is in the view frustum and is the view ray's first hit,
nothing lies between x1 and x2 or between x2 and p, and each reflection is valid (the
ray arrives in front of the interpolated normal and leaves the front of the facet), the
same rules the ray map (``engine/methods/sbc/raymap.py``) applies when it traces
second-order rays.

The extension never solves for exact paths at runtime: this is the yard stick of the tests
and benchmarks of second-order reflections, not shipped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..engine.geometry.bvh import descend
from ..engine.reference.exact import (CONE_SLACK, INSIDE_TOLERANCE, _first_hit_of_view_ray, _foot,
                                      first_of_duplicates, half_vector_may_meet_cone, turn_toward)
from ..engine.geometry.raytrace import ReflectorSet, reflect
from ..engine.geometry.vectors import cross, dot, lengths, normalized, unit
from ..engine.view import View

NEWTON_ITERATIONS = 30
NEWTON_TOLERANCE = 1e-13
#: The residual (unit-vector difference) below which a pair counts as converged.
CONVERGED_RESIDUAL = 1e-9
BACKTRACK_HALVINGS = 8
#: A pair this far outside either triangle (barycentric units) after ABANDON_AFTER
#: iterations is dropped: its root, if any, belongs to a neighbouring pair.
ABANDON_DISTANCE = 0.5
ABANDON_AFTER = 5
#: ... and a pair whose full (unlimited) Newton step aims this far outside, twice running.
ABANDON_AIM = 0.5
#: Points per chunk of the per-point stage (bounds the (point, t2) arrays).
POINT_CHUNK = 128


@dataclass(frozen=True)
class SecondOrderReflections:
    """All second-order paths found; one row per (point, path), sorted by point."""

    point: np.ndarray  # (S,) index of the reflected point
    history: np.ndarray  # (S, 2) reflectors of x1 and x2
    triangle: np.ndarray  # (S, 2) triangles of x1 and x2 in the ReflectorSet
    first: np.ndarray  # (S, 3) x1, the first reflector point (where the reflection appears)
    second: np.ndarray  # (S, 3) x2
    pixel: np.ndarray  # (S, 2) where x1 appears in the view
    in_view: np.ndarray  # (S,) bool
    seen_by_eye: np.ndarray  # (S,) bool: x1 is the view ray's first hit, valid reflection there
    sees_second: np.ndarray  # (S,) bool: nothing between x1 and x2, valid reflection at x2
    sees_point: np.ndarray  # (S,) bool: nothing between x2 and p, ray leaves x2's facet

    @property
    def visible(self) -> np.ndarray:
        return self.in_view & self.seen_by_eye & self.sees_second & self.sees_point

    def select(self, mask: np.ndarray) -> "SecondOrderReflections":
        return SecondOrderReflections(*(getattr(self, f)[mask] for f in self.__dataclass_fields__))


def solve_second_order(reflector_set: ReflectorSet, view: View, points: np.ndarray) -> SecondOrderReflections:
    """Every second-order reflection path of every point, with visibility."""
    if not view.is_perspective:
        raise ValueError(f"{view.name!r}: the second-order solver needs a perspective view")
    points = np.asarray(points, dtype=np.float64)
    spheres = _triangle_spheres(reflector_set)
    first_leg = _first_leg_pairs(reflector_set, view, spheres)
    sources = _second_leg_sources(spheres, *first_leg) if len(first_leg[0]) else None
    parts = [_solve_chunk(reflector_set, view, spheres, first_leg, sources, points[start:start + POINT_CHUNK],
                          start) for start in range(0, len(points), POINT_CHUNK)]
    found = {key: np.concatenate([part[key] for part in parts]) for key in parts[0]} if parts else None
    if found is None or len(found["point"]) == 0:
        return _empty()
    return _with_visibility(reflector_set, view, points, found)


# --- candidates -------------------------------------------------------------------------


@dataclass(frozen=True)
class _Spheres:
    centre: np.ndarray  # (T, 3) triangle bounding-sphere centres
    radius: np.ndarray  # (T,)
    axis: np.ndarray  # (T, 3) normal-cone axis
    cos: np.ndarray  # (T,) normal-cone half-angle cosine


def _triangle_spheres(reflector_set: ReflectorSet) -> _Spheres:
    corners = reflector_set.vertices[reflector_set.triangles]
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    normals = reflector_set.normals[reflector_set.triangles]
    axis = normalized(normals.sum(axis=1))
    cos = np.einsum("tkd,td->tk", normals, axis).min(axis=1)
    return _Spheres(0.5 * (lo + hi), 0.5 * lengths(hi - lo), axis, cos)


def _first_leg_pairs(reflector_set: ReflectorSet, view: View, spheres: _Spheres):
    """(t1, t2) pairs where a point of t1 may reflect the eye toward a point of t2."""
    bvh = reflector_set.bvh
    boxes = [(np.where(lo <= hi, lo, 0.0), np.where(lo <= hi, hi, 0.0)) for lo, hi in zip(bvh.box_lo, bvh.box_hi)]
    centres = [0.5 * (lo + hi) for lo, hi in boxes]
    radii = [0.5 * lengths(hi - lo) for lo, hi in boxes]
    to_eye = view.eye - spheres.centre
    eye_distance = lengths(to_eye)
    to_eye /= eye_distance[:, None]
    eye_turn = turn_toward(spheres.radius, eye_distance)
    faces_eye = _seen_facets(reflector_set, view)

    def pair_test(t1, centre, radius):
        offset = centre - spheres.centre[t1]
        distance = lengths(offset)
        toward = offset / np.maximum(distance, 1e-300)[:, None]
        return half_vector_may_meet_cone(to_eye[t1], eye_turn[t1], toward,
                                         turn_toward(spheres.radius[t1] + radius, distance),
                                         spheres.axis[t1], spheres.cos[t1])

    # The ray from x1 must leave the front of t1's facet (the eye's side of its plane).
    front = reflector_set.face_normals * np.sign(dot(view.eye - reflector_set.v0, reflector_set.face_normals))[:, None]
    # A facet whose corners lie in t1's plane (the other half of a flat quad) gets only
    # grazing paths; rounding must not let it through.
    ahead_tolerance = 1e-9 * reflector_set.scale

    def node_test(queries, level, nodes):
        lo, hi = bvh.box_lo[level][nodes], bvh.box_hi[level][nodes]
        non_empty = lo[:, 0] <= hi[:, 0]
        lo, hi = np.where(non_empty[:, None], lo, 0.0), np.where(non_empty[:, None], hi, 0.0)
        t1 = faces_eye[queries]
        ahead = (dot(0.5 * (lo + hi) - reflector_set.v0[t1], front[t1])
                 + dot(np.abs(front[t1]), 0.5 * (hi - lo)) > ahead_tolerance)
        return non_empty & ahead & pair_test(t1, centres[level][nodes], radii[level][nodes])

    query, t2 = descend(bvh, np.arange(len(faces_eye)), node_test)
    t1 = faces_eye[query]
    corners = reflector_set.vertices[reflector_set.triangles[t2]] - reflector_set.v0[t1][:, None]
    ahead = np.einsum("pkd,pd->pk", corners, front[t1]).max(axis=1) > ahead_tolerance
    keep = ahead & pair_test(t1, spheres.centre[t2], spheres.radius[t2])
    t1, t2 = t1[keep], t2[keep]
    # The tracer never lets a reflected ray hit its own facet or that facet's one-ring.
    keep = (t1 != t2) & ~reflector_set.neighbours(t1, t2)
    t1, t2 = t1[keep], t2[keep]
    order = np.argsort(t2, kind="stable")
    return t1[order], t2[order]


def _seen_facets(reflector_set: ReflectorSet, view: View) -> np.ndarray:
    """Facets that may hold a visible x1: those the view rays of every pixel centre hit
    first, grown by their one-ring among facets that face the eye the same way.

    Mirrors are two-sided, so the cones alone keep the hidden back of every closed
    mirror (whose pairs with its own front are most of all pairs). The one step that
    samples rather than bounds: a facet whose visible part lies between pixel centres
    and touches no facet a centre ray hits that faces the eye the same way (a sub-pixel
    sliver at a fold) is missed.
    """
    origins, directions = view.pixel_rays(view.pixel_grid(1))
    hit = reflector_set.intersect(origins, directions).triangle
    hit = np.unique(hit[hit >= 0])
    corners = reflector_set.triangles
    facing = (dot(view.eye - reflector_set.v0, reflector_set.face_normals)
              * dot(reflector_set.face_normals, reflector_set.normals[corners].sum(axis=1))) > 0
    welded = reflector_set.welded_triangles
    seen = np.zeros(len(corners), dtype=bool)
    for side in (True, False):
        marked = np.zeros(welded.max() + 1, dtype=bool)
        marked[welded[hit[facing[hit] == side]].ravel()] = True
        seen |= (facing == side) & marked[welded].any(axis=1)
    return np.flatnonzero(seen)


def _second_leg_sources(spheres: _Spheres, t1: np.ndarray, t2: np.ndarray):
    """Per distinct t2: the bounding sphere of its t1 partners (centre, radius) and its pair slice."""
    second, start = np.unique(t2, return_index=True)
    stop = np.append(start[1:], len(t2))
    count = stop - start
    lo = np.minimum.reduceat(spheres.centre[t1] - spheres.radius[t1, None], start, axis=0)
    hi = np.maximum.reduceat(spheres.centre[t1] + spheres.radius[t1, None], start, axis=0)
    return second, start, count, 0.5 * (lo + hi), 0.5 * lengths(hi - lo)


def _candidates(spheres, eye, first_leg, sources, points):
    """(point, t1, t2) triples that may hold a second-order path."""
    t1_sorted, t2_sorted = first_leg
    second, start, count, source_centre, source_radius = sources
    n_points, n_second = len(points), len(second)
    point = np.repeat(np.arange(n_points), n_second)
    k = np.tile(np.arange(n_second), n_points)
    arrival, arrival_width = _arrival_cone(spheres, second[k], points[point])
    keep = _cones_meet(arrival, arrival_width, *_toward(spheres, second[k], source_centre[k], source_radius[k]))
    point, k = point[keep], k[keep]
    # Expand each surviving (point, t2) into its first-leg pairs.
    n = count[k]
    pair = np.repeat(start[k] - np.cumsum(n) + n, n) + np.arange(n.sum())
    arrival, arrival_width = np.repeat(arrival[keep], n, axis=0), np.repeat(arrival_width[keep], n)
    point = np.repeat(point, n)
    t1, t2 = t1_sorted[pair], t2_sorted[pair]
    leaving, leaving_width = _leaving_cone(spheres, eye, t1)
    across, across_width = _toward(spheres, t2, spheres.centre[t1], spheres.radius[t1])
    keep = (_cones_meet(arrival, arrival_width, across, across_width)
            & _cones_meet(leaving, leaving_width, across, across_width)
            & _cones_meet(leaving, leaving_width, arrival, arrival_width))
    return point[keep], t1[keep], t2[keep]


def _leaving_cone(spheres, eye, t1):
    """Cone of the directions the eye's rays leave t1 in, after reflection.

    Reflection about n or -n is the same (two-sided mirrors); turning the normal by a
    turns the reflected ray by at most 2a, turning the incoming ray by b turns it by b.
    """
    offset = spheres.centre[t1] - eye
    distance = lengths(offset)
    incoming = offset / distance[:, None]
    width = 2 * np.arccos(np.clip(spheres.cos[t1], -1, 1)) + turn_toward(spheres.radius[t1], distance)
    return reflect(incoming, spheres.axis[t1]), width


def _arrival_cone(spheres, t2, points):
    """Cone of the directions a ray must arrive at t2 in to leave toward the point."""
    offset = points - spheres.centre[t2]
    distance = lengths(offset)
    to_point = offset / np.maximum(distance, 1e-300)[:, None]
    width = 2 * np.arccos(np.clip(spheres.cos[t2], -1, 1)) + turn_toward(spheres.radius[t2], distance)
    return reflect(to_point, spheres.axis[t2]), width


def _toward(spheres, t2, centre, radius):
    """Cone of the directions from a sphere (centre, radius) toward t2."""
    offset = spheres.centre[t2] - centre
    distance = lengths(offset)
    return offset / np.maximum(distance, 1e-300)[:, None], turn_toward(spheres.radius[t2] + radius, distance)


def _cones_meet(axis_a, width_a, axis_b, width_b) -> np.ndarray:
    """Two cones (unit axes, half-angles) share a direction."""
    angle = np.arccos(np.clip(dot(axis_a, axis_b), -1.0, 1.0))
    return angle <= width_a + width_b + CONE_SLACK


# --- Newton ---------------------------------------------------------------------------------


def _solve_chunk(reflector_set, view, spheres, first_leg, sources, points, offset) -> dict:
    empty = {"point": np.zeros(0, np.int64), "t1": np.zeros(0, np.int64), "t2": np.zeros(0, np.int64),
             "uv": np.zeros((0, 4)), "orientation": np.zeros((0, 2))}
    if sources is None or len(points) == 0:
        return empty
    point, t1, t2 = _candidates(spheres, view.eye, first_leg, sources, points)
    if len(point) == 0:
        return empty
    # Two starts: both centroids, and x2 at the point's foot on t2 (for points close to
    # the second mirror, where the direction to p swings fast across t2).
    centroid = np.full((len(point), 2), 1.0 / 3.0)
    starts = np.concatenate([np.concatenate([centroid, centroid], axis=1),
                             np.concatenate([centroid, _foot(reflector_set, points[point], t2)], axis=1)])
    point, t1, t2 = (np.concatenate([a, a]) for a in (point, t1, t2))
    uv, converged, orientation = _newton(reflector_set, view, points[point], t1, t2, starts)
    inside = converged & _inside(uv[:, :2]) & _inside(uv[:, 2:])
    point, t1, t2, uv, orientation = point[inside], t1[inside], t2[inside], uv[inside], orientation[inside]
    x1 = _positions(reflector_set, t1, uv[:, :2])
    x2 = _positions(reflector_set, t2, uv[:, 2:])
    keep = first_of_duplicates((point, reflector_set.owner[t1], reflector_set.owner[t2]), (x1, x2),
                               reflector_set.scale)
    return {"point": point[keep] + offset, "t1": t1[keep], "t2": t2[keep], "uv": uv[keep],
            "orientation": orientation[keep]}


def _inside(uv):
    u, v = uv[:, 0], uv[:, 1]
    return (u >= -INSIDE_TOLERANCE) & (v >= -INSIDE_TOLERANCE) & (u + v <= 1 + INSIDE_TOLERANCE)


def _positions(reflector_set, triangles, uv):
    e1, e2 = reflector_set.e1[triangles], reflector_set.e2[triangles]
    return reflector_set.v0[triangles] + uv[:, :1] * e1 + uv[:, 1:] * e2


def _facet_table(reflector_set: ReflectorSet, triangles: np.ndarray, orientation: np.ndarray) -> list:
    """Per-pair columns of one facet the residual reads: corner v0, edges e1 and e2,
    oriented corner normal n0 and normal differences, two axes of the facet's plane."""
    corners = reflector_set.triangles[triangles]
    n0 = reflector_set.normals[corners[:, 0]]
    e1 = reflector_set.e1[triangles]
    axis_u = normalized(e1)
    # Normals turned toward where the ray comes from (the interpolation is linear, so
    # turning the corner normals turns the interpolated one).
    turn = orientation[:, None]
    return [reflector_set.v0[triangles], e1, reflector_set.e2[triangles], n0 * turn,
            (reflector_set.normals[corners[:, 1]] - n0) * turn, (reflector_set.normals[corners[:, 2]] - n0) * turn,
            axis_u, cross(reflector_set.face_normals[triangles], axis_u)]


def _residual(w, table, eye):
    """Reflection-law residuals (..., N, 4) at parameters w (..., N, 4) of the pairs in ``table``.

    At each point the half vector minus the (oriented) interpolated normal, in two axes
    of the facet's plane; ``w`` may carry leading axes (the Jacobian's perturbations).
    """
    def column(k):
        return table[:, 3 * k:3 * k + 3]

    def facet(base, uv):
        x = column(base) + uv[..., :1] * column(base + 1) + uv[..., 1:] * column(base + 2)
        n = unit(column(base + 3) + uv[..., :1] * column(base + 4) + uv[..., 1:] * column(base + 5))
        return x, n

    def in_plane(base, r):
        return np.stack([np.einsum("...j,...j->...", r, column(base + 6)),
                         np.einsum("...j,...j->...", r, column(base + 7))], axis=-1)

    x1, n1 = facet(0, w[..., :2])
    x2, n2 = facet(8, w[..., 2:])
    across = unit(x2 - x1)
    half1 = unit(unit(eye - x1) + across)
    half2 = unit(unit(table[:, 48:51] - x2) - across)
    return np.concatenate([in_plane(0, half1 - n1), in_plane(8, half2 - n2)], axis=-1)


def _newton(reflector_set, view, points, t1, t2, starts):
    """Newton's method on the two reflection laws in (u1, v1, u2, v2).

    Normals are turned toward where the ray comes from: the eye for t1, t1's centroid
    for t2. The Jacobian is taken by forward differences, all four perturbations in one
    batched residual; each iteration gathers the active pairs' rows of one table once.
    """
    eye = view.eye
    centroid1 = reflector_set.v0[t1] + (reflector_set.e1[t1] + reflector_set.e2[t1]) / 3
    centroid2 = reflector_set.v0[t2] + (reflector_set.e1[t2] + reflector_set.e2[t2]) / 3
    orientation = np.stack([np.where(dot(eye - centroid1, reflector_set.face_normals[t1]) >= 0, 1.0, -1.0),
                            np.where(dot(centroid1 - centroid2, reflector_set.face_normals[t2]) >= 0, 1.0, -1.0)],
                           axis=1)
    table = np.concatenate(_facet_table(reflector_set, t1, orientation[:, 0])
                           + _facet_table(reflector_set, t2, orientation[:, 1]) + [points], axis=1)
    w = np.array(starts, dtype=np.float64)
    h = 1e-7
    perturbations = np.concatenate([np.zeros((1, 4)), np.eye(4) * h])[:, None, :]
    active = np.arange(len(t1))
    aimed_far = np.zeros(len(t1), dtype=bool)
    for iteration in range(NEWTON_ITERATIONS):
        rows = table[active]
        x = w[active]
        values = _residual(x[None] + perturbations, rows, eye)
        g = values[0]
        jacobian = np.moveaxis((values[1:] - g) / h, 0, 2)
        singular = ~(np.abs(np.linalg.det(jacobian)) > 1e-200)
        jacobian[singular] += np.eye(4) * 1e-9
        step = np.linalg.solve(jacobian, g[:, :, None])[:, :, 0]
        # A pair whose full Newton step lands far outside its triangles twice running has
        # its root, if any, in a neighbouring pair (which is a candidate too).
        aim = x - step
        aim_far = ((aim[:, :2].min(axis=1) < -ABANDON_AIM) | (aim[:, :2].sum(axis=1) > 1 + ABANDON_AIM)
                   | (aim[:, 2:].min(axis=1) < -ABANDON_AIM) | (aim[:, 2:].sum(axis=1) > 1 + ABANDON_AIM))
        # At most half a triangle per step in either triangle.
        length = np.maximum(lengths(step[:, :2]), lengths(step[:, 2:]))
        step *= np.minimum(1.0, 0.5 / np.maximum(length, 1e-300))[:, None]
        x = _backtrack(rows, eye, x, step, lengths(g))
        w[active] = x
        far = ((x[:, :2].min(axis=1) < -ABANDON_DISTANCE) | (x[:, :2].sum(axis=1) > 1 + ABANDON_DISTANCE)
               | (x[:, 2:].min(axis=1) < -ABANDON_DISTANCE) | (x[:, 2:].sum(axis=1) > 1 + ABANDON_DISTANCE))
        keep = (length > NEWTON_TOLERANCE) & ~(far & (iteration >= ABANDON_AFTER)) & ~(aim_far & aimed_far[active])
        aimed_far[active] = aim_far
        active = active[keep]
        if len(active) == 0:
            break
    converged = lengths(_residual(w, table, eye)) < CONVERGED_RESIDUAL
    return w, converged, orientation


def _backtrack(rows, eye, start, step, size, halvings: int = BACKTRACK_HALVINGS):
    """Steps halved until the residual shrinks (as ``exact._backtrack``); else the shortest."""
    scale = np.ones(len(start))
    pending = np.arange(len(start))
    for _ in range(halvings):
        trial = np.clip(start[pending] - scale[pending, None] * step[pending], -2.0, 3.0)
        worse = lengths(_residual(trial, rows[pending], eye)) >= size[pending]
        if not worse.any():
            break
        pending = pending[worse]
        scale[pending] *= 0.5
    return np.clip(start - scale[:, None] * step, -2.0, 3.0)


# --- visibility ------------------------------------------------------------------------------


def _with_visibility(reflector_set, view, points, found) -> SecondOrderReflections:
    t1, t2, uv = found["t1"], found["t2"], found["uv"]
    order = np.argsort(found["point"], kind="stable")
    point, t1, t2, uv, orientation = found["point"][order], t1[order], t2[order], uv[order], found["orientation"][order]
    x1 = _positions(reflector_set, t1, uv[:, :2])
    x2 = _positions(reflector_set, t2, uv[:, 2:])
    n1 = reflector_set.surface(t1, np.stack([1 - uv[:, 0] - uv[:, 1], uv[:, 0], uv[:, 1]], axis=1))[1]
    n2 = reflector_set.surface(t2, np.stack([1 - uv[:, 2] - uv[:, 3], uv[:, 2], uv[:, 3]], axis=1))[1]
    n1 *= orientation[:, :1]
    n2 *= orientation[:, 1:]
    pixel, _ = view.to_pixels(x1)
    in_view = view.in_view(x1)

    # Facet normals turned toward where each ray arrives from, as the tracer does.
    to_eye = normalized(view.eye - x1)
    face1 = reflector_set.face_normals[t1]
    face1 = face1 * np.sign(dot(face1, to_eye))[:, None]
    across = x2 - x1
    across_length = lengths(across)
    across /= np.maximum(across_length, 1e-300)[:, None]
    face2 = reflector_set.face_normals[t2]
    face2 = face2 * np.sign(dot(face2, -across))[:, None]
    to_point = points[point] - x2
    point_distance = lengths(to_point)
    to_point /= np.maximum(point_distance, 1e-300)[:, None]

    seen_by_eye = _first_hit_of_view_ray(reflector_set, view, x1, pixel) & (dot(n1, face1) > 0)
    sees_second = (~reflector_set.occluded(x1, across, across_length, t1) & (dot(across, face1) > 0)
                   & (dot(n2, face2) > 0))
    sees_point = ~reflector_set.occluded(x2, to_point, point_distance, t2) & (dot(to_point, face2) > 0)
    return SecondOrderReflections(
        point=point, history=np.stack([reflector_set.owner[t1], reflector_set.owner[t2]], axis=1),
        triangle=np.stack([t1, t2], axis=1), first=x1, second=x2, pixel=pixel, in_view=in_view,
        seen_by_eye=seen_by_eye, sees_second=sees_second, sees_point=sees_point)


def _empty() -> SecondOrderReflections:
    none = np.zeros(0, dtype=bool)
    return SecondOrderReflections(
        point=np.zeros(0, dtype=np.int64), history=np.zeros((0, 2), dtype=np.int64),
        triangle=np.zeros((0, 2), dtype=np.int64), first=np.zeros((0, 3)), second=np.zeros((0, 3)),
        pixel=np.zeros((0, 2)), in_view=none, seen_by_eye=none, sees_second=none, sees_point=none)
