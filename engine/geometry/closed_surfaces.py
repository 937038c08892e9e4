# SPDX-License-Identifier: GPL-3.0-or-later
"""Closed, consistently wound diffuse meshes: the triangles a reflection never shows.

A watertight mesh whose triangles are all wound the same way bounds a solid. Seen from
any point outside it, every triangle that faces away from that point lies behind the
solid's near side, so a renderer may cull it; seen from inside, the opposite holds.
For a reflected mesh the point is the reflection point on the mirror: where every
mirror point lies outside the solid, the triangles facing away from the mirror are
hidden in every first-order image (``drawing/reflected_meshes.py`` culls them
by their winding on screen, which a mirror reverses).

Positions, not vertex indices, decide which triangles meet: captured meshes split
vertices at sharp edges and UV seams, and such a mesh is still closed.

The same holds for the mirror side: :func:`is_convex` says whether a closed mirror
bounds a convex body, whose every image is mirrored (the culling above is then valid
for it), and where the iterative search may skip its occlusion tests. Where the
reflection points are known per vertex (a sample-based camera's projection),
:func:`turned_away` culls without the winding on screen.
"""

from __future__ import annotations

import functools

import numpy as np

from .vectors import cross, dot, lengths

#: Directions of the inside test's rays: not along any axis or diagonal, so that a ray
#: through an edge or a vertex of a modelled (axis-aligned) mesh is unlikely, and three
#: of them vote.
PROBE_DIRECTIONS = np.array([(0.5773, 0.6123, 0.5401), (-0.6812, 0.2137, 0.7003), (0.1517, -0.8846, 0.4410)])
#: Points of each mirror tested against a solid (its vertices, evenly strided).
PROBES_PER_MIRROR = 16
#: Probes tested together (the test stops at the first batch with one inside).
PROBES_AT_ONCE = 8
#: Point-triangle pairs of the inside test held in memory at once.
PAIRS_PER_CHUNK = 1 << 20
#: Faces (and edges) whose convexity terms :func:`is_convex` computes at once.
CONVEXITY_BLOCK = 131072


def weld_labels(vertices: np.ndarray) -> np.ndarray | None:
    """(N,) for each vertex the lowest index of the vertices at its position (split
    vertices of a sharp edge or a UV seam share one), or None where no two vertices
    share a position. A lexicographic sort of the coordinates: ``np.unique(axis=0)``
    sorts the rows as records, and its inverse costs a (T, 3) copy of the triangles
    even where nothing is welded (a million-triangle ball: 24 MB)."""
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    order = np.lexsort((vertices[:, 2], vertices[:, 1], vertices[:, 0]))  # stable: lowest index first
    ordered = vertices[order]
    starts = np.ones(len(order), dtype=bool)
    starts[1:] = (ordered[1:] != ordered[:-1]).any(axis=1)
    del ordered
    if starts.all():
        return None
    first = np.flatnonzero(starts)
    labels = np.empty(len(order), dtype=np.int64)
    labels[order] = np.repeat(order[first], np.diff(np.append(first, len(order))))
    return labels


def welded_corners(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """``triangles`` (T, 3) over :func:`weld_labels` (vertices at one position as one):
    the same array where no two vertices share a position."""
    labels = weld_labels(vertices)
    return triangles if labels is None else labels[triangles]


def winding(vertices: np.ndarray, triangles: np.ndarray, welded: np.ndarray | None = None) -> int:
    """+1 where ``triangles`` close a solid and wind counter-clockwise seen from outside
    (normals outward, Blender's convention), -1 where they wind the other way (normals
    inward: a flipped mesh or a mirroring transform), 0 where they do not close a solid
    (an open edge, an edge of three or more faces, two neighbours wound against each
    other, no volume). ``welded``: the triangles over welded vertices
    (:func:`welded_corners`, any labels), where the caller has them."""
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if len(triangles) < 4:
        return 0
    vertices = np.asarray(vertices, dtype=np.float64)
    corners = welded_corners(vertices, triangles) if welded is None else np.asarray(welded).reshape(-1, 3)
    columns = [corners[:, k] for k in range(3)]
    if any(np.any(columns[k] == columns[(k + 1) % 3]) for k in range(3)):
        return 0
    n = int(corners.max()) + 1
    # Consistently wound and closed: each directed edge once, and its reverse once.
    forward = np.empty(3 * len(corners), dtype=np.int64)
    for k in range(3):
        part = forward[k * len(corners):(k + 1) * len(corners)]
        np.multiply(columns[k], n, out=part)
        part += columns[(k + 1) % 3]
    forward.sort()
    if np.any(forward[1:] == forward[:-1]):
        return 0
    # No directed edge twice, so every reverse found once means the same set of edges.
    for k in range(3):
        for start in range(0, len(corners), CONVEXITY_BLOCK):
            rows = slice(start, start + CONVEXITY_BLOCK)
            backward = columns[(k + 1) % 3][rows] * n + columns[k][rows]
            found = np.minimum(np.searchsorted(forward, backward), len(forward) - 1)
            if not np.array_equal(forward[found], backward):
                return 0
    del forward
    volume = 0.0
    for start in range(0, len(triangles), CONVEXITY_BLOCK):
        v = vertices[triangles[start:start + CONVEXITY_BLOCK]]
        volume += np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum()
    volume /= 6.0
    size = np.ptp(vertices, axis=0).max()
    if not abs(volume) > 1e-9 * size ** 3:
        return 0
    return 1 if volume > 0 else -1


def inside(vertices: np.ndarray, triangles: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(P,) bool: ``points`` inside the solid a closed mesh bounds, by the parity of the
    triangles each of three rays crosses (the majority of the three)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    v = np.asarray(vertices, dtype=np.float64)[np.asarray(triangles, dtype=np.int64).reshape(-1, 3)]
    v0, e1, e2 = v[:, 0], v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    votes = np.zeros(len(points), dtype=np.int64)
    chunk = max(1, PAIRS_PER_CHUNK // max(len(v), 1))
    for direction in PROBE_DIRECTIONS / np.linalg.norm(PROBE_DIRECTIONS, axis=1, keepdims=True):
        # Moller-Trumbore, each point against every triangle.
        p = np.cross(direction, e2)
        det = np.einsum("ij,ij->i", e1, p)
        usable = np.abs(det) > 1e-300
        inverse = np.where(usable, 1.0 / np.where(usable, det, 1.0), 0.0)
        for start in range(0, len(points), chunk):
            s = points[start:start + chunk, None, :] - v0[None]
            u = np.einsum("ptj,tj->pt", s, p) * inverse
            q = np.cross(s, e1[None])
            w = np.einsum("j,ptj->pt", direction, q) * inverse
            t = np.einsum("tj,ptj->pt", e2, q) * inverse
            crossed = usable & (u >= 0.0) & (w >= 0.0) & (u + w <= 1.0) & (t > 0.0)
            votes[start:start + chunk] += crossed.sum(axis=1) % 2
    return votes >= 2


def cullable_winding(vertices: np.ndarray, triangles: np.ndarray, mirrors) -> int:
    """:func:`winding` of a diffuse mesh where no point of any mirror (each an (N, 3)
    array of its vertices, PROBES_PER_MIRROR of them and the centre tested) lies inside
    the solid it bounds, else 0: seen from inside, the far side of a solid is what shows
    (a mirror ball in a closed room). A mirror only partly inside is seen, from an eye
    outside the solid, only where it is outside, so testing a sample errs only toward
    not culling."""
    sense = winding(vertices, triangles)
    if sense == 0:
        return 0
    vertices = np.asarray(vertices, dtype=np.float64)
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    for mirror in mirrors:
        mirror = np.asarray(mirror, dtype=np.float64).reshape(-1, 3)
        if len(mirror) == 0 or np.any(mirror.max(axis=0) < lo) or np.any(mirror.min(axis=0) > hi):
            continue
        stride = max(1, len(mirror) // PROBES_PER_MIRROR)
        probes = np.concatenate([mirror.mean(axis=0, keepdims=True), mirror[::stride]])
        probes = probes[np.all((probes >= lo) & (probes <= hi), axis=1)]
        # The centre alone first (a mirror inside a room is found at once), then a few
        # at a time.
        batches = [probes[:1]] + [probes[k:k + PROBES_AT_ONCE] for k in range(1, len(probes), PROBES_AT_ONCE)]
        if any(len(batch) and inside(vertices, triangles, batch).any() for batch in batches):
            return 0
    return sense


def is_convex(vertices: np.ndarray, triangles: np.ndarray, centre, tolerance: float = 1e-7) -> bool:
    """Whether a star-shaped mesh around ``centre`` bounds a convex body: it is closed
    (every edge of its welded vertices shared by two faces), folds outward at every edge
    (faces oriented away from the centre: each face's neighbour across an edge lies on
    or behind its plane) and has no saddle vertex (angles around each vertex sum to at
    most 2 pi). A closed surface that is locally convex everywhere is convex (Tietze's
    theorem), so this costs O(faces) where comparing every vertex with every face plane
    cost O(vertices x faces). An open or degenerate mesh counts as not convex (only a
    cost: the search then runs its occlusion tests)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64)
    welded = welded_corners(vertices, triangles)
    # One integer per edge, sorted: rows as records cost seconds and a gigabyte on a
    # million-triangle mirror, and a 1-D unique with its inverse and counts 200 MB.
    n = int(welded.max()) + 1
    keys = np.empty(welded.shape, dtype=np.int64)
    for k in range(3):
        a, b = welded[:, k], welded[:, (k + 1) % 3]
        np.multiply(np.minimum(a, b), n, out=keys[:, k])
        keys[:, k] += np.maximum(a, b)
    keys = keys.reshape(-1)
    order = np.argsort(keys, kind="stable")  # the two sides of each edge, side by side
    if len(order) % 2:
        return False
    # Every edge of two faces: keys come in equal pairs, each pair unlike the next
    # (looked at a block of pairs at a time, each with the next pair's first key).
    for block in range(0, len(order), 2 * CONVEXITY_BLOCK):
        ordered = keys[order[block:block + 2 * CONVEXITY_BLOCK + 1]]
        if not (np.array_equal(ordered[0:-1:2] if len(ordered) % 2 else ordered[0::2], ordered[1::2])
                and np.all(ordered[1:-1:2] != ordered[2::2])):
            return False
    del keys, ordered
    order = order.reshape(-1, 2)
    scale = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))
    total = np.zeros(int(welded.max()) + 1)
    centre = np.asarray(centre, dtype=np.float64)
    # In blocks of faces and of edges: a million-triangle mirror's temporaries stay small.
    for block in range(0, len(triangles), CONVEXITY_BLOCK):
        a, b, c = (vertices[triangles[block:block + CONVEXITY_BLOCK, k]] for k in range(3))
        angles = np.stack([_angle(b - a, c - a), _angle(c - b, a - b), _angle(a - c, b - c)], axis=1)
        total += np.bincount(welded[block:block + CONVEXITY_BLOCK].reshape(-1), angles.reshape(-1),
                             minlength=len(total))
    for block in range(0, len(order), CONVEXITY_BLOCK):
        sides = order[block:block + CONVEXITY_BLOCK]
        face, opposite = sides // 3, triangles[sides // 3, (sides % 3 + 2) % 3]
        for k in range(2):
            a, b, c = (vertices[triangles[face[:, k], j]] for j in range(3))
            normal = cross(b - a, c - a)
            with np.errstate(invalid="ignore", divide="ignore"):  # a degenerate face: NaN, not convex
                normal *= np.sign(dot(normal, a - centre))[:, None] / lengths(normal)[:, None]
            if not np.all(dot(normal, vertices[opposite[:, 1 - k]] - a) <= tolerance * scale):
                return False
    return bool(np.all(total <= 2.0 * np.pi + 1e-6))


def bounds_convex_body(mesh) -> bool:
    """:func:`is_convex` of a mirror ``mesh`` (``vertices``, ``triangles``) about the mean
    of its vertices: every image it shows is mirrored, as in a flat mirror, and the far
    sides of closed solids can be culled from its reflections."""
    return is_convex(mesh.vertices, mesh.triangles, np.asarray(mesh.vertices, dtype=np.float64).mean(axis=0))


class ConvexMirrors:
    """Which of a scene's mirrors (each with ``vertices`` and ``triangles``) bound a convex
    body (:func:`bounds_convex_body`): tested on first use, once for every pass that asks
    (a renderer's camera projections and its morphing pass share one; the test is O(faces),
    seconds for a million-triangle mirror)."""

    def __init__(self, mirrors=()):
        self._mirrors = list(mirrors)

    @functools.cached_property
    def indices(self) -> frozenset:
        """Indices of the mirrors that bound a convex body."""
        return frozenset(index for index, mirror in enumerate(self._mirrors) if bounds_convex_body(mirror))

    @property
    def higher_orders(self) -> bool:
        """Whether a path can meet a mirror after a mirror: there is more than one, or the
        one bounds no convex body (it may see itself). One convex mirror never does."""
        return len(self._mirrors) != 1 or 0 not in self.indices


def turned_away(vertices: np.ndarray, corners: np.ndarray, winding: np.ndarray, eyes: np.ndarray,
                known: np.ndarray) -> np.ndarray:
    """(n,) bool: which triangles (``corners``, (n, 3) indices into ``vertices``; their
    solid's ``winding``, (n,), 0 where they bound none) turn their back, at every
    ``known`` corner ((n, 3) bool; at least one), to the point each such corner is seen
    from (``eyes``, (n, 3, 3): from the corner to that point, e.g. its reflection point
    on a mirror). Seen from outside the solid, such a triangle is behind its near side."""
    winding = np.asarray(winding)
    away = np.zeros(len(corners), bool)
    closed = np.flatnonzero(winding != 0)
    if len(closed) == 0:
        return away
    v = np.asarray(vertices, dtype=np.float64)[corners[closed]]
    outward = cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]) * winding[closed, None]
    behind = np.einsum("nj,nkj->nk", outward, eyes[closed]) < 0.0
    away[closed] = (behind | ~known[closed]).all(axis=1) & known[closed].any(axis=1)
    return away


def _angle(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.arctan2(lengths(cross(u, v)), dot(u, v))


def reflects_outside(mirror, triangles: np.ndarray, roots: np.ndarray, normals: np.ndarray, eye: np.ndarray,
                     points: np.ndarray) -> np.ndarray:
    """(R,) bool: a root of the law of reflection (on ``mirror``'s ``triangles``, with
    its interpolated normal) is a reflection: the eye (a point toward it) and the point
    lie on one side of the surface there, and on the outer side of the root's triangle
    where its mirror closes a solid (``ReflectorSet.closed_sides``; any side where it
    closes none). At a silhouette the half vector can meet the interpolated normal with
    the eye just behind the surface (a grazing ray, no image); a root on a closed
    mirror's far side satisfies the law for the surface seen from inside, a path that
    runs through the mirror (an image past a node's horizon, Newton carried round the rim)."""
    one_side = dot(normals, eye - roots) * dot(normals, points - roots) > 0
    sides = mirror.closed_sides[triangles]
    face = mirror.face_normals[triangles]
    outside = (sides == 0) | ((sides * dot(face, eye - roots) > 0) & (sides * dot(face, points - roots) > 0))
    return one_side & outside
