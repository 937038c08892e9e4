# SPDX-License-Identifier: GPL-3.0-or-later
"""Reflection morphing: a tetrahedral grid of panoramic sample-based cameras (SBC paper VI).

Popescu, Sacks, Mei (2006), section VI, after Martin & Popescu (2004), who interpolated
the projections of 8 ray octrees trilinearly over a grid cell. A regular 3D grid is
attached to a reflector; every cell is split into 6 tetrahedra; at every grid node a
*panoramic* sample-based camera is built from a cube ray map (six 90-degree faces, each
an ordinary SBC of ``addon/sbc.py``). At draw time the tetrahedron holding the desired
eye is found, a point is projected with the SBCs of its four nodes, and the four first
reflector points are blended with the eye's barycentric weights; the blended point is
then projected into the desired view.

The grid lives in the reflector's *rigid frame* (rotation and translation of its
object matrix, scale kept in the geometry): the reflection law is invariant under rigid
motion, so a moving reflector keeps its grid; points and eye are carried into the frame,
the blended point back out (section VI: "scene vertices are first transformed into the
reflector coordinate system").

Ambiguous points (section VI, Fig. 15): seen by some of the four nodes, not by others.

1. *Extended reflectors while building*: open boundaries of the mirror are extended by
   a strip (``extend_reflector``), so points reflecting just past the real edge from one
   node still project at the others; the draw masks reflections to the real mirror.
   The paper grows the strip in small increments until no ray-map tail or head is
   ambiguous; we use one strip of fixed width (``MorphSettings.extension``).
2. *Extended leaf frustums*: where a node has no image of a point that another node
   sees, its camera leaves are asked again with their chart widened by
   ``EXTENDED_CHART`` (the leaf's ray-field patch extrapolated beyond its rays; its tail
   polynomial is the first reflector point).

Images are matched across nodes by nearest first reflector point (within
``MATCH_FRACTION`` of the reflector's size) to the image of the heaviest node that has
one. A node still without a matching image is left out and the others' weights are
renormalised if they hold at least ``PARTIAL_WEIGHT`` of the total; below that the
image is dropped (its triangles are not drawn). ``MorphProjection.remedy`` says which
case each image took.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .bsp import CAMERA_LEAF
from .errors import SceneInputError
from .ray_patch import RayPatches, solve_charts
from .raytrace import ReflectorSet
from .sbc import SampleBasedCamera, descend_tree, in_band
from .sbc_build import build_sample_based_camera, check_view_outside_reflectors
from .scene import Reflector
from .vectors import cross
from .view import View, look_at_view

#: Version of everything that shapes a baked grid; part of the cache key.
ENGINE_VERSION = "morphing-2"
#: Cube faces: forward and up axes (+X, -X, +Y, -Y, +Z, -Z).
CUBE_FACES = (
    ((1, 0, 0), (0, 0, 1)), ((-1, 0, 0), (0, 0, 1)), ((0, 1, 0), (0, 0, 1)),
    ((0, -1, 0), (0, 0, 1)), ((0, 0, 1), (0, 1, 0)), ((0, 0, -1), (0, 1, 0)),
)
#: The 6 axis orders of the Kuhn (Freudenthal) split of a cube: tetrahedron k holds the
#: points whose local coordinates satisfy f[p0] >= f[p1] >= f[p2] for PERMUTATIONS[k].
PERMUTATIONS = np.array([(0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)])
#: Camera-leaf charts span [-1, 1]; an extended frustum accepts up to this far out.
EXTENDED_CHART = 1.25
#: Images of one point at two nodes match when their reflector points are this close
#: (fraction of the reflector's size).
MATCH_FRACTION = 0.2
#: Images closer than this many cube-face pixels (at their distance from the node), or
#: this fraction of the reflector's size, are one image seen in two overlapping faces.
DUPLICATE_PIXELS = 3.0
DUPLICATE_FRACTION = 1e-3
#: An image missing at some nodes is blended over the others if they weigh this much.
PARTIAL_WEIGHT = 0.5
#: Sets of static points whose node images a grid keeps (one per renderer or mesh set);
#: the oldest is dropped first.
STATIC_SETS = 4
#: remedy codes of MorphProjection
NOT_PROJECTED, ALL_NODES, EXTENDED_FRUSTUM, PARTIAL = 0, 1, 2, 3
#: node status codes
NODE_OK, NODE_INSIDE = 0, 1


class ViewOutsideGrid(Exception):
    """The desired eye is not in a usable tetrahedron: the caller falls back to runtime mode."""

    def __init__(self, reflector_name: str, reason: str):
        self.reflector_name = reflector_name
        self.reason = reason
        super().__init__(f"{reflector_name!r}: {reason}; using runtime mode")


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

    def __post_init__(self):
        grid = tuple(int(n) for n in self.grid)
        if len(grid) != 3 or min(grid) < 2:
            raise SceneInputError("morph_grid", f"needs at least 2 nodes on each axis, got {self.grid}")
        object.__setattr__(self, "grid", grid)
        if not self.margin > 0:
            raise SceneInputError("morph_margin", f"must be positive, got {self.margin}")
        if int(self.face_resolution) // int(self.downsample) < 4:
            raise SceneInputError("morphing", "cube faces need at least 4 ray-map cells a side")

    def as_tuple(self) -> tuple:
        return (self.grid, float(self.margin), int(self.face_resolution), int(self.downsample),
                float(self.accuracy_px), int(self.overlap_cells), float(self.extension))


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
    lo, hi = reflector.bounds
    extended = extend_reflector(reflector, settings.extension * float(np.max(hi - lo)))
    return ReflectorSet([extended]), grid, (grid.lo - grid.spacing, grid.hi + grid.spacing)


class NodesOnDemand(dict):
    """Node cameras of a grid built on first use, instead of baked: a grid to try a
    reflector with, and what tests and benchmarks measure morphing with (a view only
    ever uses the four nodes of its tetrahedron). ``cpu_seconds`` sums the builds."""

    def __init__(self, reflector_set: ReflectorSet, positions: np.ndarray, bounds, settings: MorphSettings):
        super().__init__()
        self.args = reflector_set, positions, bounds, settings
        self.cpu_seconds = 0.0

    def __missing__(self, node) -> NodeCamera:
        reflector_set, positions, bounds, settings = self.args
        self[node] = camera = build_node(reflector_set, positions[int(node)], bounds, settings)
        self.cpu_seconds += camera.cpu_seconds
        return camera


class _StatusOnDemand:
    """Node status of a :class:`NodesOnDemand` grid: known once the node is built."""

    def __init__(self, nodes: NodesOnDemand):
        self.nodes = nodes

    def __getitem__(self, index) -> np.ndarray:
        return np.array([self.nodes[int(n)].status for n in np.atleast_1d(index)], dtype=np.int8)


def grid_on_demand(reflector: Reflector, settings: MorphSettings, reflector_index: int = 0,
                   blend: str = "surface", nodes: NodesOnDemand | None = None) -> MorphingGrid:
    """A MorphingGrid of ``reflector`` (in its rigid frame) whose nodes are built when a
    view first needs them (:class:`NodesOnDemand`; pass ``nodes`` to share them between grids)."""
    reflector_set, grid, bounds = bake_reflector(reflector, settings)
    if nodes is None:
        nodes = NodesOnDemand(reflector_set, grid.node_positions(), bounds, settings)
    lo, hi = reflector.bounds
    return MorphingGrid(reflector.name, reflector_index, grid, settings, _StatusOnDemand(nodes), nodes,
                        float(np.max(hi - lo)), blend=blend)


# --- projection -----------------------------------------------------------------------


@dataclass(frozen=True)
class MorphProjection:
    """Morphed projection of P points: up to K images per point (K = len(groups))."""

    groups: list  # K reflection histories, ((reflector index,), ...)
    reflector_points: np.ndarray  # (K, P, 3) blended first reflector point, world space, NaN where none
    valid: np.ndarray  # (K, P) bool
    pixels: np.ndarray  # (K, P, 2) desired-view pixel
    ray_distance: np.ndarray  # (K, P) distance from the reflector point to the point
    remedy: np.ndarray  # (K, P) int8: NOT_PROJECTED, ALL_NODES, EXTENDED_FRUSTUM or PARTIAL
    tetrahedron: int
    nodes: np.ndarray  # (4,) node indices
    weights: np.ndarray  # (4,) barycentric weights of the eye

    def counts(self) -> dict:
        r = self.remedy[self.valid]
        return {"all_nodes": int((r == ALL_NODES).sum()), "extended_frustum": int((r == EXTENDED_FRUSTUM).sum()),
                "partial": int((r == PARTIAL).sum())}


@dataclass
class MorphingGrid:
    """A baked grid for one reflector: node cameras, the frame, the settings.

    ``nodes`` may be a list of NodeCamera or any object with ``__getitem__`` returning
    them (the cache loads nodes lazily, see ``bake_cache``).
    """

    reflector_name: str
    reflector_index: int
    grid: TetrahedralGrid
    settings: MorphSettings
    node_status: np.ndarray  # (N,) int8
    nodes: object
    reflector_size: float
    #: "surface" (default): the blend refined on a quadratic fitted to the four nodes'
    #: reflector points and normals; "linear": the paper's barycentric blend alone.
    blend: str = "surface"
    #: How a node's cube-face SBC projects points: ``(sbc, points) -> (G, P, 3)`` first
    #: reflector points, NaN where not projected. ``None``: ``sbc.project`` in numpy;
    #: the viewport passes the GPU's (``gpu_shaders/morph_source.GPUFaceImages``).
    face_images: object = field(default=None, repr=False, compare=False)
    #: The cache fault (``bake_cache.CacheError``) met reading one of its nodes: the grid
    #: is not used again (its reflector is drawn in runtime mode) until loaded anew.
    failure: object = field(default=None, repr=False, compare=False)
    _static: dict = field(default_factory=dict, repr=False)

    def __post_init__(self):
        if self.blend not in ("surface", "linear"):
            raise ValueError(f"blend must be 'surface' or 'linear', got {self.blend!r}")

    def locate_view(self, eye_world, matrix):
        """Tetrahedron, nodes and weights of the eye; raises ViewOutsideGrid where unusable."""
        frame = rigid_frame(matrix)
        eye = to_frame(frame, np.asarray(eye_world, dtype=np.float64)[None])
        tet, nodes, weights, inside = self.grid.locate(eye)
        if not inside[0]:
            raise ViewOutsideGrid(self.reflector_name, "the view is outside the morphing grid")
        nodes = nodes[0]
        if np.any(self.node_status[nodes] != NODE_OK):
            raise ViewOutsideGrid(self.reflector_name, "the view's grid cell touches the inside of the mirror")
        return int(tet[0]), nodes, weights[0], frame

    def check_view(self, view: View, matrix=np.eye(4)):
        """:meth:`locate_view` of a desired view; raises ViewOutsideGrid where morphing
        cannot draw it (outside the grid, a cell inside the mirror, an orthographic view)."""
        if not view.is_perspective:
            raise ViewOutsideGrid(self.reflector_name, "morphing needs a perspective view")
        return self.locate_view(view.eye, matrix)

    def project(self, points_world, view: View, matrix=np.eye(4), static_key=None) -> MorphProjection:
        """Morph the projections of world points for the desired ``view``.

        ``matrix`` is the reflector's current object matrix (its rigid part moves the
        grid). With ``static_key`` (a name for one fixed set of points: static vertices),
        the four nodes' images of these points are kept and reused while the eye stays in
        the same tetrahedron and the frame does not move (SBC paper VI); only the blend is
        redone.
        """
        tet, nodes, weights, frame = self.check_view(view, matrix)
        points_world = np.asarray(points_world, dtype=np.float64)
        if static_key is not None and static_key not in self._static and len(self._static) >= STATIC_SETS:
            del self._static[next(iter(self._static))]  # the oldest set of static points
        cached = self._static.get(static_key) if static_key is not None else None
        if cached is not None and cached[0] == tet and np.array_equal(cached[1], frame) \
                and cached[2] == len(points_world):
            matched, remedy_nodes = cached[3], cached[4]
        else:
            points = to_frame(frame, points_world)
            matched, remedy_nodes = self._matched_images(points, nodes, weights)
            if static_key is not None:
                self._static[static_key] = (tet, frame, len(points_world), matched, remedy_nodes)
        return self._blend(matched, remedy_nodes, weights, frame, points_world, view, tet, nodes)

    # images at the four nodes, matched to one another

    def _node_images(self, node: int, points: np.ndarray, face_images=None):
        """(P, K, 3) distinct first reflector points of each point at one node, NaN padded;
        ``face_images`` projects a face (default: the grid's own, numpy where it has none)."""
        camera = self.nodes[node]
        face_images = face_images or self.face_images or project_face
        parts = []
        for sbc in camera.faces:
            if sbc is None:
                continue
            parts.append(face_images(sbc, points))
        if not parts:
            return np.full((len(points), 0, 3), np.nan)
        images = np.concatenate(parts, axis=0).transpose(1, 0, 2)
        return _compact(images, self._duplicate_tolerance(node, images))

    def node_slots(self, node: int, points: np.ndarray, slots: int, face_images=None) -> np.ndarray:
        """(P, 2 slots, 3): the first ``slots`` distinct images of each point (frame
        coordinates) at one node, then the first ``slots`` of its widened charts (remedy
        2), NaN padded. What the GPU blend keeps per node (``gpu_shaders/morph_pass.py``):
        everything :meth:`_matched_images` reads of a node, for every point at once, so
        that it serves every tetrahedron the node belongs to. ``face_images`` as for
        :meth:`_node_images` (``project_face``: numpy, for a thread without the GPU)."""
        parts = [self._node_images(node, points, face_images), self._extended_images(node, points)]
        return np.concatenate([_pad(part[:, :slots], slots) for part in parts], axis=1)

    def _duplicate_tolerance(self, node: int, images: np.ndarray) -> np.ndarray:
        """(P, M): one image seen in two overlapping faces differs by up to about the
        faces' accuracy; DUPLICATE_PIXELS face pixels at its distance, at least
        DUPLICATE_FRACTION of the reflector."""
        settings = self.settings
        cells = settings.face_resolution / settings.downsample
        pixel_angle = 2.0 * (1.0 + (settings.overlap_cells + 0.5) * 2.0 / cells) / settings.face_resolution
        distance = np.linalg.norm(images - self.grid.node_positions()[node], axis=2)
        return np.maximum(DUPLICATE_PIXELS * pixel_angle * np.nan_to_num(distance), DUPLICATE_FRACTION
                          * self.reflector_size)

    def _extended_images(self, node: int, points: np.ndarray):
        """Remedy 2: reflector points from camera leaves with widened charts, (P, K, 3)."""
        camera = self.nodes[node]
        parts = []
        for sbc in camera.faces:
            if sbc is None or sbc.model_name != "ray_patch":
                continue
            for tree in sbc.trees:
                parts.append(_extended_tails(tree, points))
        if not parts:
            return np.full((len(points), 0, 3), np.nan)
        images = np.stack(parts, axis=1)
        return _compact(images, self._duplicate_tolerance(node, images))

    def _matched_images(self, points, nodes, weights):
        """(4, P, K, 3) images matched across the four nodes and (4, P, K) int8 how each was found."""
        images = [self._node_images(int(n), points) for n in nodes]
        k_max = max(im.shape[1] for im in images)
        if k_max == 0:
            return np.full((4, len(points), 0, 3), np.nan), np.zeros((4, len(points), 0), np.int8)
        images = np.stack([_pad(im, k_max) for im in images])  # (4, P, K, 3)
        has = np.isfinite(images[..., 0]).any(axis=2)  # (4, P)
        reference_node = np.argmax(np.where(has, weights[:, None], -1.0), axis=0)  # (P,)
        reference = images[reference_node, np.arange(len(points))]  # (P, K, 3)
        threshold = MATCH_FRACTION * self.reflector_size
        matched = np.full((4, len(points), k_max, 3), np.nan)
        how = np.zeros((4, len(points), k_max), np.int8)
        for n in range(4):
            found = _match(reference, images[n], threshold)
            missing = np.isfinite(reference[..., 0]) & ~np.isfinite(found[..., 0])
            rows = np.flatnonzero(missing.any(axis=1))
            how[n] = np.where(np.isfinite(found[..., 0]), ALL_NODES, NOT_PROJECTED)
            if len(rows):
                extended = self._extended_images(int(nodes[n]), points[rows])
                again = _match(reference[rows], extended, threshold)
                fill = missing[rows] & np.isfinite(again[..., 0])
                found[rows] = np.where(fill[..., None], again, found[rows])
                how[n][rows] = np.where(fill, EXTENDED_FRUSTUM, how[n][rows])
            matched[n] = found
        return matched, how

    def _blend(self, matched, how, weights, frame, points_world, view, tet, nodes) -> MorphProjection:
        n_points, k_max = matched.shape[1], matched.shape[2]
        present = how > 0  # (4, P, K)
        w = np.where(present, weights[:, None, None], 0.0)
        total = w.sum(axis=0)  # (P, K)
        all_present = present.all(axis=0)
        usable = all_present | (total >= PARTIAL_WEIGHT)
        blended = np.einsum("npk,npkd->pkd", w, np.nan_to_num(matched)) / np.maximum(total, 1e-300)[..., None]
        if k_max:
            eyes = self.grid.node_positions()[np.asarray(nodes)]
            local_points = np.repeat(to_frame(frame, points_world), k_max, axis=0)
            local_eye = to_frame(frame, view.eye[None])[0]
            refined, ok, normal, weighted_normal = refine_on_local_surface(
                np.nan_to_num(matched).transpose(1, 2, 0, 3).reshape(-1, 4, 3),
                present.transpose(1, 2, 0).reshape(-1, 4), eyes, local_points, local_eye,
                w.transpose(1, 2, 0).reshape(-1, 4))
            if self.blend == "surface":
                ok = ok.reshape(n_points, k_max)
                blended = np.where(ok[..., None], refined.reshape(n_points, k_max, 3), blended)
                # A partial blend leaves a node out, and is kept only where the surface fit
                # (which needs no weights) succeeded: renormalised weights alone err by many pixels.
                usable &= all_present | ok
            else:
                normal = weighted_normal
            # A reflection is seen from the front of the mirror by both the eye and the
            # point (the blend of images seen by the nodes may lie past the eye's horizon).
            x = blended.reshape(-1, 3)
            front = ((np.einsum("qd,qd->q", normal, local_eye - x) > 0)
                     & (np.einsum("qd,qd->q", normal, local_points - x) > 0))
            usable &= front.reshape(n_points, k_max)
        remedy = np.where(all_present & (how == ALL_NODES).all(axis=0), ALL_NODES,
                          np.where(all_present, EXTENDED_FRUSTUM, PARTIAL)).astype(np.int8)
        world = from_frame(frame, blended.reshape(-1, 3)).reshape(n_points, k_max, 3)
        pixels, depth = view.to_pixels(world.reshape(-1, 3))
        pixels = pixels.reshape(n_points, k_max, 2)
        with np.errstate(invalid="ignore"):
            valid = usable & np.isfinite(pixels).all(axis=2) & (np.abs(depth.reshape(n_points, k_max)) <= 1)
        world[~valid] = np.nan
        pixels[~valid] = np.nan
        remedy[~valid] = NOT_PROJECTED
        distance = np.where(valid, np.linalg.norm(points_world[:, None] - world, axis=2), np.nan)
        return MorphProjection(
            groups=[(self.reflector_index,)] * k_max, reflector_points=world.transpose(1, 0, 2), valid=valid.T,
            pixels=pixels.transpose(1, 0, 2), ray_distance=distance.T, remedy=remedy.T, tetrahedron=tet,
            nodes=np.asarray(nodes), weights=np.asarray(weights))


def project_face(sbc: SampleBasedCamera, points: np.ndarray) -> np.ndarray:
    """(G, P, 3) first reflector points of ``points`` in one face SBC, NaN where not projected.

    Interpolated answers only (``polish=False``): a baked face camera does not keep the
    scene (``sbc_arrays.TRANSIENT``), and the blend is measured on what the cache gives."""
    result = sbc.project(points, polish=False)
    return np.where(result.valid[:, :, None], result.reflector_points, np.nan)


def _extended_tails(tree, points: np.ndarray) -> np.ndarray:
    """(P, 3) first reflector point from the camera leaf each point falls in, chart widened."""
    result = np.full((len(points), 3), np.nan)
    leaf = tree.leaf[descend_tree(tree, points)]
    on_camera = np.flatnonzero(tree.leaf_kind[leaf] == CAMERA_LEAF)
    if len(on_camera) == 0 or not isinstance(tree.cameras, RayPatches):
        return result
    p = points[on_camera]
    rows = tree.leaf_row[leaf[on_camera]]
    u, v, s, tail, miss = solve_charts(tree.cameras, rows, p)
    ok = ((miss < 1e-6 * (1 + np.linalg.norm(p, axis=1))) & (np.abs(u) <= EXTENDED_CHART)
          & (np.abs(v) <= EXTENDED_CHART) & (s >= 0))
    if tree.camera_band is not None:
        ok &= ~in_band(tree, rows, s)  # where the leaf's rays focus its patch is not trusted
    result[on_camera[ok]] = tail[ok]
    return result


def _compact(images: np.ndarray, tolerance: np.ndarray) -> np.ndarray:
    """(P, M, 3) with NaN rows -> (P, K, 3): valid images first, duplicates (closer than
    ``tolerance`` (P, M) to an earlier image) removed."""
    valid = np.isfinite(images[..., 0])
    for m in range(1, images.shape[1]):
        earlier = np.linalg.norm(images[:, :m] - images[:, m:m + 1], axis=2) <= tolerance[:, m:m + 1]
        duplicate = valid[:, m] & (earlier & valid[:, :m]).any(axis=1)
        valid[:, m] &= ~duplicate
    order = np.argsort(~valid, axis=1, kind="stable")
    k = int(valid.sum(axis=1).max()) if len(images) else 0
    out = np.take_along_axis(images, order[:, :k, None], axis=1)
    keep = np.take_along_axis(valid, order[:, :k], axis=1)
    return np.where(keep[..., None], out, np.nan)


def _pad(images: np.ndarray, k: int) -> np.ndarray:
    return np.concatenate([images, np.full((images.shape[0], k - images.shape[1], 3), np.nan)], axis=1)


def _match(reference: np.ndarray, candidates: np.ndarray, threshold: float) -> np.ndarray:
    """For each reference image (P, K, 3), the nearest candidate (P, K', 3) within ``threshold``."""
    if candidates.shape[1] == 0:
        return np.full(reference.shape, np.nan)
    distance = np.linalg.norm(reference[:, :, None] - candidates[:, None], axis=3)
    distance = np.where(np.isnan(distance), np.inf, distance)
    best = np.argmin(distance, axis=2)
    chosen = np.take_along_axis(candidates, best[..., None].repeat(3, axis=2), axis=1)
    close = np.take_along_axis(distance, best[..., None], axis=2)[..., 0] <= threshold
    return np.where(close[..., None], chosen, np.nan)


#: Nodes with an image (and a usable normal) a local surface is fitted to, at least.
MIN_SURFACE_NODES = 3
#: Newton iterations of the reflection law on the local quadratic surface.
SURFACE_ITERATIONS = 8
#: The refined point may lie this far (in units of the nodes' images' spread) from the blend.
SURFACE_REACH = 2.0
#: A node's image joins the surface fit where its normal is within about 78 degrees of
#: the nodes' weighted normal (cosine above this).
SURFACE_NORMAL_MIN = 0.2


def refine_on_local_surface(images, present, eyes, points, eye, weights):
    """The reflection point of ``eye`` on a quadratic fitted to the nodes' images.

    Our refinement of the paper's blend (SBC VI blends the four first reflector points
    linearly, an error quadratic in the grid spacing). Each node's image x_i of point p
    seen from node eye n_i comes with the mirror normal there: by the law of reflection
    it bisects the directions to n_i and to p. Around the blend, in the frame of the
    blended normal, a height field h(a, b) = c0 + c1 a + c2 b + c3 a^2/2 + c4 ab + c5 b^2/2
    is fitted (least squares) to the images' heights and slopes (3 equations per node),
    and Newton's method finds the point of that surface where its normal bisects the
    directions to the desired eye and to p. The result is exact for a quadratic mirror
    and third order in the spread of the images elsewhere. Needs MIN_SURFACE_NODES nodes
    (two give as many equations as unknowns: measured, their fits are often wrong);
    where it fails or leaves the images' neighbourhood, ``ok`` is False.

    images (Q, 4, 3), present (Q, 4) bool, eyes (4, 3) node positions, points (Q, 3),
    eye (3,), weights (Q, 4) (zero where absent). Returns (Q, 3) points, (Q,) ok, (Q, 3) the
    mirror normal there (fitted where ok, else the weighted one) and (Q, 3) the weighted
    normal of the images (the normal at the linear blend).
    """
    q = len(images)
    total = np.maximum(weights.sum(axis=1), 1e-300)
    origin = np.einsum("qn,qnd->qd", weights, images) / total[:, None]
    to_eye = _unit(eyes[None] - images)
    to_point = _unit(points[:, None] - images)
    normals = _unit(to_eye + to_point)
    normal = _unit(np.einsum("qn,qnd->qd", weights, normals))
    nz = np.einsum("qnd,qd->qn", normals, normal)
    usable = present & (nz > SURFACE_NORMAL_MIN)
    x, ok, fitted_normal = origin.copy(), np.zeros(q, bool), normal.copy()
    # Only rows with enough usable nodes are fitted (a point's empty image slots and
    # images seen by too few nodes are most rows of a drawn mesh's projection).
    rows = np.flatnonzero(usable.sum(axis=1) >= MIN_SURFACE_NODES)
    if len(rows):
        x[rows], ok[rows], fitted_normal[rows] = _fit_and_reflect(
            images[rows], present[rows], usable[rows], normals[rows], normal[rows], nz[rows], origin[rows],
            points[rows], eye)
    # Where the fit is not used, the weighted normal of the nodes' images stands for the
    # mirror's normal at the linear blend.
    return x, ok, np.where(ok[:, None], fitted_normal, normal), normal


def _fit_and_reflect(images, present, usable, normals, normal, nz, origin, points, eye):
    """:func:`refine_on_local_surface` for rows that have enough usable nodes: the
    height-field fit and Newton on it; returns (x, ok, fitted normal). Newton runs on the
    rows not yet converged only."""
    q = len(images)
    helper = np.where(np.abs(normal[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    t1 = _unit(cross(normal, helper))
    t2 = cross(normal, t1)
    offset = images - origin[:, None]
    a, b, h = (np.einsum("qnd,qd->qn", offset, axis) for axis in (t1, t2, normal))
    spread = np.maximum(np.sqrt(np.max(np.where(present, a * a + b * b, 0.0), axis=1)), 1e-12)
    a, b, h = a / spread[:, None], b / spread[:, None], h / spread[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        slope_a = -np.einsum("qnd,qd->qn", normals, t1) / nz
        slope_b = -np.einsum("qnd,qd->qn", normals, t2) / nz
    zero, one = np.zeros_like(a), np.ones_like(a)
    rows = np.concatenate([
        np.stack([one, a, b, 0.5 * a * a, a * b, 0.5 * b * b], axis=2),
        np.stack([zero, one, zero, a, b, zero], axis=2),
        np.stack([zero, zero, one, zero, a, b], axis=2)], axis=1)  # (Q, 12, 6)
    rhs = np.concatenate([h, slope_a, slope_b], axis=1)
    mask = np.tile(usable, 3).astype(np.float64)
    rows, rhs = rows * mask[..., None], np.nan_to_num(rhs) * mask
    normal_matrix = np.einsum("qri,qrj->qij", rows, rows) + 1e-10 * np.eye(6)
    coefficients = np.linalg.solve(normal_matrix, np.einsum("qri,qr->qi", rows, rhs)[..., None])[..., 0]

    def surface(k, u, v):
        c = coefficients[k]
        height = c[:, 0] + c[:, 1] * u + c[:, 2] * v + 0.5 * c[:, 3] * u * u + c[:, 4] * u * v + 0.5 * c[:, 5] * v * v
        du = c[:, 1] + c[:, 3] * u + c[:, 4] * v
        dv = c[:, 2] + c[:, 4] * u + c[:, 5] * v
        x = origin[k] + spread[k, None] * (u[:, None] * t1[k] + v[:, None] * t2[k] + height[:, None] * normal[k])
        return x, t1[k] + du[:, None] * normal[k], t2[k] + dv[:, None] * normal[k]

    def residual(k, u, v):
        x, ta, tb = surface(k, u, v)
        bisector = _unit(eye[None] - x) + _unit(points[k] - x)
        return np.stack([np.einsum("qd,qd->q", bisector, ta), np.einsum("qd,qd->q", bisector, tb)], axis=1)

    u, v = np.zeros(q), np.zeros(q)
    active = np.arange(q)
    step = 1e-6
    for _ in range(SURFACE_ITERATIONS):
        ua, va = u[active], v[active]
        f = residual(active, ua, va)
        ju = (residual(active, ua + step, va) - f) / step
        jv = (residual(active, ua, va + step) - f) / step
        det = ju[:, 0] * jv[:, 1] - jv[:, 0] * ju[:, 1]
        det = np.where(np.abs(det) > 1e-300, det, 1e-300)
        du = (f[:, 0] * jv[:, 1] - jv[:, 0] * f[:, 1]) / det
        dv = (ju[:, 0] * f[:, 1] - f[:, 0] * ju[:, 1]) / det
        u[active], v[active] = np.clip(ua - du, -4.0, 4.0), np.clip(va - dv, -4.0, 4.0)
        # A step below 1e-13 (in units of the images' spread) changes nothing further.
        active = active[~((np.abs(du) < 1e-13) & (np.abs(dv) < 1e-13))]
        if len(active) == 0:
            break
    every = np.arange(q)
    x, ta, tb = surface(every, u, v)
    fitted_normal = _unit(cross(ta, tb))
    fitted_normal *= np.where(np.einsum("qd,qd->q", fitted_normal, normal) < 0, -1.0, 1.0)[:, None]
    ok = ((np.abs(residual(every, u, v)).max(axis=1) < 1e-8) & (u * u + v * v <= SURFACE_REACH ** 2)
          & np.isfinite(x).all(axis=1))
    return x, ok, fitted_normal


def _unit(v):
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)
