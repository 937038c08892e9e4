# SPDX-License-Identifier: GPL-3.0-or-later
"""Reflection morphing with ray octrees (Martin & Popescu 2004, sections 3 and 6).

A regular grid of *sampling locations* around the reflector, a ray octree at each
(:mod:`.node`, :mod:`.ray_octree`); a desired eye inside a *sampling cell* sees a point
where the trilinear blend of the eight locations' first reflector points lies (MORPH_VERTEX,
section 6). The grid, its rigid frame, the matching of images across nodes, the
renderer's GPU pass and the bake cache are those of the tetrahedral grid (SBC paper VI,
:mod:`..morphing`), which succeeded this method: only the cell (a cube of eight nodes, not a
tetrahedron of four), the weights (trilinear, not barycentric) and what a node holds differ.
Like the tetrahedral grid, the blend is refined on the quadric surface fitted to the
eight images (``morph_surface``): the paper's blend alone errs quadratically in the cell size.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..morphing.morph_grid import CELL_CORNERS, NODE_OK, OCTREE, MorphSettings, NodesOnDemand, rigid_frame, to_frame
from ..morphing.morph_surface import QUADRIC_RIDGE
from ..morphing.morphing import MorphingGrid, ViewOutsideGrid, compact_images, grid_on_demand
from ...scene import Reflector
from .node import build_octree_node

#: Images a node keeps of one point (a convex mirror shows it once, a concave one more).
IMAGES = 3


def locate_cell(grid, point):
    """The cell of ``grid`` holding ``point``: (cell id, its 8 nodes, their trilinear
    weights, whether the point is inside the grid)."""
    shape = np.asarray(grid.shape)
    f = (np.asarray(point, dtype=np.float64) - grid.lo) / grid.spacing
    tolerance = 1e-9 * shape
    inside = bool(np.all((f >= -tolerance) & (f <= shape - 1 + tolerance)))
    cell = np.clip(np.floor(f).astype(np.int64), 0, shape - 2)
    local = np.clip(f - cell, 0.0, 1.0)
    weights = np.prod(np.where(CELL_CORNERS == 1, local, 1.0 - local), axis=1)
    nodes = grid.node_index(cell + CELL_CORNERS)
    cell_id = int(cell[0] + (shape[0] - 1) * (cell[1] + (shape[1] - 1) * cell[2]))
    return cell_id, nodes, weights, inside


class OctreeGrid(MorphingGrid):
    """A baked (or on-demand) grid of ray octrees for one reflector: the interface of
    :class:`..morphing.morphing.MorphingGrid` (``project``, ``check_view``, ``node_slots``), which
    the renderer's GPU pass and the operators use for both kinds of grid."""

    #: A cube's eight nodes are all blended, with the eye's trilinear weights.
    blend_nodes = 8

    @property
    def quadric_ridge(self) -> float:
        """A ray octree's images are traced, never polished (:meth:`_polished_regular`),
        each within ``ray_octree.CONVERGED`` of the law: the fit keeps the stronger pull
        toward a sphere, :data:`..morphing.morph_surface.QUADRIC_RIDGE`, to damp that error."""
        return QUADRIC_RIDGE

    def locate_view(self, eye_world, matrix):
        """Cell, its eight nodes and the eye's trilinear weights; ViewOutsideGrid where unusable."""
        frame = rigid_frame(matrix)
        eye = to_frame(frame, np.asarray(eye_world, dtype=np.float64)[None])[0]
        cell, nodes, weights, inside = locate_cell(self.grid, eye)
        if not inside:
            raise ViewOutsideGrid(self.reflector_name, "the view is outside the octree grid")
        if np.any(self.node_status[nodes] != NODE_OK):
            raise ViewOutsideGrid(self.reflector_name, "the view's grid cell touches the inside of the mirror")
        return cell, nodes, weights, frame

    @property
    def projects_nodes_on_gpu(self) -> bool:
        """Ray octrees project in numpy on any thread (``face_images`` is unused)."""
        return False

    def _camera_images(self, node: int, points: np.ndarray, face_images=None):
        """(P, K, 3) distinct first reflector points of each point at one node (its ray
        octree, whose images are traced and never polished: ``face_images`` is the
        tetrahedral grid's and unused here)."""
        images = self.nodes[node].octree.images(points, IMAGES)
        return compact_images(images, self._duplicate_tolerance(node, images))

    def _polished_regular(self, node: int, points: np.ndarray, images: np.ndarray, polish=None):
        """A ray octree's regular images are traced (its refinement stops within
        ``ray_octree.CONVERGED`` of the law): the polish has nothing to move."""
        return images

    def _widened_images(self, node: int, points: np.ndarray, regular: np.ndarray):
        """Remedy 2 of a ray octree, which has no leaf charts to widen: where a point has
        no image at this node, the mirror point of its nearest ray
        (``RayOctree.near_misses``), for :meth:`_polished_extended` to place on the mirror
        (*Polish Node Images*); none where the grid has no mirror to polish on."""
        if self.mirror is None:
            return np.full((len(points), 0, 3), np.nan)
        missing = ~np.isfinite(regular[..., 0]).any(axis=1)
        images = np.full((len(points), 1, 3), np.nan)
        images[missing, 0] = self.nodes[node].octree.near_misses(points[missing])
        return images


def octree_grid_on_demand(reflector: Reflector, settings: MorphSettings, reflector_index: int = 0,
                          blend: str = "surface", nodes: NodesOnDemand | None = None,
                          polish: bool = False) -> OctreeGrid:
    """An :class:`OctreeGrid` of ``reflector`` (in its rigid frame) whose nodes are built
    when a view first needs them (tests, benchmarks, trying a reflector); ``blend``,
    ``nodes`` and ``polish`` as for ``morphing.grid_on_demand``."""
    return grid_on_demand(reflector, dataclasses.replace(settings, kind=OCTREE), reflector_index, blend=blend,
                          nodes=nodes, polish=polish, grid_class=OctreeGrid, build=build_octree_node)
