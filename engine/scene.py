# SPDX-License-Identifier: GPL-3.0-or-later
"""The scene as the engine sees it: reflectors and diffuse meshes, world space, numpy.

A reflector's mirror surface is its triangle mesh with smooth, per-vertex normals
interpolated across each triangle (Phong normals). Positions stay on the flat
triangles; only the normal is interpolated. Every method in the engine, and the
exact reference solver, works on that same surface, so errors measure the method and
not a difference of surface models.

Sharp edges and custom split normals are represented by splitting vertices: two
corners that share a position but not a normal become two reflector vertices.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import SceneInputError
from .geometry.components import component_roots, numbered_in_order

#: Normals shorter than this are treated as zero-length (degenerate) input.
MIN_NORMAL_LENGTH = 1e-8


def _as_points(name: str, what: str, array) -> np.ndarray:
    points = np.ascontiguousarray(array, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise SceneInputError(name, f"{what} must be an (N, 3) array, got shape {points.shape}")
    bad = ~np.isfinite(points).all(axis=1)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        raise SceneInputError(
            name, f"{int(bad.sum())} {what} are NaN or infinite (first at index {first})"
        )
    return points


def _as_triangles(name: str, array, n_vertices: int) -> np.ndarray:
    triangles = np.ascontiguousarray(array, dtype=np.int64)
    if triangles.ndim != 2 or triangles.shape[1] != 3:
        raise SceneInputError(name, f"triangles must be an (M, 3) array, got shape {triangles.shape}")
    if len(triangles) == 0:
        raise SceneInputError(name, "has no faces (a mirror needs at least one triangle)")
    if triangles.min() < 0 or triangles.max() >= n_vertices:
        raise SceneInputError(
            name, f"triangle indices must lie in [0, {n_vertices - 1}], "
            f"got [{triangles.min()}, {triangles.max()}]"
        )
    return triangles


def triangle_areas(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area of each triangle, (M,)."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


#: Triangles whose areas a validation computes at a time (it stops at the first with area).
AREA_BLOCK = 1 << 14


def _any_area(vertices: np.ndarray, triangles: np.ndarray) -> bool:
    """Whether some triangle has an area, looked for a block at a time: a million
    triangles' corners and cross products cost 200 MB at once, and the first block
    almost always has one."""
    return any((triangle_areas(vertices, triangles[start:start + AREA_BLOCK]) > 0).any()
               for start in range(0, len(triangles), AREA_BLOCK))


def smooth_pieces(triangles: np.ndarray, n_vertices: int) -> np.ndarray:
    """(M,) the smooth piece of each triangle, numbered 0, 1, ... in order of first triangle.

    Triangles that share a vertex share its normal, so the interpolated normal field is
    continuous across them; across a sharp edge (split vertices) it jumps, and so do the
    reflected rays. A piece is a connected set of triangles through shared vertices: the
    mirror surfaces over which the reflected ray field is continuous. Connected
    components (``geometry.components``).
    """
    label = component_roots(triangles, n_vertices)
    return numbered_in_order(label[np.asarray(triangles)[:, 0]])


@dataclass(frozen=True)
class Reflector:
    """A mirror: world-space triangle mesh with unit per-vertex normals.

    Construction validates the arrays and normalises the normals; a bad array raises
    :class:`SceneInputError` naming ``name``.
    """

    name: str
    vertices: np.ndarray  # (N, 3) float64
    triangles: np.ndarray  # (M, 3) int64
    normals: np.ndarray  # (N, 3) float64, unit length

    def __post_init__(self):
        vertices = _as_points(self.name, "vertices", self.vertices)
        normals = _as_points(self.name, "normals", self.normals)
        if normals.shape != vertices.shape:
            raise SceneInputError(
                self.name, f"needs one normal per vertex: {len(vertices)} vertices, "
                f"{len(normals)} normals"
            )
        triangles = _as_triangles(self.name, self.triangles, len(vertices))
        lengths = np.linalg.norm(normals, axis=1)
        used = np.zeros(len(vertices), dtype=bool)
        used[triangles.ravel()] = True
        zero = used & (lengths < MIN_NORMAL_LENGTH)
        if zero.any():
            raise SceneInputError(
                self.name, f"{int(zero.sum())} vertex normals have zero length "
                f"(first at vertex {int(np.flatnonzero(zero)[0])})"
            )
        if not _any_area(vertices, triangles):
            raise SceneInputError(self.name, "all faces have zero area")
        normals = normals / np.maximum(lengths, MIN_NORMAL_LENGTH)[:, None]
        for attr, value in (("vertices", vertices), ("normals", normals), ("triangles", triangles)):
            value.setflags(write=False)
            object.__setattr__(self, attr, value)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.vertices.min(axis=0), self.vertices.max(axis=0)


@dataclass(frozen=True)
class DiffuseMesh:
    """A diffuse (reflected) mesh: world-space triangles with a colour per vertex.

    ``colors`` is (N, 4) linear RGBA in [0, 1]; ``emissive`` says the colour is an
    emission colour to be shown unlit (the demo scenes' flat labels).
    """

    name: str
    vertices: np.ndarray  # (N, 3) float64
    triangles: np.ndarray  # (M, 3) int64
    colors: np.ndarray  # (N, 4) float32
    emissive: bool = False
    uvs: np.ndarray | None = field(default=None)  # (N, 2) or None
    #: (N, 3) shading normals (Blender's corner normals), or None for smooth ones from the faces.
    normals: np.ndarray | None = field(default=None)
    #: (H, W, 4) float32 linear RGBA image texture read through ``uvs`` (rows bottom to top), or None.
    image: np.ndarray | None = field(default=None)

    def __post_init__(self):
        vertices = _as_points(self.name, "vertices", self.vertices)
        for what, value, width in (("uvs", self.uvs, 2), ("normals", self.normals, 3)):
            if value is not None and np.shape(value) != (len(vertices), width):
                raise SceneInputError(self.name, f"{what} must be (N, {width}) with N = {len(vertices)}, "
                                                 f"got shape {np.shape(value)}")
        if self.image is not None and (np.ndim(self.image) != 3 or np.shape(self.image)[2] != 4):
            raise SceneInputError(self.name, f"image must be (H, W, 4), got shape {np.shape(self.image)}")
        triangles = _as_triangles(self.name, self.triangles, len(vertices))
        colors = np.ascontiguousarray(self.colors, dtype=np.float32)
        if colors.ndim == 2 and colors.shape[1] == 3:
            colors = np.concatenate([colors, np.ones((len(colors), 1), np.float32)], axis=1)
        if colors.shape != (len(vertices), 4):
            raise SceneInputError(
                self.name, f"colors must be (N, 3) or (N, 4) with N = {len(vertices)}, "
                f"got shape {colors.shape}"
            )
        if not np.isfinite(colors).all():
            raise SceneInputError(self.name, "colors contain NaN or infinite values")
        object.__setattr__(self, "vertices", vertices)
        object.__setattr__(self, "triangles", triangles)
        object.__setattr__(self, "colors", colors)


def vertex_normals(vertices, triangles) -> np.ndarray:
    """Smooth unit normals (N, 3): the area-weighted sum of each vertex's face normals
    (zero for a vertex in no face)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    face = np.cross(b - a, c - a)  # length = twice the area
    normals = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(normals, triangles[:, k], face)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)


def scene_bounds(reflectors, meshes=(), margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned box around all reflectors and meshes, grown by ``margin``."""
    arrays = [r.vertices for r in reflectors] + [m.vertices for m in meshes]
    if not arrays:
        raise SceneInputError("scene", "is empty: no reflector and no diffuse mesh")
    stacked = np.concatenate(arrays)
    return stacked.min(axis=0) - margin, stacked.max(axis=0) + margin
