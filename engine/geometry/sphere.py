# SPDX-License-Identifier: GPL-3.0-or-later
"""Geodesic spheres: the icosphere and a bumpy one, with their normals.

The Add Demo Scene operator builds its bumpy mirror ball from :func:`bumpy_icosphere`;
the tests and benchmarks use both as mirrors. The sphere's closed-form reflection and the
other held-out test surfaces (ellipsoids, superellipsoids, the torus) are in
``tools/surfaces.py``, outside the zip.
"""

from __future__ import annotations

import numpy as np

from ..scene import Reflector, vertex_normals

_ICOSAHEDRON_PHI = (1 + 5 ** 0.5) / 2


def icosphere(center, radius: float, subdivisions: int, name: str = "Sphere") -> Reflector:
    """Geodesic sphere: an icosahedron split ``subdivisions`` times, radial unit normals.

    Triangles are nearly equilateral, so the flat facets stay uniformly close to the
    sphere (largest gap about (0.95 / 2**subdivisions)**2 / 3 * radius / 2).
    """
    t = _ICOSAHEDRON_PHI
    vertices = np.array([
        [-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
        [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1],
    ], dtype=np.float64)
    faces = np.array([
        [0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
        [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
        [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1],
    ], dtype=np.int64)
    vertices /= np.linalg.norm(vertices, axis=1, keepdims=True)
    for _ in range(subdivisions):
        vertices, faces = _split_faces(vertices, faces)
    center = np.asarray(center, dtype=np.float64)
    return Reflector(name, center + radius * vertices, faces, vertices.copy())


def bumpy_icosphere(center, radius: float, subdivisions: int, amplitude: float, lobes=(5, 4),
                    name: str = "Bumpy") -> Reflector:
    """A geodesic sphere with bumps: radius (1 + a sin(m phi) sin(n theta)) along each
    vertex direction, normals from the faces (``scene.vertex_normals``). Star-shaped
    around its centre but not convex: a held-out surface for the iterative search."""
    sphere = icosphere(center, 1.0, subdivisions)
    d = sphere.normals
    theta, phi = np.arccos(np.clip(d[:, 2], -1.0, 1.0)), np.arctan2(d[:, 1], d[:, 0])
    scale = radius * (1.0 + amplitude * np.sin(lobes[0] * phi) * np.sin(lobes[1] * theta))
    vertices = np.asarray(center, dtype=np.float64) + d * scale[:, None]
    return Reflector(name, vertices, sphere.triangles, vertex_normals(vertices, sphere.triangles))


def _split_faces(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split every triangle into four, new vertices at edge midpoints pushed onto the sphere."""
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    unique_edges, edge_index = np.unique(edges, axis=0, return_inverse=True)
    midpoints = vertices[unique_edges].mean(axis=1)
    midpoints /= np.linalg.norm(midpoints, axis=1, keepdims=True)
    m = len(vertices) + edge_index.reshape(3, -1).T  # midpoint ids of edges 01, 12, 20
    a, b, c = faces.T
    new_faces = np.concatenate([
        np.stack([a, m[:, 0], m[:, 2]], axis=1), np.stack([b, m[:, 1], m[:, 0]], axis=1),
        np.stack([c, m[:, 2], m[:, 1]], axis=1), m,
    ])
    return np.concatenate([vertices, midpoints]), new_faces
