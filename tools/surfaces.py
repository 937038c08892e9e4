# SPDX-License-Identifier: GPL-3.0-or-later
"""Held-out test surfaces and the mirror sphere's closed-form reflection (numpy only).

The ellipsoid, the superellipsoid and the torus carry their exact normals, so the methods
are measured on more than spheres (the torus is not star-shaped: the iterative search must
refuse it); the flat-faced box is glass's slab and block. The sphere is the one reflector
whose reflections are known independently of any tessellation (:func:`sphere_reflection`),
so it checks the exact solver. They start from the extension's own geodesic sphere
(``engine/geometry/sphere.py``). Used by the tests and benchmarks only, not shipped.
"""

from __future__ import annotations

import numpy as np

from ..engine.geometry.sphere import icosphere
from ..engine.scene import Reflector


def rotation_z(angle: float) -> np.ndarray:
    """3x3 rotation by ``angle`` radians about +Z."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def ellipsoid(center, radii, subdivisions: int, name: str = "Ellipsoid") -> Reflector:
    """A geodesic sphere scaled by ``radii`` along the axes, with the ellipsoid's exact
    normals (x / a^2, y / b^2, z / c^2)."""
    sphere = icosphere((0.0, 0.0, 0.0), 1.0, subdivisions)
    radii = np.asarray(radii, dtype=np.float64)
    return Reflector(name, np.asarray(center, dtype=np.float64) + sphere.vertices * radii, sphere.triangles,
                     sphere.vertices / radii)


def superellipsoid(center, radii, exponent: float, subdivisions: int, name: str = "Superellipsoid") -> Reflector:
    """The superellipsoid |x / a|^p + |y / b|^p + |z / c|^p = 1 (p = ``exponent``: 2 an
    ellipsoid, larger a rounder box), its vertices where the geodesic sphere's rays from
    the centre meet it, with the exact normals (the gradient, sign(x) |x / a|^(p - 1) / a
    per axis). Star-shaped around its centre for any p > 0, convex for p >= 1."""
    d = icosphere((0.0, 0.0, 0.0), 1.0, subdivisions).vertices
    radii, p = np.asarray(radii, dtype=np.float64), float(exponent)
    local = d * ((np.abs(d / radii) ** p).sum(axis=1) ** (-1.0 / p))[:, None]
    normals = np.sign(local) * np.abs(local / radii) ** (p - 1.0) / radii
    return Reflector(name, np.asarray(center, dtype=np.float64) + local,
                     icosphere((0.0, 0.0, 0.0), 1.0, subdivisions).triangles, normals)


def torus(center, major: float, minor: float, segments: int, rings: int, name: str = "Torus") -> Reflector:
    """A closed torus about the +Z axis through ``center``: ``segments`` around the axis,
    ``rings`` around the tube of radius ``minor`` whose centre line has radius ``major``,
    exact (outward) normals, faces wound outward. Not star-shaped (no point sees all of
    it through the hole): the iterative search must refuse it."""
    u, v = np.meshgrid(2 * np.pi * np.arange(segments) / segments, 2 * np.pi * np.arange(rings) / rings,
                       indexing="ij")
    normals = np.stack([np.cos(u) * np.cos(v), np.sin(u) * np.cos(v), np.sin(v)], axis=-1).reshape(-1, 3)
    centre_line = major * np.stack([np.cos(u), np.sin(u), np.zeros_like(u)], axis=-1).reshape(-1, 3)
    a = np.arange(segments * rings).reshape(segments, rings)
    b, c = np.roll(a, -1, axis=0), np.roll(a, -1, axis=1)
    d = np.roll(b, -1, axis=1)
    triangles = np.concatenate([np.stack([a, b, d], axis=-1).reshape(-1, 3),
                                np.stack([a, d, c], axis=-1).reshape(-1, 3)])
    return Reflector(name, np.asarray(center, dtype=np.float64) + centre_line + minor * normals, triangles, normals)


def flat_box(name: str, low, high) -> Reflector:
    """A closed box from ``low`` to ``high`` with flat faces (each face its own vertices)."""
    low, high = np.asarray(low, np.float64), np.asarray(high, np.float64)
    vertices, normals, triangles = [], [], []
    for axis in range(3):
        for side in (0, 1):
            normal = np.zeros(3)
            normal[axis] = 1.0 if side else -1.0
            u, v = (axis + 1) % 3, (axis + 2) % 3
            base = len(vertices)
            for a, b in ((0, 0), (1, 0), (1, 1), (0, 1)):
                corner = low.copy()
                corner[axis] = high[axis] if side else low[axis]
                corner[u] = high[u] if a else low[u]
                corner[v] = high[v] if b else low[v]
                vertices.append(corner)
                normals.append(normal)
            quad = [(base, base + 1, base + 2), (base, base + 2, base + 3)]
            triangles += quad if side else [t[::-1] for t in quad]  # counter-clockwise seen from outside
    return Reflector(name, np.array(vertices), np.array(triangles), np.array(normals))


def sphere_reflection(center, radius: float, eye, points: np.ndarray, iterations: int = 64):
    """Closed-form first-order reflection of points in a mirror sphere seen from ``eye``.

    The reflection point lies in the plane through the eye E, the point V and the centre
    O, on the arc between the projections of V and E onto the sphere (Ofek 1998, recalled
    by Roger-Holzschuch 2006, section 3.3.4). On that arc the tangential parts of the
    unit directions toward E and V cancel at exactly one angle, found by bisection.

    Returns the reflection points (P, 3) and a (P,) bool: the point is seen from the eye
    and sees V (both within the sphere's horizon). Points inside the sphere, or on the
    line through E and O, get NaN and False.
    """
    center = np.asarray(center, dtype=np.float64)
    eye = np.asarray(eye, dtype=np.float64) - center
    points = np.asarray(points, dtype=np.float64) - center
    eye_distance = np.linalg.norm(eye)
    e_x = eye / eye_distance
    along = points @ e_x
    across_vec = points - along[:, None] * e_x
    across = np.linalg.norm(across_vec, axis=1)
    e_y = across_vec / np.maximum(across, 1e-300)[:, None]
    point_distance = np.linalg.norm(points, axis=1)
    usable = (across > 1e-12 * radius) & (point_distance > radius) & (eye_distance > radius)

    eye_2d = np.array([eye_distance, 0.0])
    theta_v = np.arctan2(across, along)
    lo, hi = np.zeros_like(theta_v), theta_v.copy()
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        positive = _tangential_balance(mid, radius, eye_2d, along, across) > 0
        lo = np.where(positive, mid, lo)
        hi = np.where(positive, hi, mid)
    theta = 0.5 * (lo + hi)

    reflection = center + radius * (np.cos(theta)[:, None] * e_x + np.sin(theta)[:, None] * e_y)
    seen_by_eye = np.cos(theta) > radius / eye_distance
    sees_point = np.cos(theta_v - theta) > radius / np.maximum(point_distance, radius)
    visible = usable & seen_by_eye & sees_point
    reflection[~usable] = np.nan
    return reflection, visible


def _tangential_balance(theta, radius, eye_2d, along, across):
    """Sum of the tangential components of the unit directions from the arc point to E and V."""
    normal = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    x = radius * normal
    to_eye = eye_2d - x
    to_point = np.stack([along, across], axis=1) - x
    to_eye /= np.linalg.norm(to_eye, axis=1, keepdims=True)
    to_point /= np.linalg.norm(to_point, axis=1, keepdims=True)
    total = to_eye + to_point
    return normal[:, 0] * total[:, 1] - normal[:, 1] * total[:, 0]
