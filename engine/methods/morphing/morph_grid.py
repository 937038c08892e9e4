# SPDX-License-Identifier: GPL-3.0-or-later
"""The grid of reflection morphing and its nodes (SBC paper, Popescu, Sacks, Mei 2006,
section VI): the reflector's rigid frame, the open edges extended while building, the
regular grid split into tetrahedra (Kuhn), and the panoramic sample-based camera at
each node (six cube faces). How a view between nodes is blended: :mod:`.morphing`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ...errors import SceneInputError
from ...geometry.raytrace import ReflectorSet
from ..sbc.sbc import SampleBasedCamera
from ..sbc.sbc_build import build_sample_based_camera, check_view_outside_reflectors
from ...scene import Reflector
from ...view import View, look_at_view

#: Cube faces: forward and up axes (+X, -X, +Y, -Y, +Z, -Z).
CUBE_FACES = (
    ((1, 0, 0), (0, 0, 1)), ((-1, 0, 0), (0, 0, 1)), ((0, 1, 0), (0, 0, 1)),
    ((0, -1, 0), (0, 0, 1)), ((0, 0, 1), (0, 1, 0)), ((0, 0, -1), (0, 1, 0)),
)
#: The 6 axis orders of the Kuhn (Freudenthal) split of a cube: tetrahedron k holds the
#: points whose local coordinates satisfy f[p0] >= f[p1] >= f[p2] for PERMUTATIONS[k].
PERMUTATIONS = np.array([(0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)])

#: The eight corners of a grid cell, as (x, y, z) steps from its lowest node.
CELL_CORNERS = np.array([(i, j, k) for k in (0, 1) for j in (0, 1) for i in (0, 1)])

#: MorphSettings.kind values
TETRAHEDRAL, OCTREE = "tetrahedral", "octree"
#: node status codes
NODE_OK, NODE_INSIDE = 0, 1


@dataclass(frozen=True)
class MorphSettings:
    """What shapes a baked grid (all part of the cache key)."""

    grid: tuple = (9, 9, 5)  # nodes along the frame's X, Y, Z
    margin: float = 1.0  # the box grows by this many reflector sizes on every side
    face_resolution: int = 96  # pixels per cube-face side
    downsample: int = 1
    accuracy_px: float = 0.5  # leaf accuracy, in cube-face pixels
    overlap_cells: int = 2  # cube faces overlap by this many ray-map cells
    extension: float = 0.05  # open edges extended by this many reflector sizes
    #: What sits at the nodes: "tetrahedral", panoramic sample-based cameras blended over
    #: the tetrahedron holding the eye (SBC paper VI); "octree", ray octrees blended
    #: trilinearly over the cell holding it (Martin & Popescu 2004, ``methods/octree``).
    kind: str = TETRAHEDRAL
    octree_depth: int = 6  # the ray octrees' leaves are 2**-depth of their root cube

    def __post_init__(self):
        grid = tuple(int(n) for n in self.grid)
        if len(grid) != 3 or min(grid) < 2:
            raise SceneInputError("morph_grid", f"needs at least 2 nodes on each axis, got {self.grid}")
        object.__setattr__(self, "grid", grid)
        if not self.margin > 0:
            raise SceneInputError("morph_margin", f"must be positive, got {self.margin}")
        if int(self.face_resolution) // int(self.downsample) < 4:
            raise SceneInputError("morphing", "cube faces need at least 4 ray-map cells a side")
        if self.kind not in (TETRAHEDRAL, OCTREE):
            raise SceneInputError("morphing", f"grid kind must be {TETRAHEDRAL!r} or {OCTREE!r}, got {self.kind!r}")
        if not 1 <= int(self.octree_depth) <= 10:
            raise SceneInputError("morphing", f"octree depth must be 1 to 10, got {self.octree_depth}")

    def as_tuple(self) -> tuple:
        return (self.grid, float(self.margin), int(self.face_resolution), int(self.downsample),
                float(self.accuracy_px), int(self.overlap_cells), float(self.extension), self.kind,
                int(self.octree_depth))




# --- the rigid frame ----------------------------------------------------------------


def rigid_frame(matrix) -> np.ndarray:
    """Rotation and translation of an object matrix (4x4): the frame the grid is baked in.

    The linear part's nearest rotation (polar decomposition); scale and shear stay in
    the geometry, which is what changes reflections.
    """
    matrix = np.asarray(matrix, dtype=np.float64)
    u, _, vt = np.linalg.svd(matrix[:3, :3])
    rotation = u @ vt
    if np.linalg.det(rotation) < 0:
        rotation = u @ np.diag([1.0, 1.0, -1.0]) @ vt
    frame = np.eye(4)
    frame[:3, :3], frame[:3, 3] = rotation, matrix[:3, 3]
    return frame


def to_frame(frame: np.ndarray, points: np.ndarray) -> np.ndarray:
    return (np.asarray(points, dtype=np.float64) - frame[:3, 3]) @ frame[:3, :3]


def from_frame(frame: np.ndarray, points: np.ndarray) -> np.ndarray:
    return np.asarray(points, dtype=np.float64) @ frame[:3, :3].T + frame[:3, 3]


def reflector_in_frame(reflector: Reflector, frame: np.ndarray) -> Reflector:
    """The world-space reflector expressed in the rigid frame (normals rotate alike)."""
    return Reflector(reflector.name, to_frame(frame, reflector.vertices), reflector.triangles,
                     reflector.normals @ frame[:3, :3])


# --- remedy 1: extended reflectors ---------------------------------------------------


def extend_reflector(reflector: Reflector, width: float) -> Reflector:
    """The reflector with a strip of ``width`` along its open edges (SBC paper VI, Fig. 15b).

    Boundary edges are found on welded positions (split vertices are not edges). Each
    boundary vertex moves outward in the plane of its boundary triangles; the strip's
    vertices keep the boundary vertex's normal. A closed mesh is returned unchanged.
    """
    if width <= 0:
        return reflector
    _, welded = np.unique(reflector.vertices, axis=0, return_inverse=True)
    welded = welded.reshape(-1)
    tri = welded[reflector.triangles]
    directed = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    third = np.concatenate([tri[:, 2], tri[:, 0], tri[:, 1]])
    n = welded.max() + 1
    key = directed[:, 0] * n + directed[:, 1]
    reverse = directed[:, 1] * n + directed[:, 0]
    undirected = np.minimum(key, reverse)
    _, count = np.unique(undirected, return_counts=True)
    edge_count = count[np.searchsorted(np.unique(undirected), undirected)]
    boundary = np.flatnonzero(edge_count == 1)
    if len(boundary) == 0:
        return reflector
    # A representative original vertex for each welded index.
    representative = np.zeros(n, dtype=np.int64)
    representative[welded] = np.arange(len(welded))
    position = reflector.vertices[representative]
    a, b, c = directed[boundary, 0], directed[boundary, 1], third[boundary]
    edge = position[b] - position[a]
    edge_unit = edge / np.linalg.norm(edge, axis=1, keepdims=True)
    away = position[a] - position[c]
    outward = away - np.einsum("ij,ij->i", away, edge_unit)[:, None] * edge_unit
    outward /= np.maximum(np.linalg.norm(outward, axis=1, keepdims=True), 1e-300)
    push = np.zeros((n, 3))
    np.add.at(push, a, outward)
    np.add.at(push, b, outward)
    ends = np.unique(np.concatenate([a, b]))
    push[ends] /= np.maximum(np.linalg.norm(push[ends], axis=1, keepdims=True), 1e-300)
    new_index = np.full(n, -1, dtype=np.int64)
    new_index[ends] = len(reflector.vertices) + np.arange(len(ends))
    vertices = np.concatenate([reflector.vertices, position[ends] + width * push[ends]])
    normals = np.concatenate([reflector.normals, reflector.normals[representative[ends]]])
    ra, rb = representative[a], representative[b]
    strip = np.concatenate([np.stack([ra, new_index[b], rb], axis=1),
                            np.stack([ra, new_index[a], new_index[b]], axis=1)])
    return Reflector(reflector.name, vertices, np.concatenate([reflector.triangles, strip]), normals)


# --- the grid and its tetrahedra ------------------------------------------------------


@dataclass(frozen=True)
class TetrahedralGrid:
    """A regular grid of ``shape`` nodes over the box [lo, hi], 6 Kuhn tetrahedra per cell.

    Every cell is split along its main diagonal by the same rule, so faces of
    neighbouring cells' tetrahedra coincide (the split is conforming).
    """

    lo: np.ndarray
    hi: np.ndarray
    shape: tuple

    @property
    def spacing(self) -> np.ndarray:
        return (self.hi - self.lo) / (np.asarray(self.shape) - 1)

    @property
    def n_nodes(self) -> int:
        return int(np.prod(self.shape))

    def node_index(self, ijk: np.ndarray) -> np.ndarray:
        nx, ny, _ = self.shape
        return ijk[..., 0] + nx * (ijk[..., 1] + ny * ijk[..., 2])

    def node_positions(self) -> np.ndarray:
        """(N, 3) node positions, X fastest."""
        nx, ny, nz = self.shape
        k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
        ijk = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1)
        return self.lo + ijk * self.spacing

    def locate(self, points: np.ndarray):
        """Tetrahedron of each point: (tet id (P,), node indices (P, 4), weights (P, 4), inside (P,)).

        Weights are barycentric (sum 1, all >= 0 inside). Points outside the grid get
        the nearest cell's tetrahedron with weights that may be negative, inside False.
        """
        points = np.atleast_2d(np.asarray(points, dtype=np.float64))
        shape = np.asarray(self.shape)
        f = (points - self.lo) / self.spacing
        tolerance = 1e-9 * shape
        inside = np.all((f >= -tolerance) & (f <= shape - 1 + tolerance), axis=1)
        cell = self._cell(f)
        local = f - cell
        order = np.argsort(-local, axis=1, kind="stable")
        # Permutation index of each axis order (rows of PERMUTATIONS are lexicographic).
        perm = (order[:, 0] * 2 + (order[:, 1] > order[:, 2])).astype(np.int64)
        sorted_local = np.take_along_axis(local, order, axis=1)
        weights = np.stack([1 - sorted_local[:, 0], sorted_local[:, 0] - sorted_local[:, 1],
                            sorted_local[:, 1] - sorted_local[:, 2], sorted_local[:, 2]], axis=1)
        steps = np.eye(3, dtype=np.int64)[order]  # (P, 3 steps, 3)
        corners = cell[:, None, :] + np.concatenate([np.zeros((len(points), 1, 3), np.int64),
                                                      np.cumsum(steps, axis=1)], axis=1)
        nodes = self.node_index(corners)
        cells = cell[:, 0] + (shape[0] - 1) * (cell[:, 1] + (shape[1] - 1) * cell[:, 2])
        return cells * 6 + perm, nodes, weights, inside

    def cell_nodes(self, tet: int) -> np.ndarray:
        """(8,) the nodes of the cell (cube) that holds tetrahedron ``tet`` (of :meth:`locate`)."""
        nx, ny, _ = self.shape
        cell = int(tet) // 6
        ijk = np.array([cell % (nx - 1), (cell // (nx - 1)) % (ny - 1), cell // ((nx - 1) * (ny - 1))])
        return self.node_index(ijk + CELL_CORNERS)

    def _cell(self, f: np.ndarray) -> np.ndarray:
        """(P, 3) integer cell (lowest corner node) of grid coordinates ``f``, clamped to the grid."""
        return np.clip(np.floor(f).astype(np.int64), 0, np.asarray(self.shape) - 2)

    def nodes_around(self, point) -> np.ndarray:
        """The nodes of the cell holding ``point`` and of the cells beside it (up to 4 x
        4 x 4, fewer at the grid's faces), nearest to ``point`` first: those a view moving
        on from ``point`` uses next."""
        point = np.asarray(point, dtype=np.float64)
        cell = self._cell(((point - self.lo) / self.spacing)[None])[0]
        offsets = np.stack(np.meshgrid(*[np.arange(-1, 3)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
        around = np.unique(self.node_index(np.clip(cell + offsets, 0, np.asarray(self.shape) - 1)))
        distance = np.linalg.norm(self.node_positions()[around] - point, axis=1)
        return around[np.argsort(distance, kind="stable")]


def grid_for(reflector: Reflector, settings: MorphSettings) -> TetrahedralGrid:
    """The grid over the reflector's box grown by ``margin`` reflector sizes (its largest extent)."""
    lo, hi = reflector.bounds
    size = float(np.max(hi - lo))
    return TetrahedralGrid(lo - settings.margin * size, hi + settings.margin * size, settings.grid)


# --- panoramic cameras at the nodes ----------------------------------------------------


def cube_face_views(eye, settings: MorphSettings, near: float, far: float) -> list[View]:
    """Six perspective views from ``eye`` covering every direction, overlapping slightly.

    A 90-degree face would leave the half cell at its border between faces unprojected
    (a point needs four rays around it); each face is widened by ``overlap_cells``.
    """
    cells = settings.face_resolution / settings.downsample
    half_tan = 1.0 + (settings.overlap_cells + 0.5) * 2.0 / cells
    fov = float(np.degrees(2.0 * np.arctan(half_tan)))
    eye = np.asarray(eye, dtype=np.float64)
    return [look_at_view(eye, eye + np.asarray(forward, float), up, fov_y_deg=fov, width=settings.face_resolution,
                         height=settings.face_resolution, near=near, far=far, name=f"face{k}")
            for k, (forward, up) in enumerate(CUBE_FACES)]


def _face_sees_sphere(view: View, centre: np.ndarray, radius: float) -> bool:
    """Conservative: the reflector's bounding sphere meets the face's frustum."""
    camera = (view.view_matrix[:3, :3] @ centre + view.view_matrix[:3, 3])
    x, y, z = camera
    tx, ty = 1.0 / view.projection_matrix[0, 0], 1.0 / view.projection_matrix[1, 1]
    depth = -z
    for value, t in ((x, tx), (-x, tx), (y, ty), (-y, ty)):
        if (t * depth - value) / np.hypot(1.0, t) < -radius:
            return False
    return True


@dataclass
class NodeCamera:
    """One grid node: its status and one SBC per cube face (None where the face sees nothing)."""

    status: int
    faces: list  # 6 SampleBasedCamera or None
    seconds: float = 0.0  # wall time of the build
    cpu_seconds: float = 0.0  # CPU time of the building process

    @property
    def nbytes(self) -> int:
        return int(sum(f.stats.get("nbytes", 0) + _ray_map_bytes(f) for f in self.faces if f is not None))


def _ray_map_bytes(sbc: SampleBasedCamera) -> int:
    rm = sbc.ray_map
    return int(sum(getattr(rm, k).nbytes for k in ("cell", "order", "group", "first_point", "first_depth", "tail",
                                                    "direction", "head_distance", "triangle", "blocked")))


def build_node(reflector_set: ReflectorSet, eye, bounds, settings: MorphSettings) -> NodeCamera:
    """The panoramic SBC at one node: an SBC per cube face that sees the reflector."""
    start, cpu = time.perf_counter(), time.process_time()
    lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
    reach = float(np.linalg.norm(hi - lo))
    spacing_scale = reach * 1e-4
    views = cube_face_views(eye, settings, near=spacing_scale, far=2.0 * reach + 1.0)
    try:
        check_view_outside_reflectors(reflector_set, views[0])
    except SceneInputError:
        return NodeCamera(NODE_INSIDE, [None] * 6, time.perf_counter() - start, time.process_time() - cpu)
    # A face whose frustum misses the reflectors' bounding sphere sees no triangle (the
    # box's circumsphere, larger, let through faces with empty ray maps).
    centre, radius = reflector_set.bounding_sphere
    faces = []
    for view in views:
        if not _face_sees_sphere(view, centre, radius):
            faces.append(None)
            continue
        sbc = build_sample_based_camera(reflector_set, view, (lo, hi), max_order=1, downsample=settings.downsample,
                                        accuracy_px=settings.accuracy_px)
        faces.append(sbc if sbc.ray_map.n_rays else None)
    return NodeCamera(NODE_OK, faces, time.perf_counter() - start, time.process_time() - cpu)


def bake_reflector(reflector: Reflector, settings: MorphSettings) -> tuple[ReflectorSet, TetrahedralGrid, tuple]:
    """What every node of one reflector's grid is built from (in the rigid frame).

    Returns the (extended) reflector set, the grid and the box where reflected rays end
    (the grid box grown by one spacing: the patches are fitted over the depths where
    the scene's points lie, and a ray leaving the box is not cut short for points beyond).
    """
    grid = grid_for(reflector, settings)
    return extended_mirror(reflector, settings), grid, (grid.lo - grid.spacing, grid.hi + grid.spacing)


def extended_mirror(reflector: Reflector, settings: MorphSettings) -> ReflectorSet:
    """The reflector with its open edges extended (remedy 1), as every node camera sees it."""
    lo, hi = reflector.bounds
    return ReflectorSet([extend_reflector(reflector, settings.extension * float(np.max(hi - lo)))])


class NodesOnDemand(dict):
    """Node cameras of a grid built on first use, instead of baked: a grid to try a
    reflector with, and what tests and benchmarks measure morphing with (a view only
    ever uses the nodes of its cell: eight). ``cpu_seconds`` sums the builds."""

    def __init__(self, reflector_set: ReflectorSet, positions: np.ndarray, bounds, settings: MorphSettings,
                 build=None):
        super().__init__()
        self.args = reflector_set, positions, bounds, settings
        self.build = build or build_node  # (reflector_set, eye, bounds, settings) -> node
        self.cpu_seconds = 0.0

    def __missing__(self, node) -> NodeCamera:
        reflector_set, positions, bounds, settings = self.args
        self[node] = camera = self.build(reflector_set, positions[int(node)], bounds, settings)
        self.cpu_seconds += camera.cpu_seconds
        return camera


class _StatusOnDemand:
    """Node status of a :class:`NodesOnDemand` grid: known once the node is built."""

    def __init__(self, nodes: NodesOnDemand):
        self.nodes = nodes

    def __getitem__(self, index) -> np.ndarray:
        return np.array([self.nodes[int(n)].status for n in np.atleast_1d(index)], dtype=np.int8)
