# SPDX-License-Identifier: GPL-3.0-or-later
"""A star-shaped reflector as a cube map of its radius and normal around a centre O.

Roger & Holzschuch (2006), section 3.3.1: a reflector seen whole from one point O is a
scalar function r(d) of the direction d from O, P(d) = O + r(d) d, stored once in a
texture so that one fetch gives the surface at any direction. The paper used spherical
coordinates and, in section 3.3.7, names the cube map as the better choice (no poles,
no trigonometry: the face and its coordinates come from the direction's largest
component); we use the cube map.

Our surface model (docs/overview.md, Conventions) has flat triangles with interpolated normals, so each texel
stores r and the *interpolated* normal where the ray from O along the texel's direction
meets the mesh, rather than the gradient of r: the reflection law is then solved with
the same normals as the exact reference solver (``engine/reference/exact.py``). Values between
texel centres are bilinear (four fetches, not the hardware filter, so the GLSL twin and
numpy agree exactly). Each face is one texel wider on every side than its [-1, 1]
square (texels taken along directions just past the face's edge), so a bilinear lookup
never needs a second face.

Layout (shared with ``drawing/glsl/cube_map.glsl``): face f = 2 a + s for
the major axis a (0 x, 1 y, 2 z) and s = 1 where that component is negative; on it
u = d[(a + 1) % 3] / |d[a]|, v = d[(a + 2) % 3] / |d[a]|. Texel (i, j) of face f, with
i, j in 0 .. S + 1 for face size S, has its centre at u = (i - 0.5) 2 / S - 1 (v alike)
and sits in row f (S + 2) + j, column i of the atlas. A texel is (r, n): r = 0 where the
ray from O meets nothing (an open mirror's hole).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ...geometry.closed_surfaces import is_convex
from ...geometry.raytrace import ReflectorSet
from ...geometry.vectors import dot, lengths, normalized

#: Texels along a cube face's side (without the border): about 0.35 degree per texel.
DEFAULT_FACE_SIZE = 256


@dataclass(frozen=True)
class ReflectorMap:
    """The cube map of one reflector: ``texels`` (6 (S + 2), S + 2, 4) float32 rows of
    (r, normal); ``centre`` O in world space; ``face_size`` S.

    ``convex``: every face of the mesh has the whole mesh behind its plane, so a
    reflection point that faces the eye and the reflected point is visible from both
    (the search skips its occlusion tests). ``min_radius`` and ``max_radius`` bound r.

    ``patches``: for a piece of a mirror that is not star-shaped (``pieces.py``), the
    starts of its search, (K, 3, 4) float32 rows (normal-cone axis, its half-angle),
    (centre of the patch's bounding sphere relative to O, its radius), (start direction,
    0); None for a star-shaped mirror (one guess), or on a folded one the starts from
    which every image is searched (``images``).
    """

    centre: np.ndarray
    face_size: int
    texels: np.ndarray
    convex: bool
    min_radius: float
    max_radius: float
    patches: np.ndarray | None = None
    #: Images of a point the search keeps: 1, or up to this many distinct roots found
    #: from every patch on a folded star-shaped mirror (``fold_patches.py``).
    images: int = 1

    @functools.cached_property
    def mean_radius(self) -> float:
        r = self.texels[..., 0]
        return float(r[r > 0].mean())

    @property
    def nbytes(self) -> int:
        return int(self.texels.nbytes)

    def surface(self, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Bilinear radius (K,), unit normal (K, 3) and validity (K,) along unit
        ``directions`` (K, 3) from the centre; invalid where a texel used is a hole."""
        rows, columns, weights = texel_stencil(directions, self.face_size)
        corners = self.texels[rows, columns].astype(np.float64)  # (K, 4, 4)
        values = np.einsum("kc,kcv->kv", weights, corners)
        valid = (corners[..., 0] > 0).all(axis=1)
        return np.where(valid, values[:, 0], 0.0), normalized(values[:, 1:]), valid

    def inside(self, points: np.ndarray) -> np.ndarray:
        """(K,) bool: the point lies strictly inside the surface (closer to O than r)."""
        offset = np.asarray(points, dtype=np.float64) - self.centre
        distance = lengths(offset)
        radius, _, valid = self.surface(normalized(offset))
        return valid & (distance < radius)


def face_coordinates(directions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cube face (K,) and face coordinates u, v (K,) in [-1, 1] of directions (K, 3).

    Ties between components go to the lower axis, as in the GLSL twin."""
    d = np.asarray(directions, dtype=np.float64)
    magnitude = np.abs(d)
    axis = np.where((magnitude[:, 0] >= magnitude[:, 1]) & (magnitude[:, 0] >= magnitude[:, 2]), 0,
                    np.where(magnitude[:, 1] >= magnitude[:, 2], 1, 2))
    rows = np.arange(len(d))
    major = d[rows, axis]
    scale = 1.0 / np.maximum(np.abs(major), 1e-300)
    u = d[rows, (axis + 1) % 3] * scale
    v = d[rows, (axis + 2) % 3] * scale
    return 2 * axis + (major < 0), u, v


def texel_stencil(directions: np.ndarray, face_size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Atlas rows and columns (K, 4) of the four texels around each direction, and their
    bilinear weights (K, 4), corners in the order (i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)."""
    face, u, v = face_coordinates(directions)
    size = int(face_size)
    fx = (u + 1.0) * 0.5 * size + 0.5
    fy = (v + 1.0) * 0.5 * size + 0.5
    i = np.clip(np.floor(fx), 0, size).astype(np.int64)
    j = np.clip(np.floor(fy), 0, size).astype(np.int64)
    tx, ty = fx - i, fy - j
    columns = np.stack([i, i + 1, i, i + 1], axis=1)
    rows = face[:, None] * (size + 2) + np.stack([j, j, j + 1, j + 1], axis=1)
    weights = np.stack([(1 - tx) * (1 - ty), tx * (1 - ty), (1 - tx) * ty, tx * ty], axis=1)
    return rows, columns, weights


def texel_directions(face_size: int) -> np.ndarray:
    """Unit directions (6 (S + 2), S + 2, 3) of every texel centre of the atlas."""
    size = int(face_size)
    coordinate = (np.arange(size + 2) - 0.5) * 2.0 / size - 1.0
    v, u = np.meshgrid(coordinate, coordinate, indexing="ij")  # rows are j (v), columns i (u)
    faces = []
    for face in range(6):
        axis, sign = face // 2, (-1.0 if face % 2 else 1.0)
        d = np.empty(u.shape + (3,))
        d[..., axis] = sign
        d[..., (axis + 1) % 3] = u
        d[..., (axis + 2) % 3] = v
        faces.append(d / np.linalg.norm(d, axis=-1, keepdims=True))
    return np.concatenate(faces, axis=0)


@dataclass(frozen=True)
class MapBake:
    """A baked map and what its rays saw: ``crossings`` is the number of texel rays that
    met the surface a second time (0 for a star-shaped reflector), ``min_cosine`` the
    smallest cosine between a texel ray and the surface normal where it met it."""

    reflector_map: ReflectorMap
    crossings: int
    min_cosine: float
    coverage: float  # share of texels whose ray met the surface
    #: (6 (S + 2), S + 2) |cosine| between each texel's ray and the face it met (0: none),
    #: what a piece of a mirror keeps (``pieces.piece_map``).
    texel_cosine: np.ndarray | None = None
    #: (6 (S + 2), S + 2) the triangle each texel's ray met first (-1: none).
    texel_triangle: np.ndarray | None = None


def bake_reflector_map(reflector_set: ReflectorSet, centre, face_size: int = DEFAULT_FACE_SIZE) -> MapBake:
    """Trace a ray from ``centre`` through every texel of the cube map and store the
    distance and the interpolated normal (turned away from the centre) where it first
    meets the reflector; trace on from there to count second crossings."""
    centre = np.asarray(centre, dtype=np.float64)
    directions = texel_directions(face_size).reshape(-1, 3)
    origins = np.broadcast_to(centre, directions.shape)
    hits = reflector_set.intersect(origins, directions)
    hit = hits.hit
    texels = np.zeros((len(directions), 4), np.float32)
    outward = -hits.normal[hit]  # the tracer turns normals toward the ray's origin
    texels[hit, 0] = hits.t[hit]
    texels[hit, 1:] = outward
    again = reflector_set.intersect(hits.position[hit], directions[hit], source_triangles=hits.triangle[hit])
    cosine = np.abs(dot(hits.face_normal[hit], directions[hit]))
    radius = texels[hit, 0]
    shape = (6 * (face_size + 2), face_size + 2, 4)
    texel_cosine = np.zeros(len(directions), np.float32)
    texel_cosine[hit] = cosine
    reflector_map = ReflectorMap(
        centre=centre, face_size=int(face_size), texels=texels.reshape(shape),
        convex=is_convex(reflector_set.vertices, reflector_set.triangles, centre),
        min_radius=float(radius.min()) if len(radius) else 0.0,
        max_radius=float(radius.max()) if len(radius) else 0.0,
    )
    return MapBake(reflector_map, int(again.hit.sum()), float(cosine.min()) if len(cosine) else 0.0,
                   float(hit.mean()), texel_cosine.reshape(shape[:2]), hits.triangle.reshape(shape[:2]).astype(np.int32))
