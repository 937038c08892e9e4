# SPDX-License-Identifier: GPL-3.0-or-later
"""Images the perturbation series cannot reach, found by Newton's method on the mesh.

On a mirror that bends both ways, a point's images crowd toward the folds of its
reflection, and the Taylor step from a candidate seed (Chen & Arvo 2000, section III)
does not converge there: its step is not local (the candidate is dropped, ``projector``
step 4) or its estimate stays above the accuracy after the adaptive seeds (refused).
Most images perturbation misses on such a mirror (a bumpy sphere, a rippled ellipsoid)
have such a candidate, often far from any answer of the point.

Each such candidate starts the exact solver's Newton iteration on the law of reflection
(``reference.exact.newton_in_triangles``: flat triangles, interpolated normals, the
surface model every method is measured against) in the triangle its seed's ray meets,
at the seed's point. A root outside that triangle moves the start across the edge it
left by, to the neighbour's centroid, up to WALK_TRIANGLES triangles: no ray is traced
and no BVH descended. A root found is an exact reflection of the point; whether the eye
and the point see it is the caller's check (``PerturbationMethod._polished``).
"""

from __future__ import annotations

import numpy as np

from ...geometry.closed_surfaces import reflects_outside
from ...geometry.raytrace import ReflectorSet
from ...reference.exact import INSIDE_TOLERANCE, newton_in_triangles
from ...view import View

#: Triangles a start walks through (its seed's, then across the edge its root lies
#: beyond). Next to the silhouette a pixel spans several foreshortened triangles, and a
#: seed a pixel from a missed image can be 5 or more triangles from it; more triangles
#: find few more images for much more time.
WALK_TRIANGLES = 6
#: Newton iterations per triangle (the exact solver's from a centroid take 24; a root
#: beyond the triangle is left after 4, ``reference.exact.ABANDON_AFTER``).
NEWTON_STEPS = 8


def walk_to_roots(reflector_set: ReflectorSet, view: View, points: np.ndarray, point_of: np.ndarray,
                  triangles: np.ndarray, barycentric: np.ndarray) -> np.ndarray:
    """(K, 3) the reflection point of ``points[point_of]`` (P, 3; K indices) found from
    each start (its triangle (K,) and barycentric (u, v) (K, 2) there), NaN where none
    is found within WALK_TRIANGLES triangles, or where the root lies on the far side of
    the surface for the eye or the point. Starts of one point in one triangle are solved
    once."""
    roots = np.full((len(point_of), 3), np.nan)
    if len(point_of) == 0:
        return roots
    _, first, same = np.unique(np.asarray(point_of, np.int64) * len(reflector_set.triangles) + triangles,
                               return_index=True, return_inverse=True)
    triangle, uv = np.array(triangles[first]), np.array(barycentric[first], dtype=np.float64)
    targets = points[point_of[first]]
    found = np.full((len(first), 3), np.nan)
    active = np.arange(len(first))
    for _ in range(WALK_TRIANGLES):
        solved, converged, _ = newton_in_triangles(reflector_set, view, targets[active], triangle[active], uv[active],
                                                   iterations=NEWTON_STEPS)
        weights = np.column_stack([1.0 - solved.sum(axis=1), solved])
        inside = converged & (weights.min(axis=1) >= -INSIDE_TOLERANCE)
        at = active[inside]
        clamped = np.clip(weights[inside], 0.0, None)
        root, normal = reflector_set.surface(triangle[at], clamped / clamped.sum(axis=1, keepdims=True))
        front = reflects_outside(reflector_set, triangle[at], root, normal, root + view.directions_to_eye(root),
                                 targets[at])
        found[at[front]] = root[front]
        leaving = np.flatnonzero(~inside)
        across = reflector_set.edge_neighbours[triangle[active[leaving]], np.argmin(weights[leaving], axis=1)]
        active = active[leaving[across >= 0]]
        triangle[active], uv[active] = across[across >= 0], 1.0 / 3.0
        if len(active) == 0:
            break
    roots[:] = found[same.reshape(-1)]
    return roots
