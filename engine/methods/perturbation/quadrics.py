# SPDX-License-Identifier: GPL-3.0-or-later
"""The surfaces a perturbed path bounces off, as quadrics g(y) = y^T Q y / 2 + b . y + c.

Chen & Arvo (2000, eq. 5) write each reflector as an implicit surface g = 0 and need its
derivatives at the path's points: the gradient (the normal) for the path Jacobian, the
second derivatives for it too, the third for the path Hessian.

- :class:`AnalyticSurface`: a reflector declared an exact sphere, ellipsoid or
  superquadric (the object's local axes, radii and exponent); g is exact. A sphere or
  ellipsoid is a quadric, its third derivatives vanish; a superquadric bounces a path
  off its osculating quadric at the path's point (exact value, gradient and second
  derivatives there), as a mesh does, its third derivatives caught by the model error.
  The mesh is then only for display and for finding seeds: seed hits are moved onto the
  true surface (:meth:`AnalyticSurface.intersect`), and the exact reference can be
  polished onto it too (``path_derivatives.newton``).
- :func:`osculating_quadrics`: on a mesh (flat triangles with interpolated normals, the
  surface model of ``engine/reference/exact.py``), the quadric through the hit point whose gradient
  is the interpolated normal and whose second derivatives are the normal field's
  derivative along the facet (symmetrised). Its third derivatives are taken as zero:
  the Taylor step is exact to second order on the quadric, and the adaptive seeds
  (``projector.py``) keep the steps short where the mesh bends differently.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import SceneInputError
from ...scene import Reflector
from ...geometry.vectors import dot

SPHERE, ELLIPSOID, SUPERQUADRIC = "SPHERE", "ELLIPSOID", "SUPERQUADRIC"
SHAPES = (SPHERE, ELLIPSOID, SUPERQUADRIC)
#: A superquadric's exponents: from 2 (an ellipsoid) up, smooth and convex.
MIN_EXPONENT, MAX_EXPONENT = 2.0, 64.0
#: Newton steps along a ray onto a superquadric, from the mesh's hit.
INTERSECT_ITERATIONS = 12


@dataclass(frozen=True)
class QuadricRows:
    """Per-row quadrics: Q (K, 3, 3), b (K, 3), c (K,)."""

    hessian: np.ndarray
    linear: np.ndarray
    constant: np.ndarray

    def gradients(self, points: np.ndarray) -> np.ndarray:
        return np.einsum("kij,kj->ki", self.hessian, points) + self.linear

    def take(self, rows) -> "QuadricRows":
        """The quadrics of ``rows`` (indices or a mask)."""
        return QuadricRows(self.hessian[rows], self.linear[rows], self.constant[rows])


@dataclass(frozen=True)
class AnalyticSurface:
    """An exact sphere, ellipsoid or superquadric (superellipsoid): in the unit frame
    l = W y - m of the object (``matrix``, 4 x 4 local to world, its matrix_world, and
    ``radii`` along its local axes), sum |l_i|^p = 1 with p = ``exponent`` (2 for the
    sphere and ellipsoid; 4 a rounded box, larger a boxier one). Written
    g(y) = s (sum |l_i|^p - 1) / p, s = :attr:`scale`, so that |grad g| ~ 1 on it."""

    name: str
    shape: str
    matrix: np.ndarray
    radii: np.ndarray
    exponent: float = 2.0

    def __post_init__(self):
        if self.shape not in SHAPES:
            raise SceneInputError(self.name, f"unknown analytic shape {self.shape!r} (one of {', '.join(SHAPES)})")
        matrix = np.asarray(self.matrix, dtype=np.float64)
        radii = np.asarray(self.radii, dtype=np.float64).reshape(-1)
        if self.shape == SPHERE:
            radii = np.full(3, radii[0])
        if matrix.shape != (4, 4) or not np.isfinite(matrix).all() or abs(np.linalg.det(matrix[:3, :3])) < 1e-300:
            raise SceneInputError(self.name, "the analytic surface needs an invertible, finite object transform")
        if radii.shape != (3,) or not np.isfinite(radii).all() or (radii <= 0).any():
            raise SceneInputError(self.name, f"the analytic {self.shape.lower()} needs positive radii, got {radii}")
        exponent = float(self.exponent) if self.shape == SUPERQUADRIC else 2.0
        if not (np.isfinite(exponent) and MIN_EXPONENT <= exponent <= MAX_EXPONENT):
            raise SceneInputError(self.name, f"the superquadric's exponent must lie in [{MIN_EXPONENT:g}, "
                                             f"{MAX_EXPONENT:g}] (smooth, convex), got {self.exponent}")
        object.__setattr__(self, "matrix", matrix)
        object.__setattr__(self, "radii", radii)
        object.__setattr__(self, "exponent", exponent)

    @property
    def is_quadric(self) -> bool:
        return self.exponent == 2.0

    @property
    def _to_unit(self) -> tuple[np.ndarray, np.ndarray]:
        """(W, m): W y - m maps world points onto the unit sphere's frame."""
        w = np.linalg.inv(self.matrix[:3, :3]) / self.radii[:, None]
        return w, w @ self.matrix[:3, 3]

    @property
    def scale(self) -> float:
        """The surface's mean world radius: g is scaled by it so that |grad g| ~ 1 on it."""
        return float(abs(np.linalg.det(self.matrix[:3, :3] * self.radii[None, :])) ** (1.0 / 3.0))

    def quadric(self) -> tuple[np.ndarray, np.ndarray, float]:
        """(Q, b, c) of a sphere's or ellipsoid's g(y) = y^T Q y / 2 + b . y + c."""
        if not self.is_quadric:
            raise ValueError(f"{self.name!r}: a superquadric is not a quadric (use osculating)")
        w, m = self._to_unit
        s = self.scale
        return s * w.T @ w, -s * w.T @ m, 0.5 * s * (m @ m - 1.0)

    def _local(self, points) -> np.ndarray:
        w, m = self._to_unit
        return np.asarray(points, dtype=np.float64) @ w.T - m

    def values(self, points: np.ndarray) -> np.ndarray:
        p = self.exponent
        return self.scale * ((np.abs(self._local(points)) ** p).sum(axis=1) - 1.0) / p

    def gradients(self, points: np.ndarray) -> np.ndarray:
        local = self._local(points)
        return self.scale * (np.sign(local) * np.abs(local) ** (self.exponent - 1.0)) @ self._to_unit[0]

    def hessians(self, points: np.ndarray) -> np.ndarray:
        """(K, 3, 3) second derivatives: s (p - 1) W^T diag(|l|^(p - 2)) W."""
        w = self._to_unit[0]
        weights = (self.exponent - 1.0) * np.abs(self._local(points)) ** (self.exponent - 2.0)
        return self.scale * np.einsum("ia,ka,aj->kij", w.T, weights, w)

    def osculating(self, points: np.ndarray) -> QuadricRows:
        """The quadric with the surface's value, gradient and second derivatives at each
        point: exact for a sphere or ellipsoid (the same one everywhere); for a
        superquadric the path derivatives' quadric at the path's point."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        q = self.hessians(points)
        gradient = self.gradients(points)
        qx = np.einsum("kij,kj->ki", q, points)
        return QuadricRows(q, gradient - qx, self.values(points) - dot(gradient, points) + 0.5 * dot(points, qx))

    def normals(self, points: np.ndarray) -> np.ndarray:
        g = self.gradients(points)
        return g / np.linalg.norm(g, axis=1, keepdims=True)

    def intersect(self, origins: np.ndarray, directions: np.ndarray, near_t: np.ndarray) -> np.ndarray:
        """(R,) distance along each ray to its intersection with the surface nearest to
        ``near_t`` (the mesh's hit), NaN where the line misses the surface: in closed
        form on a quadric, by Newton's method from ``near_t`` on a superquadric."""
        if not self.is_quadric:
            return self._newton_along(origins, directions, np.asarray(near_t, dtype=np.float64))
        w, m = self._to_unit
        o = origins @ w.T - m
        d = directions @ w.T
        a, half_b, c = dot(d, d), dot(o, d), dot(o, o) - 1.0
        disc = half_b * half_b - a * c
        with np.errstate(invalid="ignore"):
            root = np.sqrt(disc)
            t = np.stack([(-half_b - root) / a, (-half_b + root) / a], axis=1)
        pick = np.nanargmin(np.abs(np.nan_to_num(t, nan=np.inf) - np.asarray(near_t)[:, None]), axis=1)
        return np.where(disc >= 0, t[np.arange(len(t)), pick], np.nan)

    def _newton_along(self, origins, directions, t) -> np.ndarray:
        for _ in range(INTERSECT_ITERATIONS):
            points = origins + t[:, None] * directions
            slope = dot(self.gradients(points), directions)
            with np.errstate(divide="ignore", invalid="ignore"):
                t = t - self.values(points) / slope
        converged = np.abs(self.values(origins + t[:, None] * directions)) < 1e-9 * self.scale
        return np.where(converged, t, np.nan)

    def mesh_deviation(self, reflector: Reflector) -> float:
        """The largest distance of the mesh's vertices from the surface, relative to the
        surface's radius (first-order: |g| / |grad g| / radius). The panel reports it; a
        mesh far from its declared surface draws reflections the surface does not make."""
        g = self.values(reflector.vertices)
        grad = np.linalg.norm(self.gradients(reflector.vertices), axis=1)
        return float(np.max(np.abs(g) / np.maximum(grad, 1e-300)) / self.scale)


def osculating_quadrics(reflector_set, triangles: np.ndarray, barycentric: np.ndarray) -> QuadricRows:
    """The mesh's osculating quadric at each hit (triangle, barycentric): through the hit
    point x, gradient the interpolated unit normal n, second derivatives S the
    symmetrised derivative of the normal field along the facet:

        g(y) = n . (y - x) + (y - x)^T S (y - x) / 2.

    The normal field n = N / |N|, N = sum_k beta_k n_k, changes along the facet by
    dn = (I - n n^T) dN / |N|; dN / du = n_1 - n_0 and dN / dv = n_2 - n_0 map to a
    world displacement through the facet's edges (the Gram matrix of e1, e2)."""
    corners = reflector_set.triangles[triangles]
    vertex_normals = reflector_set.normals[corners]  # (K, 3, 3)
    raw = np.einsum("kj,kji->ki", barycentric, vertex_normals)
    size = np.linalg.norm(raw, axis=1)
    n = raw / np.maximum(size, 1e-300)[:, None]
    x = np.einsum("kj,kji->ki", barycentric, reflector_set.vertices[corners])
    tangent = np.eye(3) - n[:, :, None] * n[:, None, :]
    dn = np.einsum("kij,kjc->kic", tangent, np.stack([vertex_normals[:, 1] - vertex_normals[:, 0],
                                                      vertex_normals[:, 2] - vertex_normals[:, 0]], axis=2))
    dn /= np.maximum(size, 1e-300)[:, None, None]
    edges = np.stack([reflector_set.e1[triangles], reflector_set.e2[triangles]], axis=2)  # (K, 3, 2)
    gram = np.einsum("kic,kid->kcd", edges, edges)
    derivative = np.einsum("kic,kcd,kjd->kij", dn, np.linalg.inv(gram), edges)
    s = 0.5 * (derivative + np.swapaxes(derivative, 1, 2))
    sx = np.einsum("kij,kj->ki", s, x)
    return QuadricRows(s, n - sx, -dot(n, x) + 0.5 * dot(x, sx))
