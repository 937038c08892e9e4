# SPDX-License-Identifier: GPL-3.0-or-later
"""Pre-subdivision of diffuse meshes so that their reflected edges can bend (numpy only).

SBC paper (Popescu, Sacks, Mei 2006), section V-B: a reflected triangle is rasterised
with straight edges between its three projected vertices, while the true reflection of
a straight edge in a curved mirror is curved. The approximation is good only for small
triangles, so the scene triangles are subdivided once, as a preprocess, until their
edges are short.

"Short" is relative to what a mirror does to the edge: the bend of an edge's reflection
grows with the angle it subtends from the mirror, about its length over its distance to
the mirror. An edge's length limit is therefore ``fraction * max(radius, distance)``,
with ``radius`` the bounding radius of a reflector and ``distance`` from the edge's
midpoint to that reflector's centre, the smallest limit over all reflectors: a floor
tile under a mirror sphere is cut to a fraction of the sphere's radius, one ten radii
away to ten times that.

The refinement is *conforming* (no T-junctions, which would open pixel cracks in the
rasterised reflection): edges, not triangles, are marked, and every triangle is cut
by the pattern of its marked edges (one marked edge: two triangles; two: three; three:
four, the classic red-green refinement). Both triangles beside a marked edge use the
same midpoint vertex. Rounds repeat until no edge exceeds its limit; each round is a
handful of whole-array operations. Vertex colours are interpolated at midpoints.
"""

from __future__ import annotations

import numpy as np

#: Default length limit as a share of max(reflector radius, distance to the reflector).
EDGE_FRACTION = 0.1
#: Rounds of refinement at most (each halves the marked edges).
MAX_ROUNDS = 16
#: Refinement stops (with a ValueError) rather than produce more triangles than this.
MAX_TRIANGLES = 4_000_000

# For a triangle (a, b, c) with edges 0 = ab, 1 = bc, 2 = ca and midpoints m0, m1, m2
# (local slots 3, 4, 5), the new triangles of each canonical marking pattern, winding
# kept. Patterns are rotated to canonical form: one edge marked -> edge 0; two -> edges 0, 1.
_SPLIT_ONE = np.array([[0, 3, 2], [3, 1, 2]])
_SPLIT_TWO = np.array([[3, 1, 4], [0, 3, 4], [0, 4, 2]])
_SPLIT_THREE = np.array([[0, 3, 5], [3, 1, 4], [5, 4, 2], [3, 4, 5]])


def reflector_spheres(reflectors) -> tuple[np.ndarray, np.ndarray]:
    """Centre (R, 3) and bounding radius (R,) of each reflector (its bounding box centre)."""
    centres, radii = [], []
    for reflector in reflectors:
        lo, hi = reflector.vertices.min(axis=0), reflector.vertices.max(axis=0)
        centre = 0.5 * (lo + hi)
        centres.append(centre)
        radii.append(np.linalg.norm(reflector.vertices - centre, axis=1).max())
    return np.reshape(centres, (-1, 3)), np.asarray(radii, dtype=np.float64)


def edge_limits(midpoints: np.ndarray, centres: np.ndarray, radii: np.ndarray, fraction: float) -> np.ndarray:
    """Length limit of edges with these midpoints: fraction * max(radius, distance), min over reflectors."""
    if len(centres) == 0:
        return np.full(len(midpoints), np.inf)
    distance = np.linalg.norm(midpoints[:, None, :] - centres[None, :, :], axis=2)
    return fraction * np.maximum(radii[None, :], distance).min(axis=1)


def subdivide(vertices, triangles, colors, centres, radii, fraction: float = EDGE_FRACTION,
              max_rounds: int = MAX_ROUNDS):
    """Conforming refinement of a triangle mesh until every edge is within its limit.

    ``vertices`` (N, 3), ``triangles`` (M, 3) int, ``colors`` (N, C) interpolated at
    midpoints; ``centres``/``radii`` from :func:`reflector_spheres`. Returns the new
    ``(vertices, triangles, colors)``; the original vertices keep their indices.
    """
    if not fraction > 0:
        raise ValueError(f"fraction must be positive, got {fraction}")
    vertices = np.asarray(vertices, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    colors = np.asarray(colors, dtype=np.float32)
    centres = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    radii = np.asarray(radii, dtype=np.float64).reshape(-1)
    for _ in range(max_rounds):
        # Every triangle's three edges, then the unique undirected edges.
        corner_a = triangles
        corner_b = np.roll(triangles, -1, axis=1)
        low, high = np.minimum(corner_a, corner_b), np.maximum(corner_a, corner_b)
        key = (low * len(vertices) + high).reshape(-1)
        unique, inverse = np.unique(key, return_inverse=True)
        ends = np.stack([unique // len(vertices), unique % len(vertices)], axis=1)
        length = np.linalg.norm(vertices[ends[:, 0]] - vertices[ends[:, 1]], axis=1)
        middle = 0.5 * (vertices[ends[:, 0]] + vertices[ends[:, 1]])
        marked = length > edge_limits(middle, centres, radii, fraction)
        if not marked.any():
            break
        # New midpoint vertices, one per marked edge, shared by both of its triangles.
        midpoint_index = np.full(len(unique), -1, dtype=np.int64)
        midpoint_index[marked] = len(vertices) + np.arange(int(marked.sum()))
        vertices = np.concatenate([vertices, middle[marked]])
        colors = np.concatenate([colors, 0.5 * (colors[ends[marked, 0]] + colors[ends[marked, 1]])])
        triangle_mid = midpoint_index[inverse].reshape(-1, 3)  # (M, 3) midpoint of edge k, or -1
        triangles = _split(triangles, triangle_mid)
        if len(triangles) > MAX_TRIANGLES:
            raise ValueError(f"subdivision would exceed {MAX_TRIANGLES} triangles; raise the edge fraction")
    return vertices, triangles, colors


def _split(triangles: np.ndarray, mid: np.ndarray) -> np.ndarray:
    """Cut each triangle by the pattern of its marked edges (``mid`` >= 0)."""
    is_marked = mid >= 0
    count = is_marked.sum(axis=1)
    parts = [triangles[count == 0]]
    # Rotation r puts the marked edge first (one) or the unmarked edge last (two).
    for n, table in ((1, _SPLIT_ONE), (2, _SPLIT_TWO)):
        rows = np.flatnonzero(count == n)
        if len(rows) == 0:
            continue
        marks = is_marked[rows]
        rotation = np.argmax(marks, axis=1) if n == 1 else (np.argmin(marks, axis=1) + 1) % 3
        parts.append(_apply(triangles[rows], mid[rows], rotation, table))
    rows = np.flatnonzero(count == 3)
    if len(rows):
        parts.append(_apply(triangles[rows], mid[rows], np.zeros(len(rows), dtype=np.int64), _SPLIT_THREE))
    return np.concatenate(parts)


def _apply(triangles: np.ndarray, mid: np.ndarray, rotation: np.ndarray, table: np.ndarray) -> np.ndarray:
    """New triangles from ``table`` over the rotated corners and midpoints of each triangle."""
    order = (rotation[:, None] + np.arange(3)[None, :]) % 3
    corners = np.take_along_axis(triangles, order, axis=1)
    mids = np.take_along_axis(mid, order, axis=1)
    local = np.concatenate([corners, mids], axis=1)  # slots 0-2 corners, 3-5 midpoints
    return local[:, table].reshape(-1, 3)


def barycentric_grid(n: int) -> tuple[np.ndarray, np.ndarray]:
    """A triangle cut into n^2 sub-triangles by a regular grid (SBC V-B, mixed triangles).

    Returns the (n + 1)(n + 2) / 2 grid points as barycentric weights of corners 0 and 1,
    (K, 2) (corner 2's is one minus their sum), and the (n^2, 3) sub-triangles over them,
    wound as the triangle (0, 1, 2).
    """
    n = max(1, int(n))
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keep = (i + j) <= n
    i, j = i[keep], j[keep]  # i steps toward corner 1, j toward corner 2
    index = np.full((n + 1, n + 1), -1, dtype=np.int64)
    index[i, j] = np.arange(len(i))
    points = np.stack([(n - i - j) / n, i / n], axis=1)
    a, b = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    up = (a + b) <= n - 1
    a_up, b_up = a[up], b[up]
    upward = np.stack([index[a_up, b_up], index[a_up + 1, b_up], index[a_up, b_up + 1]], axis=1)
    down = (a + b) <= n - 2
    a_dn, b_dn = a[down], b[down]
    downward = np.stack([index[a_dn + 1, b_dn], index[a_dn + 1, b_dn + 1], index[a_dn, b_dn + 1]], axis=1)
    return points, np.concatenate([upward, downward])
