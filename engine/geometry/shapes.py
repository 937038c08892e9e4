# SPDX-License-Identifier: GPL-3.0-or-later
"""Meshes with analytic normals for the demo scenes and tests (numpy only, no bpy).

Curved mirrors are only as good as their normals: a tessellated surface shaded with
averaged face normals reflects a visibly different image than the smooth surface it
stands for. So every reflector here carries the exact normal of the surface it samples
(surfaces of revolution, canal surfaces, spheres), and the Blender layer stores these as
custom split normals. Keeping the geometry bpy-free lets engine tests use exactly the
meshes the demo scenes show, e.g. the Chen-Arvo vase.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: Chen & Arvo 2000, §IV: the vase r(z) = a (z/h)^3 + b (z/h)^2 + c (z/h) + d, 0 <= z <= h.
VASE_A, VASE_B, VASE_C, VASE_D, VASE_H = 5.80, -9.78, 3.90, 0.47, 2.0


@dataclass(frozen=True)
class Shape:
    """A polygon mesh: vertices (N, 3), unit vertex normals (N, 3), triangles and quads.

    Faces are wound counter-clockwise seen from the side the normals point to.
    """

    vertices: np.ndarray
    normals: np.ndarray
    tris: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.int64))
    quads: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), np.int64))

    @property
    def triangles(self) -> np.ndarray:
        """All faces as triangles (quads split along their 0-2 diagonal), (M, 3)."""
        q = self.quads
        split = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]]) if len(q) else q[:, :3]
        return np.concatenate([self.tris, split]).astype(np.int64)

    def faces(self) -> list[tuple[int, ...]]:
        """Faces as index tuples, the form ``bpy.types.Mesh.from_pydata`` takes."""
        return [tuple(f) for f in self.tris.tolist()] + [tuple(f) for f in self.quads.tolist()]

    def moved(self, offset=(0.0, 0.0, 0.0), rotation=None, scale: float = 1.0) -> "Shape":
        """Copy rotated by the 3x3 ``rotation``, uniformly scaled, then translated."""
        r = np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64)
        return Shape(self.vertices @ r.T * scale + np.asarray(offset, dtype=np.float64),
                     self.normals @ r.T, self.tris, self.quads)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def merge(shapes) -> Shape:
    """One shape holding all of ``shapes`` as separate parts (vertices are not welded)."""
    offsets = np.cumsum([0] + [len(s.vertices) for s in shapes])
    return Shape(
        np.concatenate([s.vertices for s in shapes]),
        np.concatenate([s.normals for s in shapes]),
        np.concatenate([s.tris + o for s, o in zip(shapes, offsets)]).astype(np.int64),
        np.concatenate([s.quads + o for s, o in zip(shapes, offsets)]).astype(np.int64),
    )


def orient_faces(shape: Shape) -> Shape:
    """Flip each face whose winding disagrees with the normals at its corners.

    Generators build faces in a convenient order; this makes the winding agree with
    the analytic normals so back-face culling and Blender's face normals are right.
    """
    v, n = shape.vertices, shape.normals
    tris, quads = shape.tris.copy(), shape.quads.copy()
    if len(tris):
        geometric = np.cross(v[tris[:, 1]] - v[tris[:, 0]], v[tris[:, 2]] - v[tris[:, 0]])
        flip = np.einsum("ij,ij->i", geometric, n[tris].sum(axis=1)) < 0
        tris[flip] = tris[flip][:, ::-1]
    if len(quads):
        geometric = np.cross(v[quads[:, 2]] - v[quads[:, 0]], v[quads[:, 3]] - v[quads[:, 1]])
        flip = np.einsum("ij,ij->i", geometric, n[quads].sum(axis=1)) < 0
        quads[flip] = quads[flip][:, ::-1]
    return Shape(v, n, tris, quads)


def revolution(r, z, normal_r, normal_z, segments: int) -> Shape:
    """Surface of revolution about +Z of the profile (r, z) with 2D normals (normal_r, normal_z).

    Profile points with r == 0 become a single pole vertex closed by a triangle fan.
    The normal at angle phi is (normal_r cos phi, normal_r sin phi, normal_z), exact
    for the smooth surface when the profile normals are exact.
    """
    r, z = np.asarray(r, np.float64), np.asarray(z, np.float64)
    profile_normals = _unit(np.stack([normal_r, normal_z], axis=1).astype(np.float64))
    phi = 2.0 * np.pi * np.arange(segments) / segments
    cos, sin = np.cos(phi), np.sin(phi)
    pole = r <= 1e-12
    counts = np.where(pole, 1, segments)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    vertices, normals = [], []
    for k in range(len(r)):
        nr, nz = profile_normals[k]
        if pole[k]:
            vertices.append(np.array([[0.0, 0.0, z[k]]]))
            normals.append(np.array([[0.0, 0.0, -1.0 if nz < 0 else 1.0]]))
        else:
            vertices.append(np.stack([r[k] * cos, r[k] * sin, np.full(segments, z[k])], axis=1))
            normals.append(np.stack([nr * cos, nr * sin, np.full(segments, nz)], axis=1))
    j = np.arange(segments)
    j1 = (j + 1) % segments
    tris, quads = [], []
    for k in range(len(r) - 1):
        a, b = starts[k], starts[k + 1]
        if pole[k] and pole[k + 1]:
            continue
        if pole[k]:
            tris.append(np.stack([np.full(segments, a), b + j, b + j1], axis=1))
        elif pole[k + 1]:
            tris.append(np.stack([a + j, a + j1, np.full(segments, b)], axis=1))
        else:
            quads.append(np.stack([a + j, a + j1, b + j1, b + j], axis=1))
    shape = Shape(
        np.concatenate(vertices), _unit(np.concatenate(normals)),
        np.concatenate(tris).astype(np.int64) if tris else np.zeros((0, 3), np.int64),
        np.concatenate(quads).astype(np.int64) if quads else np.zeros((0, 4), np.int64),
    )
    return orient_faces(shape)


def vase_radius(z) -> np.ndarray:
    """Chen & Arvo's vase contour r(z) (§IV), for 0 <= z <= h."""
    t = np.asarray(z, np.float64) / VASE_H
    return ((VASE_A * t + VASE_B) * t + VASE_C) * t + VASE_D


def vase_radius_slope(z) -> np.ndarray:
    """dr/dz of :func:`vase_radius`."""
    t = np.asarray(z, np.float64) / VASE_H
    return ((3.0 * VASE_A * t + 2.0 * VASE_B) * t + VASE_C) / VASE_H


def vase(segments: int = 96, rings: int = 64) -> Shape:
    """The Chen-Arvo vase: ``segments`` around x ``rings`` up, open at both ends.

    The normal is the gradient of g = sqrt(x^2 + y^2) - r(z), i.e. (cos phi, sin phi, -r'(z))
    normalised, evaluated exactly at every vertex.
    """
    z = np.linspace(0.0, VASE_H, rings + 1)
    return revolution(vase_radius(z), z, np.ones_like(z), -vase_radius_slope(z), segments)


def sphere(radius: float = 1.0, segments: int = 64, rings: int = 32) -> Shape:
    """UV sphere about the origin with exact normals (position / radius)."""
    theta = np.linspace(np.pi, 0.0, rings + 1)
    r, z = np.sin(theta), np.cos(theta)
    r[[0, -1]] = 0.0
    return revolution(radius * r, radius * z, r, z, segments)


def _frame(tangents: np.ndarray, reference) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors (N, B) perpendicular to each tangent, N = T x reference normalised."""
    normal = _unit(np.cross(tangents, np.asarray(reference, np.float64)))
    return normal, np.cross(tangents, normal)


def canal(centres, derivatives, radii, radius_slopes, segments: int, reference=(0.0, 1.0, 0.0)) -> Shape:
    """Canal surface: envelope of spheres of radius rho(s) centred on a curve c(s).

    Samples give c, c', rho, rho'. With T = c'/|c'| and sin(alpha) = rho'/|c'|, the exact
    unit normal is n = -sin(alpha) T + cos(alpha) (cos(theta) N + sin(theta) B) and the
    surface point is c + rho n. ``reference`` must never be parallel to the tangent
    (the Y axis for curves in the XZ plane). Both ends are left open.
    """
    c = np.asarray(centres, np.float64)
    d = np.asarray(derivatives, np.float64)
    speed = np.linalg.norm(d, axis=1)
    tangent = d / speed[:, None]
    sin_a = np.clip(np.asarray(radius_slopes, np.float64) / speed, -1.0, 1.0)
    cos_a = np.sqrt(1.0 - sin_a**2)
    normal, binormal = _frame(tangent, reference)
    theta = 2.0 * np.pi * np.arange(segments) / segments
    around = (np.cos(theta)[None, :, None] * normal[:, None, :]
              + np.sin(theta)[None, :, None] * binormal[:, None, :])
    n = -sin_a[:, None, None] * tangent[:, None, :] + cos_a[:, None, None] * around
    points = c[:, None, :] + np.asarray(radii, np.float64)[:, None, None] * n
    k, j = np.meshgrid(np.arange(len(c) - 1), np.arange(segments), indexing="ij")
    j1 = (j + 1) % segments
    quads = np.stack([k * segments + j, k * segments + j1, (k + 1) * segments + j1,
                      (k + 1) * segments + j], axis=-1).reshape(-1, 4)
    return orient_faces(Shape(points.reshape(-1, 3), n.reshape(-1, 3), quads=quads))


def _body_profile(t):
    """Teapot body r(t), z(t), t in [0, 1], and their derivatives."""
    r = 0.78 + 0.5 * np.sin(np.pi * t) - 0.1 * t
    dr = 0.5 * np.pi * np.cos(np.pi * t) - 0.1
    return r, 1.3 * t, dr, np.full_like(t, 1.3)


def teapot(segments: int = 64) -> Shape:
    """A teapot-like mirror standing on z = 0: body, base, lid, knob, spout and handle.

    Every part is a surface of revolution or a canal surface with exact normals. Parts
    overlap where they join (spout and handle ends sink into the body), as in the
    classic Newell teapot; creases between parts keep separate vertices.
    """
    t = np.linspace(0.0, 1.0, 41)
    r, z, dr, dz = _body_profile(t)
    body = revolution(r, z, dz, -dr, segments)
    base_r = np.linspace(0.0, r[0], 6)
    base = revolution(base_r, np.zeros(6), np.zeros(6), -np.ones(6), segments)
    u = np.linspace(0.0, np.pi / 2, 13)
    lid_a, lid_b = r[-1], 0.25
    lid_r = lid_a * np.cos(u)
    lid_r[-1] = 0.0
    lid = revolution(lid_r, z[-1] + lid_b * np.sin(u), np.cos(u) / lid_a, np.sin(u) / lid_b, segments)
    knob = sphere(0.12, 24, 12).moved((0.0, 0.0, z[-1] + lid_b + 0.07))
    return merge([body, base, lid, knob, _spout(), _handle()])


def _spout() -> Shape:
    """Quadratic Bezier centreline from inside the body up to the tip, tapering radius."""
    s = np.linspace(0.0, 1.0, 33)[:, None]
    p0, p1, p2 = (np.array(p) for p in ((0.75, 0.0, 0.35), (1.75, 0.0, 0.45), (1.85, 0.0, 1.25)))
    centres = (1 - s) ** 2 * p0 + 2 * (1 - s) * s * p1 + s**2 * p2
    derivatives = 2 * (1 - s) * (p1 - p0) + 2 * s * (p2 - p1)
    radii = 0.2 - 0.13 * s[:, 0]
    return canal(centres, derivatives, radii, np.full(len(s), -0.13), 32)


def _handle() -> Shape:
    """Torus arc in the XZ plane on the far side (-X) of the body; its ends sink into the body."""
    angle = np.radians(np.linspace(45.0, 315.0, 49))[:, None]
    centre, major = np.array([-1.0, 0.0, 0.7]), 0.45
    centres = centre + major * np.concatenate([np.cos(angle), 0 * angle, np.sin(angle)], axis=1)
    derivatives = major * np.concatenate([-np.sin(angle), 0 * angle, np.cos(angle)], axis=1)
    return canal(centres, derivatives, np.full(len(angle), 0.07), np.zeros(len(angle)), 24)


def box(size=(1.0, 1.0, 1.0)) -> Shape:
    """Axis-aligned box centred on the origin (flat shaded objects: normals point outward)."""
    corners = np.array([[x, y, z] for z in (-0.5, 0.5) for y in (-0.5, 0.5) for x in (-0.5, 0.5)])
    vertices = corners * np.asarray(size, np.float64)
    quads = np.array([[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]])
    return orient_faces(Shape(vertices, _unit(corners), quads=quads))


def cylinder(radius: float, height: float, segments: int = 32) -> Shape:
    """Closed cylinder standing on z = 0."""
    return revolution([0.0, radius, radius, 0.0], [0.0, 0.0, height, height],
                      [0.0, 1.0, 1.0, 0.0], [-1.0, -1.0, 1.0, 1.0], segments)


def icosahedron(radius: float = 1.0) -> Shape:
    """Regular icosahedron about the origin."""
    g = (1.0 + 5.0**0.5) / 2.0
    v = np.array([[-1, g, 0], [1, g, 0], [-1, -g, 0], [1, -g, 0], [0, -1, g], [0, 1, g],
                  [0, -1, -g], [0, 1, -g], [g, 0, -1], [g, 0, 1], [-g, 0, -1], [-g, 0, 1]], np.float64)
    tris = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9],
                     [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2],
                     [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
                     [8, 6, 7], [9, 8, 1]])
    unit = _unit(v)
    return orient_faces(Shape(unit * radius, unit, tris=tris))


def checker_tiles(count: int, tile: float, parity: int) -> Shape:
    """The tiles of a ``count`` x ``count`` floor at z = 0 whose (i + j) % 2 == parity."""
    i, j = np.meshgrid(np.arange(count), np.arange(count), indexing="ij")
    keep = (i + j) % 2 == parity
    x0 = (i[keep] - count / 2) * tile
    y0 = (j[keep] - count / 2) * tile
    corners = np.stack([np.stack([x0 + dx, y0 + dy, 0 * x0], axis=1)
                        for dx, dy in ((0, 0), (tile, 0), (tile, tile), (0, tile))], axis=1)
    quads = np.arange(4 * len(x0)).reshape(-1, 4)
    vertices = corners.reshape(-1, 3)
    return Shape(vertices, np.tile([0.0, 0.0, 1.0], (len(vertices), 1)), quads=quads)
