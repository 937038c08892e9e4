# SPDX-License-Identifier: GPL-3.0-or-later
"""Reflection morphing: a tetrahedral grid of panoramic sample-based cameras (SBC paper VI).

Popescu, Sacks, Mei (2006), section VI, after Martin & Popescu (2004), who interpolated
the projections of 8 ray octrees trilinearly over a grid cell. A regular 3D grid is
attached to a reflector; every cell is split into 6 tetrahedra; at every grid node a
*panoramic* sample-based camera is built from a cube ray map (six 90-degree faces, each
an ordinary SBC of ``engine/methods/sbc/sbc.py``). At draw time the tetrahedron holding the desired
eye is found, a point is projected with the SBCs of its four nodes, and the four first
reflector points are blended with the eye's barycentric weights; the blended point is
then projected into the desired view. Ours: the blend is refined on a quadric fitted to
the images of every node of the tetrahedron's cube (:mod:`.morph_surface`;
:meth:`MorphingGrid.locate_view`).

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
   polynomial is the first reflector point). Ours, with the scene's *Polish Node
   Images* (:attr:`MorphingGrid.mirror`): the extrapolated image, out to
   ``POLISHED_CHART``, is then polished on the mirror (``image_polish.py``), or dropped
   where the mirror has no reflection near it, and the node's regular images seen at a
   grazing angle are polished too.

Images are matched across nodes by mutually nearest first reflector point (within
``MATCH_FRACTION`` of the reflector's size plus ``MATCH_SLOPE`` times the
nodes' distance) to the image of the heaviest node that has one. A node still without a
matching image is left out and the others' weights are renormalised if they hold at
least ``PARTIAL_WEIGHT`` of the total; below that the image is dropped (its triangles
are not drawn). ``MorphProjection.remedy`` says which case each image took.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from ..sbc.bsp import CAMERA_LEAF, descend_tree, in_band
from .morph_grid import (NODE_OK, MorphSettings, NodesOnDemand, TetrahedralGrid, _StatusOnDemand, bake_reflector,
                         extended_mirror, from_frame, rigid_frame, to_frame)
from .image_polish import FRAME_POLISH_ROUNDS, polish_images, polish_regular
from .morph_surface import POLISHED_RIDGE, QUADRIC_RIDGE, refine_on_local_surface, sphere_prior
from ..sbc.ray_patch import RayPatches, solve_charts
from ..sbc.sbc import SampleBasedCamera
from ...scene import Reflector
from ...view import View

#: Version of everything that shapes a baked grid; part of the cache key.
ENGINE_VERSION = "morphing-2"
#: Camera-leaf charts span [-1, 1]; an extended frustum accepts up to this far out.
EXTENDED_CHART = 1.25
#: ... and this far where its images are polished on the mirror (*Polish Node Images*):
#: the extrapolated patch is only the polish's start there, and the polish drops a start
#: with no reflection near it, so a wider chart only gives more images a start.
POLISHED_CHART = 4.0
#: Images of one point at two nodes match when their reflector points are this close
#: (fraction of the reflector's size), plus ``MATCH_SLOPE`` times the
#: distance between the two nodes, and each is the other's nearest (:func:`_match`).
MATCH_FRACTION = 0.2
#: A reflection point moves by up to about half the eye's move on a convex mirror seen
#: from a few radii (and up to all of it on a flat mirror, the point far). With
#: MATCH_FRACTION alone, the nodes of a tetrahedron 1.5 sphere radii apart missed each
#: other's images: 30 % of the facing reflections of the demo ball had no answer
#: (bench_octree.py's views; 0.5 % with the slope). The tetrahedral grid's slope.
MATCH_SLOPE = 0.5
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


class ViewOutsideGrid(Exception):
    """The desired eye is not in a usable tetrahedron: the caller falls back to runtime mode."""

    def __init__(self, reflector_name: str, reason: str):
        self.reflector_name = reflector_name
        self.reason = reason
        super().__init__(f"{reflector_name!r}: {reason}; using runtime mode")


def grid_on_demand(reflector: Reflector, settings: MorphSettings, reflector_index: int = 0,
                   blend: str = "surface", nodes: NodesOnDemand | None = None, polish: bool = False,
                   grid_class: type | None = None, build=None) -> MorphingGrid:
    """A MorphingGrid of ``reflector`` (in its rigid frame) whose nodes are built when a
    view first needs them (:class:`NodesOnDemand`; pass ``nodes`` to share them between
    grids); ``polish``: the nodes' grazing and extended images are polished on the mirror.
    ``grid_class`` and ``build`` (a node's builder) serve another kind of grid
    (``methods/octree``); by default the tetrahedral grid's."""
    reflector_set, grid, bounds = bake_reflector(reflector, settings)
    if nodes is None:
        nodes = NodesOnDemand(reflector_set, grid.node_positions(), bounds, settings, build=build)
    lo, hi = reflector.bounds
    return (grid_class or MorphingGrid)(reflector.name, reflector_index, grid, settings, _StatusOnDemand(nodes),
                                        nodes, float(np.max(hi - lo)), blend=blend,
                                        mirror=MirrorOnDemand(reflector, settings, reflector_set) if polish else None)


class MirrorOnDemand:
    """The extended mirror the nodes of one grid were built from (``morph_grid.extended_mirror``),
    its BVH built on first use: a baked grid loads without it, and only a node projection
    that polishes needs it."""

    def __init__(self, reflector: Reflector, settings: MorphSettings, mirror=None):
        self.reflector, self.settings, self._mirror = reflector, settings, mirror

    def __call__(self):
        if self._mirror is None:
            self._mirror = extended_mirror(self.reflector, self.settings)
        return self._mirror


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
    nodes: np.ndarray  # (N,) node indices: the tetrahedron's 4, then the rest of its cube outside the mirror
    weights: np.ndarray  # (N,) barycentric weights of the eye (0 past the tetrahedron's nodes)

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
    #: The first nodes of a cell (:meth:`locate_view`) whose images are blended with the
    #: eye's weights: a tetrahedron's four; the cell's other nodes join the surface fit only.
    blend_nodes: ClassVar[int] = 4
    #: "surface" (default): the blend refined on a quadric fitted to the cell's nodes'
    #: reflector points and normals; "linear": the paper's barycentric blend alone.
    blend: str = "surface"
    #: How a node's cube-face SBC projects points: ``(sbc, points) -> (G, P, 3)`` first
    #: reflector points, NaN where not projected. ``None``: ``sbc.project`` in numpy;
    #: the viewport passes the GPU's (``drawing/methods/morph_source.GPUFaceImages``).
    face_images: object = field(default=None, repr=False, compare=False)
    #: The cache fault (``bake_cache.CacheError``) met reading one of its nodes: the grid
    #: is not used again (its reflector is drawn in runtime mode) until loaded anew.
    failure: object = field(default=None, repr=False, compare=False)
    #: ``() -> ReflectorSet``: the mirror the node cameras were built from (frame
    #: coordinates; :class:`MirrorOnDemand`), on which the nodes' grazing and extended
    #: images are polished (the scene's *Polish Node Images*); None: they are used as
    #: the node cameras give them (extended images as the widened charts extrapolate them).
    mirror: object = field(default=None, repr=False, compare=False)
    #: How images are polished on the :attr:`mirror`: ``(mirror, eye, points, images) ->
    #: polished images`` (``image_polish.polish_images``'s signature). ``None``: that
    #: function, in numpy; the viewport passes the GPU's
    #: (``drawing/methods/polish_gpu.GPUImagePolish``).
    image_polish: object = field(default=None, repr=False, compare=False)
    #: Each blended image polished on the :attr:`mirror` from where the blend put it
    #: (:meth:`_polished_blend`; the renderer's twin: ``MorphPass(polish_frames=)``).
    polish_frames: bool = field(default=False, compare=False)
    _static: dict = field(default_factory=dict, repr=False)

    def __post_init__(self):
        if self.blend not in ("surface", "linear"):
            raise ValueError(f"blend must be 'surface' or 'linear', got {self.blend!r}")

    def locate_view(self, eye_world, matrix):
        """Tetrahedron, nodes and weights of the eye, and the frame; raises ViewOutsideGrid
        where unusable. The nodes are the tetrahedron's four (the blend's, SBC paper VI),
        with the eye's barycentric weights, then the other nodes of its cell outside the
        mirror, weighing 0 (:attr:`blend_nodes`): their images join the local surface's
        fit (``morph_surface.refine_on_local_surface``) and nothing else. Four nodes give
        the quadric's nine coefficients 12 equations, three (a node that does not see the
        point) only 9, and the fit would lean on its pull toward a sphere; the cell's
        eight give 24 and 21 (figures: docs/benchmarks/octree.md)."""
        frame = rigid_frame(matrix)
        eye = to_frame(frame, np.asarray(eye_world, dtype=np.float64)[None])
        tet, nodes, weights, inside = self.grid.locate(eye)
        if not inside[0]:
            raise ViewOutsideGrid(self.reflector_name, "the view is outside the morphing grid")
        nodes = nodes[0]
        if np.any(self.node_status[nodes] != NODE_OK):
            raise ViewOutsideGrid(self.reflector_name, "the view's grid cell touches the inside of the mirror")
        fit_only = np.array([n for n in self.grid.cell_nodes(tet[0]) if n not in nodes
                             and self.node_status[n] == NODE_OK], dtype=np.int64)
        return int(tet[0]), np.r_[nodes, fit_only], np.r_[weights[0], np.zeros(len(fit_only))], frame

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
        the cell's nodes' images of these points are kept and reused while the eye stays in
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

    # images at the cell's nodes, matched to one another

    def _node_images(self, node: int, points: np.ndarray, face_images=None, polish=None):
        """(P, K, 3) distinct first reflector points of each point at one node, NaN padded;
        ``face_images`` projects a face (default: the grid's own, numpy where it has none),
        ``polish`` polishes images (default: the grid's :attr:`image_polish`)."""
        return self._polished_regular(node, points, self._camera_images(node, points, face_images), polish)

    def _camera_images(self, node: int, points: np.ndarray, face_images=None):
        """:meth:`_node_images` before the polish."""
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
        return compact_images(images, self._duplicate_tolerance(node, images))

    def _polished_regular(self, node: int, points: np.ndarray, images: np.ndarray, polish=None):
        """A node's regular ``images``, polished on the :attr:`mirror` where the grid has
        one (``image_polish.polish_regular``)."""
        if self.mirror is None:
            return images
        return polish_regular(self.mirror(), self.grid.node_positions()[node], points, images,
                              polish or self.image_polish or polish_images)

    @property
    def quadric_ridge(self) -> float:
        """The pull of the blend's local quadric toward a sphere (``morph_surface``):
        weak where every node image is polished on the mirror (exact but for float
        rounding), :data:`.morph_surface.QUADRIC_RIDGE` where images carry the node
        cameras' interpolation error."""
        return POLISHED_RIDGE if self.mirror is not None else QUADRIC_RIDGE

    @property
    def projects_nodes_on_gpu(self) -> bool:
        """Whether :meth:`node_slots` projects on the GPU by default (``face_images`` set):
        a projection on a thread without the GPU (``project_face``, numpy) then differs
        from it by float32's rounding."""
        return self.face_images is not None

    def node_slots(self, node: int, points: np.ndarray, slots: int, face_images=None, polish=None) -> np.ndarray:
        """(P, 2 slots, 3): the first ``slots`` distinct images of each point (frame
        coordinates) at one node, then the first ``slots`` of its widened charts (remedy
        2), NaN padded. What the GPU blend keeps per node (``drawing/methods/morph_pass.py``):
        everything :meth:`_matched_images` reads of a node, for every point at once, so
        that it serves every tetrahedron the node belongs to. ``face_images`` as for
        :meth:`_node_images` (``project_face``: numpy, for a thread without the GPU), and
        ``polish`` (``image_polish.polish_images``: numpy)."""
        return self.polished_slots(node, points, self.unpolished_images(node, points, face_images), slots, polish)

    def unpolished_images(self, node: int, points: np.ndarray, face_images=None) -> tuple:
        """(regular, widened-chart) images of a node as :meth:`node_slots` finds them,
        before the polish: what a worker thread without the GPU computes of a node
        (``face_images``: ``project_face``), for :meth:`polished_slots` to finish on the
        main thread, on the GPU (:meth:`node_slots` is the two in one). The widened
        charts' repeats of a regular image are dropped against the unpolished regular
        images (the polish moves an image by less than the tolerance)."""
        regular = self._camera_images(node, points, face_images)
        return regular, self._widened_images(node, points, regular)

    def polished_slots(self, node: int, points: np.ndarray, images: tuple, slots: int, polish=None) -> np.ndarray:
        """:meth:`node_slots` of a node's :meth:`unpolished_images`: polished (by
        ``polish``, default the grid's :attr:`image_polish`) where the grid has a
        :attr:`mirror`."""
        regular, extended = images
        parts = [self._polished_regular(node, points, regular, polish),
                 self._polished_extended(node, points, extended, polish)]
        return np.concatenate([pad_images(part[:, :slots], slots) for part in parts], axis=1)

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

    def _extended_images(self, node: int, points: np.ndarray, regular: np.ndarray, polish=None):
        """Remedy 2: reflector points from camera leaves with widened charts, (P, K, 3),
        less those that repeat one of the node's ``regular`` images (P, K', 3) of the same
        points (a widened chart holds its regular one too), polished on the mirror where
        the grid has one (:attr:`mirror`; ``polish`` as for :meth:`_node_images`)."""
        return self._polished_extended(node, points, self._widened_images(node, points, regular), polish)

    def _widened_images(self, node: int, points: np.ndarray, regular: np.ndarray):
        """:meth:`_extended_images` before the polish."""
        camera = self.nodes[node]
        parts = []
        for sbc in camera.faces:
            if sbc is None or sbc.model_name != "ray_patch":
                continue
            for tree in sbc.trees:
                parts.append(_extended_tails(tree, points, EXTENDED_CHART if self.mirror is None else POLISHED_CHART))
        if not parts:
            return np.full((len(points), 0, 3), np.nan)
        images = np.stack(parts, axis=1)
        images = compact_images(images, self._duplicate_tolerance(node, images))
        tolerance = self._duplicate_tolerance(node, images)
        near = np.linalg.norm(images[:, :, None] - regular[:, None], axis=3) <= tolerance[..., None]
        return np.where(near.any(axis=2)[..., None], np.nan, images)

    def _polished_extended(self, node: int, points: np.ndarray, images: np.ndarray, polish=None):
        """Widened-chart ``images`` polished on the :attr:`mirror` where the grid has one
        (those with no reflection near them dropped), compacted."""
        if self.mirror is not None:
            polish = polish or self.image_polish or polish_images
            images = polish(self.mirror(), self.grid.node_positions()[node], points, images)
        return compact_images(images, np.zeros(images.shape[:2]))

    def _matched_images(self, points, nodes, weights):
        """(N, P, K, 3) images matched across the N nodes of the eye's cell (4 for a
        tetrahedron) and (N, P, K) int8 how each was found."""
        images = [self._node_images(int(n), points) for n in nodes]
        k_max = max(im.shape[1] for im in images)
        if k_max == 0:
            return np.full((len(nodes), len(points), 0, 3), np.nan), np.zeros((len(nodes), len(points), 0), np.int8)
        images = np.stack([pad_images(im, k_max) for im in images])  # (N, P, K, 3)
        has = np.isfinite(images[..., 0]).any(axis=2)  # (N, P)
        reference_node = np.argmax(np.where(has, weights[:, None], -1.0), axis=0)  # (P,)
        reference = images[reference_node, np.arange(len(points))]  # (P, K, 3)
        eyes = self.grid.node_positions()[np.asarray(nodes)]
        matched = np.full((len(nodes), len(points), k_max, 3), np.nan)
        how = np.zeros((len(nodes), len(points), k_max), np.int8)
        for n in range(len(nodes)):
            threshold = (MATCH_FRACTION * self.reflector_size
                         + MATCH_SLOPE * np.linalg.norm(eyes[n] - eyes[reference_node], axis=1))[:, None]
            found = _match(reference, images[n], threshold)
            missing = np.isfinite(reference[..., 0]) & ~np.isfinite(found[..., 0])
            rows = np.flatnonzero(missing.any(axis=1))
            how[n] = np.where(np.isfinite(found[..., 0]), ALL_NODES, NOT_PROJECTED)
            # A node that only joins the surface fit is asked for its regular images
            # alone: its widened charts would cost the GPU blend about a sixth more per
            # frame for a few per cent more images.
            if len(rows) and n < self.blend_nodes:
                extended = self._extended_images(int(nodes[n]), points[rows], images[n][rows])
                again = _match(reference[rows], extended, threshold[rows])
                fill = missing[rows] & np.isfinite(again[..., 0])
                found[rows] = np.where(fill[..., None], again, found[rows])
                how[n][rows] = np.where(fill, EXTENDED_FRUSTUM, how[n][rows])
            matched[n] = found
        return matched, how

    def _blend(self, matched, how, weights, frame, points_world, view, tet, nodes) -> MorphProjection:
        n_points, k_max = matched.shape[1], matched.shape[2]
        present = how > 0  # (N, P, K)
        w = np.where(present, weights[:, None, None], 0.0)
        total = w.sum(axis=0)  # (P, K)
        all_present = present[:self.blend_nodes].all(axis=0)
        usable = all_present | (total >= PARTIAL_WEIGHT)
        blended = np.einsum("npk,npkd->pkd", w, np.nan_to_num(matched)) / np.maximum(total, 1e-300)[..., None]
        if k_max:
            eyes = self.grid.node_positions()[np.asarray(nodes)]
            frame_points = to_frame(frame, points_world)
            local_points = np.repeat(frame_points, k_max, axis=0)
            local_eye = to_frame(frame, view.eye[None])[0]
            n_nodes = len(nodes)
            refined, ok, normal, weighted_normal = refine_on_local_surface(
                np.nan_to_num(matched).transpose(1, 2, 0, 3).reshape(-1, n_nodes, 3),
                present.transpose(1, 2, 0).reshape(-1, n_nodes), eyes, local_points, local_eye,
                w.transpose(1, 2, 0).reshape(-1, n_nodes), sphere_prior(self.quadric_ridge))
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
            if self.polish_frames and self.mirror is not None:
                blended, placed = self._polished_blend(local_eye, frame_points, blended, usable)
                usable &= placed
        remedy = np.where(all_present & (how[:self.blend_nodes] == ALL_NODES).all(axis=0), ALL_NODES,
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


    def _polished_blend(self, eye, points, blended, usable):
        """(images, placed) the ``usable`` ``blended`` images (P, K, 3) of ``points`` seen
        from ``eye`` (frame coordinates), polished on the mirror (``image_polish``, up to
        FRAME_POLISH_ROUNDS triangles each): placed where the polish found a reflection
        point, which then lies on the mesh as the reference solver's do."""
        images = np.where(usable[..., None], blended, np.nan)
        polished = polish_images(self.mirror(), eye, points, images, rounds=FRAME_POLISH_ROUNDS)
        placed = np.isfinite(polished[..., 0])
        return np.where(placed[..., None], polished, blended), placed


def project_face(sbc: SampleBasedCamera, points: np.ndarray) -> np.ndarray:
    """(G, P, 3) first reflector points of ``points`` in one face SBC, NaN where not projected.

    Interpolated answers only (``polish=False``): a baked face camera does not keep the
    scene (``sbc_arrays.TRANSIENT``), and the blend is measured on what the cache gives."""
    result = sbc.project(points, polish=False)
    return np.where(result.valid[:, :, None], result.reflector_points, np.nan)


def _extended_tails(tree, points: np.ndarray, chart: float) -> np.ndarray:
    """(P, 3) first reflector point from the camera leaf each point falls in, its chart
    widened to [-chart, chart]."""
    result = np.full((len(points), 3), np.nan)
    leaf = tree.leaf[descend_tree(tree, points)]
    on_camera = np.flatnonzero(tree.leaf_kind[leaf] == CAMERA_LEAF)
    if len(on_camera) == 0 or not isinstance(tree.cameras, RayPatches):
        return result
    p = points[on_camera]
    rows = tree.leaf_row[leaf[on_camera]]
    u, v, s, tail, miss = solve_charts(tree.cameras, rows, p)
    ok = ((miss < 1e-6 * (1 + np.linalg.norm(p, axis=1))) & (np.abs(u) <= chart) & (np.abs(v) <= chart)
          & (s >= 0))
    if tree.camera_band is not None:
        ok &= ~in_band(tree, rows, s)  # where the leaf's rays focus its patch is not trusted
    result[on_camera[ok]] = tail[ok]
    return result


def compact_images(images: np.ndarray, tolerance: np.ndarray) -> np.ndarray:
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


def pad_images(images: np.ndarray, k: int) -> np.ndarray:
    return np.concatenate([images, np.full((images.shape[0], k - images.shape[1], 3), np.nan)], axis=1)


def _match(reference: np.ndarray, candidates: np.ndarray, threshold) -> np.ndarray:
    """For each reference image (P, K, 3), the nearest candidate (P, K', 3) within
    ``threshold`` ((P, 1) or a scalar) whose own nearest reference image it is (mutual
    nearest: on a concave mirror, an image one node lacks is not paired with another)."""
    if candidates.shape[1] == 0:
        return np.full(reference.shape, np.nan)
    distance = np.linalg.norm(reference[:, :, None] - candidates[:, None], axis=3)
    distance = np.where(np.isnan(distance), np.inf, distance)
    best = np.argmin(distance, axis=2)
    chosen = np.take_along_axis(candidates, best[..., None].repeat(3, axis=2), axis=1)
    close = np.take_along_axis(distance, best[..., None], axis=2)[..., 0] <= threshold
    nearest_reference = np.take_along_axis(np.argmin(distance, axis=1), best, axis=1)
    close &= nearest_reference == np.arange(reference.shape[1])[None]
    return np.where(close[..., None], chosen, np.nan)
