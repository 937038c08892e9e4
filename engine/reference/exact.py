# SPDX-License-Identifier: GPL-3.0-or-later
"""The exact reference solver: every first-order reflection of a point, and its visibility.

A point p appears reflected at the reflector point x when the surface normal at x
bisects the directions from x to the eye and from x to p (law of reflection). On our
surface model (flat triangles, interpolated normals) that is two equations in the two
barycentric unknowns of a triangle:

    normalize(d_eye(x) + d_p(x)) = n(x),    x = v0 + u e1 + v e2,

solved by Newton's method to machine precision in every triangle that may hold a
solution. Candidate triangles come from a conservative BVH descent: for a node with
bounding sphere (c, rho) and a cone bounding its normals, the half vector at any x in
the sphere lies within asin(delta / |s|) of the half vector at c, where s is the sum of
the unit directions at c and delta bounds how far they can turn (chord 2 sin(a / 2)
with a = asin(rho / distance)); a node is kept only if that cone of half vectors meets
the normal cone (or its opposite: mirrors are two-sided). No solution is lost to
culling; several per point are found where the surface is not convex (the Chen-Arvo
vase shows two images of one point).

A solution is *visible* when it lies in the view frustum, nothing (no reflector,
itself included) lies between it and the eye, and nothing lies between it and p.
This is the yard stick every method's pixel error is measured against.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry.bvh import descend
from ..geometry.raytrace import ReflectorSet
from ..geometry.vectors import cross, dot, lengths, normalized
from ..view import View

NEWTON_ITERATIONS = 24
NEWTON_TOLERANCE = 1e-12
#: Step halvings tried per Newton iteration before a step is taken anyway.
BACKTRACK_HALVINGS = 6
#: Newton gives up on a pair this far outside its triangle (barycentric units) ...
ABANDON_DISTANCE = 0.5
#: ... after this many iterations.
ABANDON_AFTER = 4
#: Barycentric slack for accepting a root on a triangle's edge (duplicates are merged).
INSIDE_TOLERANCE = 1e-9
#: Extra angle (radians) added to the culling cones against rounding.
CONE_SLACK = 1e-6
POINT_CHUNK = 4096


@dataclass(frozen=True)
class Reflections:
    """All reflections found; one row per (point, reflection) solution, sorted by point."""

    point: np.ndarray  # (S,) index of the reflected point
    reflector: np.ndarray  # (S,) reflector index
    triangle: np.ndarray  # (S,) triangle index in the ReflectorSet
    barycentric: np.ndarray  # (S, 3)
    position: np.ndarray  # (S, 3) reflector point x
    normal: np.ndarray  # (S, 3) interpolated normal at x, facing the eye
    pixel: np.ndarray  # (S, 2) where x appears in the view
    in_view: np.ndarray  # (S,) bool, x inside the view frustum
    seen_by_eye: np.ndarray  # (S,) bool, nothing between x and the eye
    sees_point: np.ndarray  # (S,) bool, nothing between x and the point

    @property
    def visible(self) -> np.ndarray:
        return self.in_view & self.seen_by_eye & self.sees_point

    def select(self, mask: np.ndarray) -> "Reflections":
        return Reflections(*(getattr(self, f)[mask] for f in self.__dataclass_fields__))

    def count_per_point(self, n_points: int, reflector: int | None = None) -> np.ndarray:
        """(P,) number of visible reflections of each point (on one reflector if given)."""
        mask = self.visible if reflector is None else self.visible & (self.reflector == reflector)
        return np.bincount(self.point[mask], minlength=n_points)


def convex_candidates(mirrors, eye, points) -> np.ndarray:
    """Indices of ``points`` that may have a visible reflection in one of the convex
    ``mirrors`` (a ``ReflectorSet`` each) seen from ``eye``: those whose segment from the
    eye misses at least one of them. A visible reflection has the eye and the point in
    front of its facet's plane (the view ray's first hit, the reflected ray leaving the
    facet), so a convex mirror the segment meets shows none of the point; the solver
    spends most of its time proving that of the others, so callers solve only these."""
    eye, points = np.asarray(eye, dtype=np.float64), np.asarray(points, dtype=np.float64)
    offset = points - eye
    distance = np.linalg.norm(offset, axis=1)
    blocked = np.ones(len(points), dtype=bool)
    for mirror in mirrors:
        hits = mirror.intersect(np.broadcast_to(eye, points.shape), offset / distance[:, None])
        blocked &= hits.hit & (hits.t < distance)
    return np.flatnonzero(~blocked)


def solve_reflections(reflector_set: ReflectorSet, view: View, points: np.ndarray) -> Reflections:
    """Every first-order reflection of every point on every reflector, with visibility."""
    points = np.asarray(points, dtype=np.float64)
    parts = [_solve_chunk(reflector_set, view, points[start:start + POINT_CHUNK], start)
             for start in range(0, len(points), POINT_CHUNK)]
    found = {key: np.concatenate([part[key] for part in parts]) for key in parts[0]} if parts else None
    if found is None or len(found["point"]) == 0:
        return _empty_reflections()
    return _with_visibility(reflector_set, view, points, found)


def _solve_chunk(reflector_set, view, points, offset) -> dict:
    candidates_point, candidates_triangle = _candidates(reflector_set, view, points)
    # Two starts per candidate: the centroid, and the point's foot on the triangle. For a
    # point close to the mirror the direction to it swings fast across the triangle and
    # Newton from the centroid can fail; the reflection then lies near the foot.
    starts = np.concatenate([np.full((len(candidates_triangle), 2), 1.0 / 3.0),
                             _foot(reflector_set, points[candidates_point], candidates_triangle)])
    candidates_point = np.concatenate([candidates_point, candidates_point])
    candidates_triangle = np.concatenate([candidates_triangle, candidates_triangle])
    uv, converged, orientation = newton_in_triangles(reflector_set, view, points[candidates_point], candidates_triangle,
                                                     starts)
    u, v = uv[:, 0], uv[:, 1]
    inside = converged & (u >= -INSIDE_TOLERANCE) & (v >= -INSIDE_TOLERANCE) & (u + v <= 1 + INSIDE_TOLERANCE)
    point, triangle, u, v = candidates_point[inside], candidates_triangle[inside], u[inside], v[inside]
    barycentric = np.stack([1 - u - v, u, v], axis=1)
    position, normal = reflector_set.surface(triangle, barycentric)
    normal *= orientation[inside][:, None]
    keep = first_of_duplicates((point, reflector_set.owner[triangle]), (position,), reflector_set.scale)
    return {"point": point[keep] + offset, "triangle": triangle[keep], "barycentric": barycentric[keep],
            "position": position[keep], "normal": normal[keep]}


def _foot(reflector_set: ReflectorSet, points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Barycentric (u, v) of each point's orthogonal projection on its triangle's plane,
    pulled inside the triangle."""
    e1, e2 = reflector_set.e1[triangles], reflector_set.e2[triangles]
    w = points - reflector_set.v0[triangles]
    d11, d12, d22 = dot(e1, e1), dot(e1, e2), dot(e2, e2)
    b1, b2 = dot(w, e1), dot(w, e2)
    det = np.maximum(d11 * d22 - d12 * d12, 1e-300)
    u = np.clip((d22 * b1 - d12 * b2) / det, 0.0, 1.0)
    v = np.clip((d11 * b2 - d12 * b1) / det, 0.0, 1.0)
    total = np.maximum(u + v, 1.0)
    return np.stack([u / total, v / total], axis=1)


def _candidates(reflector_set: ReflectorSet, view: View, points: np.ndarray):
    """(point, triangle) pairs that may hold a reflection: BVH nodes, then triangles, culled."""
    bvh = reflector_set.bvh
    boxes = [(np.where(lo <= hi, lo, 0.0), np.where(lo <= hi, hi, 0.0)) for lo, hi in zip(bvh.box_lo, bvh.box_hi)]
    centres = [0.5 * (lo + hi) for lo, hi in boxes]
    radii = [0.5 * lengths(hi - lo) for lo, hi in boxes]

    def node_test(queries, level, nodes):
        lo, hi = bvh.box_lo[level][nodes], bvh.box_hi[level][nodes]
        return (lo[:, 0] <= hi[:, 0]) & _may_reflect(
            view, points[queries], centres[level][nodes], radii[level][nodes],
            bvh.cone_axis[level][nodes], bvh.cone_cos[level][nodes])

    point, triangle = descend(bvh, np.arange(len(points)), node_test)
    corners = reflector_set.vertices[reflector_set.triangles[triangle]]
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    normals = reflector_set.normals[reflector_set.triangles[triangle]]
    axis = normals.sum(axis=1)
    axis = normalized(axis)
    cos = np.einsum("tkd,td->tk", normals, axis).min(axis=1)
    keep = _may_reflect(view, points[point], 0.5 * (lo + hi), 0.5 * lengths(hi - lo), axis, cos)
    return point[keep], triangle[keep]


def _may_reflect(view, points, centres, radii, cone_axis, cone_cos) -> np.ndarray:
    """Conservative test: some x within ``radii`` of ``centres`` may reflect the point."""
    to_eye = view.directions_to_eye(centres)
    if view.is_perspective:
        eye_turn = turn_toward(radii, lengths(view.eye - centres))
    else:
        eye_turn = np.zeros(len(centres))
    to_point = points - centres
    point_distance = lengths(to_point)
    to_point /= np.maximum(point_distance, 1e-300)[:, None]
    return half_vector_may_meet_cone(to_eye, eye_turn, to_point, turn_toward(radii, point_distance),
                                     cone_axis, cone_cos)


def turn_toward(radius, distance):
    """Largest angle the direction toward a sphere of ``radius`` at ``distance`` can turn
    (pi when the sphere holds the viewer)."""
    return np.where(distance > radius, np.arcsin(np.clip(radius / np.maximum(distance, 1e-300), 0.0, 1.0)), np.pi)


def half_vector_may_meet_cone(to_a, turn_a, to_b, turn_b, cone_axis, cone_cos) -> np.ndarray:
    """Conservative: a normal in the cone (axis, cos of half-angle) may bisect some unit
    directions within ``turn_a`` of ``to_a`` and ``turn_b`` of ``to_b``.

    The half vector of directions turned by at most a and b lies within
    asin((2 sin(a/2) + 2 sin(b/2)) / |to_a + to_b|) of their sum.
    """
    half = to_a + to_b
    half_length = lengths(half)
    chord = 2 * np.sin(turn_a / 2) + 2 * np.sin(turn_b / 2)
    bounded = chord < half_length
    half_turn = np.arcsin(np.clip(chord / np.maximum(half_length, 1e-300), 0.0, 1.0))
    spread = np.arccos(np.clip(cone_cos, -1.0, 1.0)) + half_turn + CONE_SLACK
    alignment = np.abs(dot(half, cone_axis)) / np.maximum(half_length, 1e-300)
    return ~bounded | (spread >= np.pi / 2) | (alignment >= np.cos(np.minimum(spread, np.pi / 2)))


def newton_in_triangles(reflector_set: ReflectorSet, view: View, points: np.ndarray, triangles: np.ndarray,
                        starts: np.ndarray, iterations: int = NEWTON_ITERATIONS):
    """Newton's method on the reflection law in each triangle's barycentric (u, v).

    The residual is the difference between the half vector and the normal (turned
    toward the eye), expressed in two axes of the triangle's plane; its Jacobian is
    analytic (:class:`_ReflectionLaw`). Steps are limited to half a triangle.
    """
    law = _ReflectionLaw(reflector_set, view, points, triangles)
    uv = np.array(starts, dtype=np.float64)
    # Pairs leave the active set once converged, or once Newton has carried them well
    # outside their triangle (their root, if any, belongs to a neighbour).
    active = np.arange(len(triangles))
    for iteration in range(iterations):
        a = uv[active]
        g, jacobian = law.residual(a, active, with_jacobian=True)
        det = jacobian[:, 0, 0] * jacobian[:, 1, 1] - jacobian[:, 0, 1] * jacobian[:, 1, 0]
        safe = np.where(np.abs(det) > 1e-300, det, 1e-300)
        step = np.stack([jacobian[:, 1, 1] * g[:, 0] - jacobian[:, 0, 1] * g[:, 1],
                         -jacobian[:, 1, 0] * g[:, 0] + jacobian[:, 0, 0] * g[:, 1]], axis=1) / safe[:, None]
        length = lengths(step)
        step *= np.minimum(1.0, 0.5 / np.maximum(length, 1e-300))[:, None]
        a = _backtrack(law.residual, active, a, step, lengths(g))
        uv[active] = a
        far_outside = (a.min(axis=1) < -ABANDON_DISTANCE) | (a.sum(axis=1) > 1 + ABANDON_DISTANCE)
        keep = (length > NEWTON_TOLERANCE) & ~(far_outside & (iteration >= ABANDON_AFTER))
        active = active[keep]
        if len(active) == 0:
            break
    converged = lengths(law.residual(uv, np.arange(len(triangles)))) < 1e-9
    return uv, converged, law.orientation


class _ReflectionLaw:
    """The reflection law's residual at barycentric (u, v) of (point, triangle) pairs, and
    its exact Jacobian.

    With x = v0 + u e1 + v e2, the unit directions d_e (to the eye) and d_p (to the
    point), h = unit(d_e + d_p) and n = unit(n0 + u (n1 - n0) + v (n2 - n0)) turned
    toward the eye, the residual is (h - n) in the triangle's axes. Each derivative is
    the chain rule through a normalisation, d unit(w) = (dw - w^ (w^ . dw)) / |w|:
    d d_e = -(e1 - d_e (d_e . e1)) / |e - x| (zero for an orthographic view), likewise
    d_p, and dn along n1 - n0. One evaluation costs about two residuals, where central
    differences cost four more.
    """

    def __init__(self, reflector_set: ReflectorSet, view: View, points: np.ndarray, triangles: np.ndarray):
        corners = reflector_set.triangles[triangles]
        self.view, self.points = view, points
        self.v0, self.e1, self.e2 = (reflector_set.v0[triangles], reflector_set.e1[triangles],
                                     reflector_set.e2[triangles])
        self.n0 = reflector_set.normals[corners[:, 0]]
        self.dn1 = reflector_set.normals[corners[:, 1]] - self.n0
        self.dn2 = reflector_set.normals[corners[:, 2]] - self.n0
        face = reflector_set.face_normals[triangles]
        self.axis_u = normalized(self.e1)
        self.axis_v = cross(face, self.axis_u)
        centroid = self.v0 + (self.e1 + self.e2) / 3
        self.orientation = np.where(dot(view.directions_to_eye(centroid), face) >= 0, 1.0, -1.0)

    def residual(self, uv: np.ndarray, k: np.ndarray, with_jacobian: bool = False):
        """(K, 2) residual of the pairs ``k`` at their ``uv``; with its (K, 2, 2) Jacobian
        (rows: residual axis, columns: u, v) if asked."""
        u, v = uv[:, :1], uv[:, 1:]
        e1, e2, dn1, dn2 = self.e1[k], self.e2[k], self.dn1[k], self.dn2[k]
        x = self.v0[k] + u * e1 + v * e2
        n_raw = self.n0[k] + u * dn1 + v * dn2
        n_length = lengths(n_raw)[:, None]
        n = n_raw / n_length * self.orientation[k, None]
        to_point = self.points[k] - x
        point_distance = lengths(to_point)[:, None]
        # A point on the mirror (an object touching it at a vertex) has no direction from
        # x: NaN, which no Newton step reduces, so the pair never converges.
        with np.errstate(invalid="ignore", divide="ignore"):
            d_p = to_point / point_distance
        d_e = self.view.directions_to_eye(x)
        s = d_e + d_p
        s_length = lengths(s)[:, None]
        h = s / s_length
        r = h - n
        axis_u, axis_v = self.axis_u[k], self.axis_v[k]
        g = np.stack([dot(r, axis_u), dot(r, axis_v)], axis=1)
        if not with_jacobian:
            return g
        eye_distance = lengths(self.view.eye - x)[:, None] if self.view.is_perspective else None
        jacobian = np.empty((len(k), 2, 2))
        for column, (dx, dn) in enumerate(((e1, dn1), (e2, dn2))):
            with np.errstate(invalid="ignore", divide="ignore"):
                ds = -_across(d_p, dx) / point_distance
            if eye_distance is not None:
                ds -= _across(d_e, dx) / eye_distance
            dr = _across(h, ds) / s_length - _across(n, dn) / n_length * self.orientation[k, None]
            jacobian[:, 0, column] = dot(dr, axis_u)
            jacobian[:, 1, column] = dot(dr, axis_v)
        return g, jacobian


def _across(unit_rows: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The part of each row of ``w`` perpendicular to the unit row of ``unit_rows``."""
    return w - unit_rows * dot(unit_rows, w)[:, None]


def _backtrack(residual, active, start, step, size, halvings: int = BACKTRACK_HALVINGS):
    """Newton steps shortened by halving until the residual shrinks (backtracking line search).

    Near a mirror the direction to the point swings fast across a triangle and full
    steps overshoot; a pair whose residual never shrinks keeps the shortest step.
    """
    scale = np.ones(len(active))
    pending = np.arange(len(active))
    for _ in range(halvings):
        trial = np.clip(start[pending] - scale[pending, None] * step[pending], -2.0, 3.0)
        worse = lengths(residual(trial, active[pending])) >= size[pending]
        if not worse.any():
            break
        pending = pending[worse]
        scale[pending] *= 0.5
    return np.clip(start - scale[:, None] * step, -2.0, 3.0)


def first_of_duplicates(keys: tuple, positions: tuple, scale: float) -> np.ndarray:
    """Mask keeping one of the solutions that several triangles share along an edge.

    Solutions are duplicates when every integer array of ``keys`` (the point, the
    reflector or reflectors of the path) is equal and every (S, 3) array of
    ``positions`` (the reflection points) agrees to 1e-7 * ``scale``. Sorted by the
    keys, then by the first position's x, duplicates are adjacent unless another
    solution's first position falls between, which only happens at 1e-7 * scale.
    """
    n = len(keys[0])
    if n == 0:
        return np.zeros(0, dtype=bool)
    order = np.lexsort((positions[0][:, 0],) + tuple(reversed(keys)))
    same = np.ones(n - 1, dtype=bool)
    for key in keys:
        k = key[order]
        same &= k[1:] == k[:-1]
    for position in positions:
        x = position[order]
        same &= lengths(x[1:] - x[:-1]) < 1e-7 * scale
    keep_sorted = np.concatenate([[True], ~same])
    keep = np.zeros(n, dtype=bool)
    keep[order[keep_sorted]] = True
    return keep


def _with_visibility(reflector_set, view, points, found) -> Reflections:
    position, normal, triangle = found["position"], found["normal"], found["triangle"]
    pixel, _ = view.to_pixels(position)
    in_view = view.in_view(position)

    seen_by_eye = _first_hit_of_view_ray(reflector_set, view, position, pixel)
    to_eye = view.directions_to_eye(position)

    to_point = points[found["point"]] - position
    point_distance = lengths(to_point)
    to_point /= np.maximum(point_distance, 1e-300)[:, None]
    sees_point = ~reflector_set.occluded(position, to_point, point_distance, triangle)
    # The ray from the eye must hit the front of its facet, and the reflected ray leave it.
    face = reflector_set.face_normals[triangle] * np.sign(
        dot(reflector_set.face_normals[triangle], to_eye))[:, None]
    leaves_face = dot(to_point, face) > 0
    faces_eye = dot(normal, face) > 0
    return Reflections(
        point=found["point"], reflector=reflector_set.owner[triangle], triangle=triangle,
        barycentric=found["barycentric"], position=position, normal=normal, pixel=pixel,
        in_view=in_view, seen_by_eye=seen_by_eye & faces_eye, sees_point=sees_point & leaves_face,
    )


def _first_hit_of_view_ray(reflector_set, view, position, pixel) -> np.ndarray:
    """(S,) bool: the view ray through x's pixel hits the reflectors first at x.

    Tested from the eye side, like the ray map, rather than from x toward the eye: near
    a silhouette the occluder of a back-facing x is x's own neighbour.
    """
    origins, directions = view.pixel_rays(np.nan_to_num(pixel))
    expected = dot(position - origins, directions)
    hits = reflector_set.intersect(origins, directions, expected * (1 + 1e-6) + 1e-9 * reflector_set.scale)
    return hits.hit & (np.abs(hits.t - expected) <= 1e-7 * reflector_set.scale + 1e-9 * np.abs(expected))


def _empty_reflections() -> Reflections:
    empty = np.zeros(0)
    return Reflections(
        point=np.zeros(0, dtype=np.int64), reflector=np.zeros(0, dtype=np.int64),
        triangle=np.zeros(0, dtype=np.int64), barycentric=np.zeros((0, 3)), position=np.zeros((0, 3)),
        normal=np.zeros((0, 3)), pixel=np.zeros((0, 2)), in_view=empty.astype(bool),
        seen_by_eye=empty.astype(bool), sees_point=empty.astype(bool),
    )

