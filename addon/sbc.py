# SPDX-License-Identifier: GPL-3.0-or-later
"""Sample-based cameras: where does a 3D point appear, reflected, in this view?

Popescu, Sacks, Mei (2006). The reflected rays of the desired view (ray map, section
III-B) are split into reflection groups by history, and a group further by the smooth
pieces of its mirrors (``surface_sets``: across a sharp edge the rays jump); each gets
a BSP tree of leaf cameras (section IV). A point is projected in every tree: it
descends to a leaf, the leaf's model gives the ray-map position (u, v) of the ray
through the point, and the first reflector point is the point on the desired view ray of
(u, v) at the ray map's (interpolated) first-hit depth.

A projection is accepted where the four rays around (u, v) exist in the group (the
point reflects inside the reflector's footprint, not across its silhouette) and the
point lies on their interpolated ray: in front of the mirror, and before the next
reflector where one of the four rays meets one. Where the ray field folds over (a
caustic crosses the cell: FoldCells), the answer is solved again on traced sub-rays.

``leaf_model="ray_patch"`` (default) uses our ray-field patches; ``"pinhole"`` the
paper's pinhole cameras, kept as the baseline.
"""

from __future__ import annotations

import functools
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from .bsp import (CAMERA_LEAF, CONE_SIZE, MAX_DUPLICATION, RAY_LIST_LEAF, BSPTree, RaysCrossError, build_bsp,
                  in_cones, neighbour_spacing)
from .errors import SceneInputError
from .pinhole import PinholeLeaves
from .projection import Projection
from .ray_patch import RayPatches, RayPatchLeaves, invert_patches
from .raymap import RayMap, box_exit_distance, trace_ray_map
from .raytrace import ReflectorSet, reflect, reflection_valid
from .segments import expand_ranges
from .true_rays import polish_on_true_rays
from .vectors import cross
from .view import View

LEAF_MODELS = {"ray_patch": RayPatchLeaves(), "pinhole": PinholeLeaves()}
#: Tolerance (cell units) for a ray-list cell's bilinear coordinates.
CELL_TOLERANCE = 1e-6
#: A projected point may lie off the ray map's interpolated ray by this many cell spacings.
MISS_CELLS = 1.0
#: Threads that project parts of the points at once, and the fewest points per thread.
PROJECT_THREADS = 4
THREAD_MIN_POINTS = 16384
#: Points projected together: small enough that each step's temporaries stay in the cache.
PROJECT_BLOCK = 16384
#: Groups of at most this many rays are never split into sheets.
MIN_SHEET_RAYS = 64
#: Sub-rays per side traced in each *mixed* cell (see MixedCells).
SUBCELL_SAMPLES = 8
#: Ray-list cells tried per point, nearest central ray first.
CANDIDATE_CELLS = 3
#: The same for the ray list of a banded camera leaf (bsp._depth_bands), whose cells are
#: many and whose band lies where its rays cross, so several centre rays pass close.
BAND_CANDIDATES = 8
#: Camera answers up to this many cells past their leaf's rays, across a sharp edge of
#: the mirror, are polished on the true rays (SampleBasedCamera._across_edge).
EDGE_REACH_CELLS = 1.0
#: Sub-cells per side traced in each *fold* cell (see FoldCells).
FOLD_SAMPLES = 8
#: Fold sub-cells tried per point, nearest central ray first.
FOLD_CANDIDATES = 16
#: Corner triangles of a cell (corners 00, 10, 01, 11) whose orientation decides a fold.
FOLD_TRIANGLES = ((0, 1, 2), (1, 3, 0), (3, 2, 1), (2, 0, 3))


@dataclass(frozen=True)
class MixedCells:
    """Sub-cell occlusion of one group's *mixed* cells.

    In a cell whose four corner rays end partly on another reflector (blocked) and
    partly where they leave the scene box, the occluder's silhouette crosses the cell
    and the bilinear head is meaningless: it would accept points behind the occluder
    and refuse points beside it. There, SUBCELL_SAMPLES^2 in-between rays (the same
    bilinear interpolation of the corner rays that projection uses) are traced at build
    time; a point projected into the cell is limited by the head of the sub-ray nearest
    its fractional cell (no limit where that sub-ray leaves the box). A table, not a
    trace, so the GLSL twin reads the same answer from a texture.
    """

    index: np.ndarray  # (rows, columns) int: row in ``heads`` of the cell (i, j) = [j, i], -1 if not mixed
    heads: np.ndarray  # (n_mixed, M, M) float: head distance of sub-ray [b, a] at ((a + .5)/M, (b + .5)/M), inf unblocked

    @property
    def nbytes(self) -> int:
        return int(self.index.nbytes + self.heads.nbytes)


@dataclass(frozen=True)
class FoldCells:
    """True in-between rays of one group's *fold* cells.

    Near a caustic the reflected rays cross: along some cells the four corner rays fold
    over between the tail and the head (one of the cell's corner triangles changes
    orientation), so the bilinear ray patch sweeps space that no true ray reaches and
    answers points with false images, or puts true ones pixels off. In those cells
    (SBC paper section IV-C, ray-list leaves interpolate the unit frustum: here a finer
    one) (FOLD_SAMPLES + 1)^2 view rays through the cell are traced and reflected at
    build time, and an answer that falls in a fold cell is solved again on the
    FOLD_SAMPLES^2 bilinear sub-cells of those rays, as ray-list cells are: no
    sub-cell holds the point, no image. Sub-cell patches are charted in sub-cell units:
    ``patches.lo`` is FOLD_SAMPLES times the ray-map cell of the sub-cell's corner.
    """

    index: np.ndarray  # (rows, columns) int: fold number of cell (i, j) = [j, i], -1 if not a fold cell
    patches: RayPatches  # bilinear, FOLD_SAMPLES^2 rows per fold cell, row-major [b][a]
    valid: np.ndarray  # (n_fold * FOLD_SAMPLES^2,) bool: the sub-cell's four rays hit the group's reflector

    @property
    def nbytes(self) -> int:
        return int(self.index.nbytes + self.patches.nbytes + self.valid.nbytes)


@dataclass
class SampleBasedCamera:
    """One view's sample-based camera: a ray map and one BSP tree per reflection group."""

    ray_map: RayMap
    trees: list
    grids: list
    model_name: str
    histories: list  # one reflection history per tree (a history repeats once per sheet)
    stats: dict = field(default_factory=dict)
    #: (trees, CONE_SIZE) per tree, a cone around where its rays can project (bsp.ray_cones), or None.
    cones: np.ndarray | None = None
    #: Per tree, its group's MixedCells (shared by the sheets of a group), or None where not traced.
    mixed: list | None = None
    #: Per tree, its group's FoldCells (shared by the sheets of a group), or None where not traced.
    folds: list | None = None
    #: The reflectors, where first-order answers of ray-list leaves and fold cells are
    #: polished on the true reflected rays (true_rays.py); None: answers as interpolated.
    true_rays: ReflectorSet | None = None
    #: (trees, 4) per tree, the ray-map cells its sheet owns, lo <= cell < hi as
    #: (lo u, lo v, hi u, hi v) (``_build_sheets``); None: each tree owns every cell.
    owned: np.ndarray | None = None
    #: Per tree, the surface histories (indices into ``ray_map.surfaces``) whose rays it
    #: holds (``surface_sets``), or None for all of its group's; None: all trees hold all.
    surfaces: list | None = None

    @property
    def groups(self) -> list:
        return list(self.histories)

    def project(self, points, polish: bool = True) -> Projection:
        """Project world points (P, 3) in every group. With ``polish`` (and ``true_rays``
        set), first-order answers of ray-list leaves and fold cells are polished on the
        true reflected rays (``true_rays.polish_on_true_rays``); without, every answer is
        the interpolated one (what the GLSL twin computes)."""
        points = np.asarray(points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3:
            raise ValueError(f"points must be a (P, 3) array, got shape {points.shape}")
        n_groups, n_points = len(self.trees), len(points)
        result = Projection(
            groups=self.groups,
            reflector_points=np.full((n_groups, n_points, 3), np.nan),
            valid=np.zeros((n_groups, n_points), dtype=bool),
            leaf_kind=np.zeros((n_groups, n_points), dtype=np.int8),
            pixels=np.full((n_groups, n_points, 2), np.nan),
            ray_distance=np.full((n_groups, n_points), np.nan),
        )
        finite = np.flatnonzero(np.isfinite(points).all(axis=1))
        # numpy releases the GIL inside its array operations, so parts of the points
        # project in parallel on threads; each part writes its own rows of the result.
        workers = min(PROJECT_THREADS, os.cpu_count() or 1, max(1, len(finite) // THREAD_MIN_POINTS))
        parts = np.array_split(finite, max(1, -(-len(finite) // PROJECT_BLOCK)))
        # Risky answers to polish, collected over every block and polished together at the
        # end: a traced batch costs about as much for a few rays as for thousands.
        pending = [] if (polish and self.true_rays is not None) else None
        if workers == 1:
            for part in parts:
                self._project_points(points, part, result, pending)
        else:
            with ThreadPoolExecutor(workers) as pool:
                list(pool.map(lambda part: self._project_points(points, part, result, pending), parts))
        if pending:
            self._polish_pending(pending, points, result)
        return result

    def _polish_pending(self, pending: list, points, result: Projection) -> None:
        """Polish the risky answers of every group (``_polish``) and write them into ``result``."""
        for g in sorted({entry[0] for entry in pending}):
            target, pixels, reflector_points, s, kind, spacing, edge = (
                np.concatenate(column) for column in zip(*(entry[1:] for entry in pending if entry[0] == g)))
            keep = self._polish(g, np.arange(len(target)), pixels, reflector_points, s, points[target], spacing)
            if self.owned is not None:
                # Polished from a seed, an image across an edge may come to rest in another sheet's cells.
                keep[edge] &= self._owns(g, pixels[edge] / self.ray_map.downsample - 0.5)
            # Answers across an edge were never checked against the rays' heads: the
            # reflected segment must reach the point past every reflector.
            check = np.flatnonzero(edge & keep)
            if len(check):
                offset = points[target[check]] - reflector_points[check]
                length = _norm(offset)
                keep[check] = ~self.true_rays.occluded(reflector_points[check], offset / length[:, None], length)
            result.reflector_points[g, target] = np.where(keep[:, None], reflector_points, np.nan)
            result.pixels[g, target] = np.where(keep[:, None], pixels, np.nan)
            result.ray_distance[g, target] = np.where(keep, s, np.nan)
            result.valid[g, target] = keep
            result.leaf_kind[g, target] = np.where(keep, kind, 0)

    def _project_points(self, points, index, result: Projection, pending: list | None):
        points = points[index]
        for g, (tree, grid) in enumerate(zip(self.trees, self.grids)):
            chosen = self._sheet_points(g, points, index)
            if len(chosen):
                self._project_group(g, tree, grid, points[chosen], index[chosen], result, pending)

    def _sheet_points(self, g: int, points, index) -> np.ndarray:
        """Which of ``points`` (rows ``index`` of the points ``project`` was given) descend
        tree ``g``: those in the sheet's bounding cone (bsp.ray_cones)."""
        if self.cones is None:
            return np.arange(len(points))
        return np.flatnonzero(in_cones(np.broadcast_to(self.cones[g], (len(points), CONE_SIZE)), points))

    def _project_group(self, g, tree: BSPTree, grid, points, point_index, result: Projection, pending):
        leaf = tree.leaf[descend_tree(tree, points)]
        if tree.leaf_cones is not None:
            # Points outside their leaf's bounding cone cannot project there (bsp.ray_cones).
            near = np.flatnonzero(in_cones(tree.leaf_cones[leaf], points))
            leaf, points, point_index = leaf[near], points[near], point_index[near]
        kind = tree.leaf_kind[leaf]
        row = tree.leaf_row[leaf]
        cells = np.full((len(points), 2), np.nan)
        accepted = np.zeros(len(points), dtype=bool)

        folds = self.folds[g] if self.folds is not None and len(self.folds[g].valid) else None

        on_camera = np.flatnonzero(kind == CAMERA_LEAF)
        edges = pending is not None and self._has_edges(g)
        seeded = np.zeros(0, dtype=np.int64)  # ray-list answers to seed from the rays along an edge
        near_edge = []  # (indices, ray distances) of answers that may lie just across a sharp edge
        if len(on_camera):
            model = LEAF_MODELS[self.model_name]
            cells[on_camera], accepted[on_camera], distance = model.project(
                tree.cameras, row[on_camera], points[on_camera], self.ray_map)
            banded = distance is not None and tree.leaf_fallback is not None
            handed = (to_fallback(tree, leaf[on_camera], row[on_camera], distance) if banded
                      else np.zeros(len(on_camera), dtype=bool))
            accepted[on_camera[handed]] = False  # not refined in fold cells: the ray list answers
            if folds is not None:
                projected = accepted[on_camera]
                accepted = _refine_in_folds(folds, cells, accepted, points)
                if banded:
                    # A fold cell refines only an answer already in the right cell, which
                    # the leaf's cells, exact at their rays, give where the patch may be a hair off.
                    handed |= (tree.leaf_fallback[leaf[on_camera]] >= 0) & projected & ~accepted[on_camera]
            to_list = on_camera[handed]
            kind[to_list], row[to_list] = RAY_LIST_LEAF, tree.leaf_fallback[leaf[to_list]]
            if edges and distance is not None:
                own = np.flatnonzero(kind[on_camera] == CAMERA_LEAF)
                leaf_row = row[on_camera[own]]
                with np.errstate(invalid="ignore"):
                    near = (np.all(cells[on_camera[own]] >= tree.cameras.lo[leaf_row] - EDGE_REACH_CELLS, axis=1)
                            & np.all(cells[on_camera[own]] <= tree.cameras.hi[leaf_row] + EDGE_REACH_CELLS, axis=1))
                near_edge.append((on_camera[own[near]], distance[own[near]]))
        on_list = np.flatnonzero(kind == RAY_LIST_LEAF)
        if len(on_list) and tree.cells is not None:
            # A banded leaf's ray list holds a camera leaf's many cells: more candidates.
            keep = np.where(tree.leaf_kind[leaf[on_list]] == CAMERA_LEAF, BAND_CANDIDATES, CANDIDATE_CELLS)
            cells[on_list], accepted[on_list], list_distance = _project_ray_lists(
                tree, row[on_list], points[on_list], keep, EDGE_REACH_CELLS if edges else 0.0)
            if edges:
                unheld = np.flatnonzero(~accepted[on_list])
                near_edge.append((on_list[unheld], list_distance[unheld]))
                seeded = on_list[unheld]
            if folds is not None:
                listed = np.zeros(len(points), dtype=bool)
                listed[on_list] = accepted[on_list]
                accepted[on_list] = _refine_in_folds(folds, cells, listed, points)[on_list]
        edge, edge_distance = np.zeros(0, dtype=np.int64), np.zeros(0)  # answers across a sharp edge
        if near_edge:
            index, ray_distance = (np.concatenate(column) for column in zip(*near_edge))
            across = self._across_edge(g, cells[index], ray_distance)
            edge, edge_distance = index[across], ray_distance[across]
            accepted[edge] = False
            seeded = np.setdiff1d(seeded, edge)
            if len(seeded) and tree.list_rays is not None:
                # No cell of the ray list holds the point, nor reaches it across the edge:
                # its rays along the edge seed it.
                seed_cells, seed_distance = _edge_seeds(self.ray_map, tree, row[seeded], points[seeded],
                                                        self._edge_rays[g], self._ray_spacing[g])
                reached = np.flatnonzero(np.isfinite(seed_distance))
                cells[seeded[reached]] = seed_cells[reached]
                edge = np.concatenate([edge, seeded[reached]])
                edge_distance = np.concatenate([edge_distance, seed_distance[reached]])
        if self.owned is not None:
            # Next to a seam both sheets' leaves reach half a cell over it: the answer counts
            # in the sheet owning its cell only, so one image is not answered twice.
            accepted &= self._owns(g, cells)
            owned_edge = self._owns(g, cells[edge])
            edge, edge_distance = edge[owned_edge], edge_distance[owned_edge]
        if len(edge):
            # Answers across a sharp edge of the mirror are found on the true rays only.
            pixels = self.ray_map.cell_pixels(cells[edge])
            pending.append((g, point_index[edge], pixels, np.full((len(edge), 3), np.nan), edge_distance,
                            kind[edge], np.zeros(len(edge)), np.ones(len(edge), dtype=bool)))

        found = np.flatnonzero(accepted & np.isfinite(cells).all(axis=1))
        points, cells, kind, target = points[found], cells[found], kind[found], point_index[found]
        mixed = None if self.mixed is None else self.mixed[g]
        hits, s, first_depth, spacing = _check_on_rays(self.ray_map, self._ray_table, grid, cells, points, mixed)
        pixels = self.ray_map.cell_pixels(cells[hits])
        origins, directions = self.ray_map.view.pixel_rays(pixels)
        target, kind = target[hits], kind[hits]
        reflector_points = origins + first_depth[:, None] * directions
        if pending is not None and len(self.histories[g]) == 1:
            risky = self._risky(g, kind, cells[hits])
            if len(risky):
                pending.append((g, target[risky], pixels[risky], reflector_points[risky], s[risky], kind[risky],
                                spacing[risky], np.zeros(len(risky), dtype=bool)))
        result.reflector_points[g, target] = reflector_points
        result.pixels[g, target] = pixels
        result.valid[g, target] = True
        result.leaf_kind[g, target] = kind
        result.ray_distance[g, target] = s

    def _owns(self, g: int, cells) -> np.ndarray:
        """Whether tree ``g``'s sheet owns each ray-map position (``owned``; False for NaN)."""
        lo, hi = self.owned[g, :2], self.owned[g, 2:]
        with np.errstate(invalid="ignore"):
            return np.all((cells >= lo) & (cells < hi), axis=1)

    def _has_edges(self, g: int) -> bool:
        """Whether tree ``g`` holds the first-order rays of some of its reflector's smooth
        pieces only (``surface_sets``), so that its reflector goes on past its rays' edge."""
        return (self.true_rays is not None and self.surfaces is not None and self.surfaces[g] is not None
                and len(self.histories[g]) == 1)

    def _across_edge(self, g: int, cells, distance) -> np.ndarray:
        """Indices of leaf answers (``cells``, ray ``distance``) of tree ``g`` that lie just
        across a sharp edge of its mirror: in front of the mirror, in a cell whose four
        rays exist in the history but not all in the tree's surfaces (the ray map cannot
        check them: the cell's rays straddle the edge).

        Between the last ray of one smooth piece and the first of the next, the tree's
        cells end, yet the piece goes on up to the edge and reflects points there. The
        leaf's model (a camera leaf's patch, a ray-list leaf's nearest cell patch),
        extrapolated less than EDGE_REACH_CELLS past its rays, seeds the true-ray
        polish, which keeps an image only on the tree's pieces (``polish_on_true_rays``).
        """
        with np.errstate(invalid="ignore"):
            near = np.flatnonzero(np.isfinite(cells).all(axis=1) & (distance >= 0))
        return near[_complete(self._history_grids[g], cells[near]) & ~_complete(self.grids[g], cells[near])]

    @functools.cached_property
    def _edge_rays(self) -> list:
        """Per tree, (R,) bool: its rays at a corner of a cell whose four rays exist in the
        history but not all in the tree (the rays along a sharp edge of its mirror,
        ``_across_edge``); None for a tree without edges. Sheets of one set share theirs."""
        masks = {}
        for g, (grid, history) in enumerate(zip(self.grids, self._history_grids)):
            if self._has_edges(g) and id(grid) not in masks:
                edge = _complete_quads(history) & ~_complete_quads(grid)
                corner = np.zeros(grid.shape, dtype=bool)
                for dj in (0, 1):
                    for di in (0, 1):
                        corner[dj:dj + edge.shape[0], di:di + edge.shape[1]] |= edge
                mask = np.zeros(self.ray_map.n_rays, dtype=bool)
                mask[grid[corner & (grid >= 0)]] = True
                masks[id(grid)] = mask
        return [masks.get(id(grid)) if self._has_edges(g) else None for g, grid in enumerate(self.grids)]

    @functools.cached_property
    def _ray_spacing(self) -> list:
        """Per tree, (tail, direction) (R,) each: how far its rays lie from their
        neighbours in its grid (``bsp.neighbour_spacing``), 0 for rays not in it; None for
        a tree without edges. Sheets of one set share theirs."""
        spacing = {}
        for g, grid in enumerate(self.grids):
            if self._has_edges(g) and id(grid) not in spacing:
                rays = grid[grid >= 0]
                tail, direction = np.zeros(self.ray_map.n_rays), np.zeros(self.ray_map.n_rays)
                tail[rays], direction[rays] = neighbour_spacing(self.ray_map, grid, rays)
                spacing[id(grid)] = tail, direction
        return [spacing.get(id(grid)) if self._has_edges(g) else None for g, grid in enumerate(self.grids)]

    @functools.cached_property
    def _history_grids(self) -> list:
        """Per tree, the grid of every ray of its history (all surfaces)."""
        grids = {h: self.ray_map.group_grid(self.ray_map.histories.index(tuple(h))) for h in dict.fromkeys(
            tuple(h) for h in self.histories)}
        return [grids[tuple(h)] for h in self.histories]

    def _risky(self, g: int, kind: np.ndarray, cells: np.ndarray) -> np.ndarray:
        """Indices of group ``g``'s answers to polish: first order, from a ray-list leaf or in a fold cell."""
        if self.true_rays is None or len(self.histories[g]) != 1:
            return np.zeros(0, dtype=np.int64)
        return np.flatnonzero((kind == RAY_LIST_LEAF) | _in_fold_cells(self.folds, g, cells))

    def _polish(self, g, risky, pixels, reflector_points, s, points, spacing) -> np.ndarray:
        """Polish group ``g``'s ``risky`` answers (``_risky``) in place on the true reflected
        rays (true_rays.py); returns which answers stand. ``spacing``: the ray spacing at
        each point (world units per cell)."""
        keep = np.ones(len(pixels), dtype=bool)
        if len(risky):
            pixels[risky], reflector_points[risky], s[risky], ok = polish_on_true_rays(
                self.true_rays, self.ray_map.view, self.histories[g][0], pixels[risky], points[risky],
                self.ray_map.downsample, spacing[risky] / self.ray_map.downsample,
                first_pieces(self.ray_map, self.grids[g]) if self.surfaces and self.surfaces[g] else None)
            keep[risky[~ok]] = False
        return keep

    def polish_answers(self, g: int, pixels, points, kind):
        """What ``project`` does after its interpolated answers, for answers of group ``g``
        found elsewhere (the GLSL twin, ``gpu_shaders/sbc_triangles.py``): desired-view
        ``pixels`` (P, 2) of ``points`` (P, 3) with their leaf ``kind`` (P,). Returns
        (pixels, first reflector points, ray distances, ok) of the answers polished on
        the true rays (the others as given, reflector points and distances NaN there)."""
        pixels = np.array(pixels, dtype=np.float64)
        points = np.asarray(points, dtype=np.float64)
        kind = np.asarray(kind)
        reflector_points = np.full((len(pixels), 3), np.nan)
        s = np.full(len(pixels), np.nan)
        cells = pixels / self.ray_map.downsample - 0.5
        spacing = np.zeros(len(pixels))  # unconfirmed by the ray map (float32 answers at an edge): iterate
        mixed = None if self.mixed is None else self.mixed[g]
        hits, _, _, confirmed = _check_on_rays(self.ray_map, self._ray_table, self.grids[g], cells, points, mixed)
        spacing[hits] = confirmed
        ok = self._polish(g, self._risky(g, kind, cells), pixels, reflector_points, s, points, spacing)
        return pixels, reflector_points, s, ok

    @functools.cached_property
    def _ray_table(self) -> np.ndarray:
        """(R, 8) rows tail, direction, head distance, first-hit depth: one gather per corner."""
        m = self.ray_map
        return np.concatenate([m.tail, m.direction, m.head_distance[:, None], m.first_depth[:, None]], axis=1)


def _complete_quads(grid: np.ndarray) -> np.ndarray:
    """(rows - 1, columns - 1) whether the four rays at the corners of each unit cell exist in ``grid``."""
    present = grid >= 0
    return present[:-1, :-1] & present[:-1, 1:] & present[1:, :-1] & present[1:, 1:]


def _edge_seeds(ray_map: RayMap, tree: BSPTree, row, points, edge_rays: np.ndarray, spacing):
    """Seeds for images near a sharp edge, on ray-list rows ``row`` (P,) whose cells
    neither hold the point nor reach it across the edge: per point, the row's ray along
    the edge (``edge_rays``) whose line passes closest to it, relative to how far the
    neighbouring rays pass there (``spacing``: per ray, (tail, direction) of
    ``bsp.neighbour_spacing``; within EDGE_REACH_CELLS of them). Returns (ray-map
    cells (P, 2), distance along the ray (P,)), NaN where no such ray passes near.

    A ray-list leaf one ray wide along the edge has no complete cell, and next to where
    three pieces meet a point's image may lie in the cells of another leaf than the one
    it descends to; the true-ray polish starts at the ray.
    """
    start, stop = tree.list_ray_start[row], tree.list_ray_start[row + 1]
    pair_point, pair_ray = expand_ranges(start, stop - start)
    ray = tree.list_rays[pair_ray]
    on_edge = edge_rays[ray]
    pair_point, ray = pair_point[on_edge], ray[on_edge]
    offset = points[pair_point] - ray_map.tail[ray]
    along = np.einsum("ij,ij->i", offset, ray_map.direction[ray])
    miss = np.sqrt(np.maximum(np.einsum("ij,ij->i", offset, offset) - along * along, 0.0))
    tail_step, direction_step = spacing[0][ray], spacing[1][ray]
    ratio = miss / np.maximum(EDGE_REACH_CELLS * (tail_step + np.maximum(along, 0.0) * direction_step), 1e-300)
    near = np.flatnonzero((along >= 0) & (ratio <= 1.0))
    order = near[np.lexsort((ratio[near], pair_point[near]))]
    first = order[np.concatenate([[True], pair_point[order][1:] != pair_point[order][:-1]])] if len(order) else order
    cells = np.full((len(points), 2), np.nan)
    distance = np.full(len(points), np.nan)
    cells[pair_point[first]] = ray_map.cell[ray[first]]
    distance[pair_point[first]] = along[first]
    return cells, distance


def _complete(grid: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Whether the four rays around each fractional cell exist in ``grid``."""
    base = np.floor(cells).astype(np.int64)
    rows, columns = grid.shape
    i, j = base[:, 0], base[:, 1]
    inside = (i >= 0) & (j >= 0) & (i + 1 < columns) & (j + 1 < rows)
    i, j = np.where(inside, i, 0), np.where(inside, j, 0)
    return inside & (grid[j, i] >= 0) & (grid[j, i + 1] >= 0) & (grid[j + 1, i] >= 0) & (grid[j + 1, i + 1] >= 0)


def descend_tree(tree: BSPTree, points: np.ndarray) -> np.ndarray:
    """Node index of the leaf each point falls in (whole arrays, one step per tree level).

    Only the points still in inner nodes go on to the next level, and each step is a
    few 1-D operations on the point coordinates (no gathers of (n, 3) rows).
    """
    node = np.zeros(len(points), dtype=np.int64)
    if tree.leaf[0] >= 0:
        return node
    x, y, z = (np.ascontiguousarray(points[:, d]) for d in range(3))
    normal = tree.plane_normal
    nx, ny, nz = (np.ascontiguousarray(normal[:, d]) for d in range(3))
    active = np.arange(len(points))
    current = node
    for _ in range(tree.depth + 1):
        side = (x * nx[current] + y * ny[current] + z * nz[current]) >= tree.plane_offset[current]
        current = np.where(side, tree.left[current], tree.right[current])
        done = tree.leaf[current] >= 0
        if done.all():
            node[active] = current
            break
        finished = np.flatnonzero(done)
        node[active[finished]] = current[finished]
        going = np.flatnonzero(~done)
        active, current, x, y, z = active[going], current[going], x[going], y[going], z[going]
    return node


def to_fallback(tree: BSPTree, leaf, camera_row, distance) -> np.ndarray:
    """Which points of camera leaves go to the leaf's ray list (bsp._depth_bands): those
    of a banded leaf whose distance along the ray lies in its band, or is NaN (Newton did
    not converge: near the band the patch is ill-conditioned). So do answers its fold
    cell refuses (``_project_group``). An answer outside the leaf's cells is not handed
    on: outside its band the patch is accurate, so the point is not on the leaf's rays."""
    return (tree.leaf_fallback[leaf] >= 0) & (in_band(tree, camera_row, distance) | np.isnan(distance))


def in_band(tree: BSPTree, camera_row, distance) -> np.ndarray:
    """Whether distances along the rays of camera leaves lie in the leaves' bands
    (bsp._depth_bands), where their patches are not trusted; False where NaN."""
    band = tree.camera_band[camera_row]
    with np.errstate(invalid="ignore"):
        return (distance > band[:, 0]) & (distance < band[:, 1])


def _project_ray_lists(tree: BSPTree, row, points, keep=CANDIDATE_CELLS, reach: float = 0.0):
    """Find, among a ray-list leaf's cells, the one whose bilinear ray patch holds the point.

    Newton runs only on the ``keep`` cells (per point, or one count for all) whose
    central ray passes closest to the point. Returns (cells (P, 2), found (P,),
    distance (P,)). With ``reach`` > 0, a point no cell holds gets the answer of the
    nearest patch extrapolated less than ``reach`` cells past it (found stays False):
    a seed for an image just across a sharp edge (``SampleBasedCamera._across_edge``).
    """
    start, stop = tree.cell_start[row], tree.cell_start[row + 1]
    count = stop - start
    pair_point, pair_cell = expand_ranges(start, count)
    pair_point, pair_cell = _closest_cells(tree.cells, pair_point, pair_cell, points, keep)
    cells, distance, residual = invert_patches(tree.cells, pair_cell, points[pair_point])
    local = cells - tree.cells.lo[pair_cell]
    solved = (residual < 1e-6 * (1 + np.linalg.norm(points[pair_point], axis=1))) & (distance >= 0)
    inside = solved & np.all((local >= -CELL_TOLERANCE) & (local <= 1 + CELL_TOLERANCE), axis=1)
    result = np.full((len(points), 2), np.nan)
    along = np.full(len(points), np.nan)
    found = np.zeros(len(points), dtype=bool)
    if reach > 0:
        near = solved & np.all((local >= -reach) & (local <= 1 + reach), axis=1)
        first = np.flatnonzero(near)[::-1]
        result[pair_point[first]], along[pair_point[first]] = cells[first], distance[first]
    first = np.flatnonzero(inside)[::-1]  # reversed so the first match per point is written last
    result[pair_point[first]], along[pair_point[first]] = cells[first], distance[first]
    found[pair_point[first]] = True
    return result, found, along


def _in_fold_cells(folds: list | None, g: int, cells: np.ndarray) -> np.ndarray:
    """(P,) whether each ray-map position (cell coordinates) lies in one of group ``g``'s fold cells."""
    if folds is None or not len(folds[g].valid):
        return np.zeros(len(cells), dtype=bool)
    index = folds[g].index
    base = np.floor(cells).astype(np.int64)
    column = np.clip(base[:, 0], 0, index.shape[1] - 1)
    row = np.clip(base[:, 1], 0, index.shape[0] - 1)
    return index[row, column] >= 0


def _refine_in_folds(folds: FoldCells, cells, accepted, points):
    """Solve answers that fall in fold cells again on the cell's traced sub-rays (FoldCells).

    ``cells`` is updated in place; returns ``accepted`` without the answers no sub-cell holds.
    """
    rows, columns = folds.index.shape
    base = np.floor(np.where(accepted[:, None], cells, -1.0)).astype(np.int64)
    inside = np.flatnonzero(accepted & (base[:, 0] >= 0) & (base[:, 1] >= 0) & (base[:, 0] < columns)
                            & (base[:, 1] < rows))
    fold = folds.index[base[inside, 1], base[inside, 0]]
    inside, fold = inside[fold >= 0], fold[fold >= 0]
    if len(inside) == 0:
        return accepted
    per_cell = FOLD_SAMPLES * FOLD_SAMPLES
    pair_point = np.repeat(np.arange(len(inside)), per_cell)
    pair_cell = (fold[:, None] * per_cell + np.arange(per_cell)).reshape(-1)
    usable = folds.valid[pair_cell]
    pair_point, pair_cell = _closest_cells(folds.patches, pair_point[usable], pair_cell[usable], points[inside],
                                           FOLD_CANDIDATES)
    sub_cells, distance, residual = invert_patches(folds.patches, pair_cell, points[inside][pair_point])
    local = sub_cells - folds.patches.lo[pair_cell]
    scale = 1 + np.linalg.norm(points[inside][pair_point], axis=1)
    hit = (np.all((local >= -CELL_TOLERANCE) & (local <= 1 + CELL_TOLERANCE), axis=1)
           & (residual < 1e-6 * scale) & (distance >= 0))
    # A sub-cell whose own rays are folded over at the point's depth sweeps space no ray reaches.
    held = np.flatnonzero(hit)
    t, d = folds.patches.tail[pair_cell[held]], folds.patches.direction[pair_cell[held]]
    corner_tails = np.stack([t[:, 0], t[:, 0] + t[:, 1], t[:, 0] + t[:, 2], t[:, 0] + t[:, 1] + t[:, 2] + t[:, 4]], 1)
    corner_directions = np.stack([d[:, 0], d[:, 0] + d[:, 1], d[:, 0] + d[:, 2], d[:, 0] + d[:, 1] + d[:, 2] + d[:, 4]], 1)
    hit[held] = ~rays_fold_at(corner_tails, corner_directions, distance[held])
    first = np.flatnonzero(hit)[::-1]  # the first match per point (nearest centre ray) is written last
    found = np.zeros(len(inside), dtype=bool)
    refined = np.full((len(inside), 2), np.nan)
    refined[pair_point[first]] = sub_cells[first] / FOLD_SAMPLES
    found[pair_point[first]] = True
    cells[inside] = refined
    accepted = accepted.copy()
    accepted[inside] = found
    return accepted


def _closest_cells(cells, pair_point, pair_cell, points, keep=CANDIDATE_CELLS):
    """Per point, the ``keep`` (point, cell) pairs whose cell-centre ray passes closest
    (``keep``: one count, or one per point).

    Cells whose central ray passes farther from the point than twice the cell's size at
    that depth cannot hold it and are dropped first (no effect on the result, only on
    the work: a point usually lies near few of a ray-list leaf's cells).
    """
    centre_tail, centre_direction, size, spread = cells.centre_rays
    offset = points[pair_point] - centre_tail[pair_cell]
    along = np.einsum("ij,ij->i", offset, centre_direction[pair_cell])
    # Squared distance from the central line (unit direction): |o|^2 - (o . d)^2.
    miss = np.maximum(np.einsum("ij,ij->i", offset, offset) - along * along, 0.0)
    reach = 2.0 * (size[pair_cell] + np.maximum(along, 0.0) * spread[pair_cell])
    near = miss <= reach * reach
    pair_point, pair_cell, miss = pair_point[near], pair_cell[near], miss[near]
    order = np.lexsort((miss, pair_point))
    sorted_point = pair_point[order]
    group_start = np.flatnonzero(np.concatenate([[True], sorted_point[1:] != sorted_point[:-1]]))
    rank = np.arange(len(order)) - np.repeat(group_start, np.diff(np.concatenate([group_start, [len(order)]])))
    chosen = order[rank < (keep if np.isscalar(keep) else keep[sorted_point])]
    return pair_point[chosen], pair_cell[chosen]


def _check_on_rays(ray_map: RayMap, table: np.ndarray, grid: np.ndarray, cells: np.ndarray, points: np.ndarray,
                   mixed_cells: MixedCells | None = None):
    """Which leaf answers the ray map's own rays confirm: indices into ``cells``, their ray
    distances s, interpolated first-hit depths, and the spacing of the cell's rays at s
    (the smaller of its two axes, world units per cell).

    The four rays around the fractional cell must exist in the group; their bilinear
    interpolation (tail, direction, head) must pass within one cell spacing of the point
    (MISS_CELLS; this checks every leaf's answer against the traced rays themselves), with
    the point in front of the tail and, where a corner ray ends on another reflector,
    before the interpolated head. Where a ray merely leaves the scene box, every scene
    point along it is in front of its end. In a mixed cell (``mixed_cells``), the head is that
    of the nearest traced sub-ray instead.
    """
    base = np.floor(cells).astype(np.int64)
    rows, columns = grid.shape
    i0, j0 = base[:, 0], base[:, 1]
    keep = np.flatnonzero((i0 >= 0) & (j0 >= 0) & (i0 + 1 < columns) & (j0 + 1 < rows))
    flat = grid.reshape(-1)
    first = j0[keep] * columns + i0[keep]
    corners = [flat[first], flat[first + 1], flat[first + columns], flat[first + columns + 1]]
    complete = np.flatnonzero((corners[0] >= 0) & (corners[1] >= 0) & (corners[2] >= 0) & (corners[3] >= 0))
    keep = keep[complete]
    corners = [c[complete] for c in corners]
    frac = cells[keep] - base[keep]
    fu, fv = frac[:, 0:1], frac[:, 1:2]
    rays = [table[c] for c in corners]
    mixed = ((1 - fu) * (1 - fv)) * rays[0] + (fu * (1 - fv)) * rays[1] + ((1 - fu) * fv) * rays[2] + (fu * fv) * rays[3]
    direction = mixed[:, 3:6] / np.maximum(_norm(mixed[:, 3:6]), 1e-300)[:, None]
    head_distance = mixed[:, 6]
    blocked = ray_map.blocked
    blocked = blocked[corners[0]] | blocked[corners[1]] | blocked[corners[2]] | blocked[corners[3]]
    if mixed_cells is not None and len(mixed_cells.heads):
        row = mixed_cells.index.reshape(-1)[first[complete]]
        in_mixed = np.flatnonzero(row >= 0)
        if len(in_mixed):
            m = mixed_cells.heads.shape[1]
            a = np.minimum((frac[in_mixed, 0] * m).astype(np.int64), m - 1)
            b = np.minimum((frac[in_mixed, 1] * m).astype(np.int64), m - 1)
            head = mixed_cells.heads[row[in_mixed], b, a]
            blocked[in_mixed] = np.isfinite(head)
            head_distance = head_distance.copy()
            head_distance[in_mixed] = np.where(np.isfinite(head), head, head_distance[in_mixed])
    offset = points[keep] - mixed[:, 0:3]
    s = np.einsum("pd,pd->p", offset, direction)
    tolerance = 1e-6 * (1.0 + head_distance)
    miss = _norm(offset - s[:, None] * direction)
    # Spacing of neighbouring rays at distance s (the larger axis of the cell).
    along_u = _norm(rays[1][:, 0:3] - rays[0][:, 0:3] + s[:, None] * (rays[1][:, 3:6] - rays[0][:, 3:6]))
    along_v = _norm(rays[2][:, 0:3] - rays[0][:, 0:3] + s[:, None] * (rays[2][:, 3:6] - rays[0][:, 3:6]))
    ok = ((miss <= MISS_CELLS * np.maximum(along_u, along_v) + tolerance) & (s >= -tolerance)
          & (~blocked | (s <= head_distance + tolerance)))
    hits = np.flatnonzero(ok)
    return keep[hits], s[hits], mixed[hits, 7], np.minimum(along_u, along_v)[hits]


def _norm(vectors: np.ndarray) -> np.ndarray:
    return np.sqrt(np.einsum("pd,pd->p", vectors, vectors))


def _build_sheets(ray_map: RayMap, rays: np.ndarray, grid: np.ndarray, model, accuracy_px: float,
                  owned: np.ndarray) -> list:
    """(tree, owned cells) for one group's rays, split into sheets where the rays
    cross in space (or where a split fails on more than bsp.MAX_RAY_LIST_RAYS rays).

    Where rays of one history cross (a concave mirror's caustic, or two parts of a
    mirror reflecting the same region: the Chen-Arvo vase shows points twice), no
    plane separates them and the BSP duplicates rays without end. The rays are then
    halved in ray-map space (at the median cell along the longer side, both halves
    keeping the seam's line of rays) and each half gets its own tree, its own *sheet*,
    recursively. A point may project in several sheets of one history: those are its
    several images. ``owned`` (lo u, lo v, hi u, hi v) are the cells the sheet answers
    for: the halves split it at the seam, so that where both reach over the seam (their
    leaves accept half a cell beyond their rays) one image is answered once.
    """
    try:
        return [(build_bsp(ray_map, rays, grid, model, accuracy_px,
                           max_duplication=None if len(rays) <= MIN_SHEET_RAYS else MAX_DUPLICATION), owned)]
    except RaysCrossError:
        cells = ray_map.cell[rays]
        axis = int(np.argmax(cells.max(axis=0) - cells.min(axis=0)))
        seam = np.floor(np.median(cells[:, axis]))
        # Both halves keep the seam's line of rays, so the cells across the seam (four
        # corner rays, two on each side) belong to the upper sheet: no line of holes.
        low, high = cells[:, axis] <= seam, cells[:, axis] >= seam
        if low.all() or high.all():
            return [(build_bsp(ray_map, rays, grid, model, accuracy_px, max_duplication=None), owned)]
        owned_low, owned_high = owned.copy(), owned.copy()
        owned_low[2 + axis] = owned_high[axis] = seam
        return (_build_sheets(ray_map, rays[low], grid, model, accuracy_px, owned_low)
                + _build_sheets(ray_map, rays[high], grid, model, accuracy_px, owned_high))


def surface_sets(ray_map: RayMap, group: int) -> list:
    """The rays of a reflection group, split by surface history (``RayMap.surfaces``):
    tuples of surface indices, each set getting its own trees; [None] where the group
    is not split (one set holds all its rays).

    Across a sharp edge of a mirror (a teapot's lid on its body, a spout joining it)
    the reflected rays jump, so no leaf straddling the edge is accurate however small,
    and the BSP ended there in ray lists and sheets (SBC paper IV: leaves model a
    continuous ray field; groups there are split by reflector for the same reason).
    Each surface of at least MIN_SHEET_RAYS rays gets its own trees; the smaller ones
    (a faceted mirror's flat faces) stay together in one set, as the whole group was.
    """
    counts = np.bincount(ray_map.surface[ray_map.group == group], minlength=len(ray_map.surfaces))
    present = np.flatnonzero(counts)
    large = present[counts[present] >= MIN_SHEET_RAYS]
    small = present[counts[present] < MIN_SHEET_RAYS]
    sets = [(int(k),) for k in large] + ([tuple(int(k) for k in small)] if len(small) else [])
    return [None] if len(sets) <= 1 else sets


def first_pieces(ray_map: RayMap, grid: np.ndarray) -> np.ndarray:
    """The smooth pieces (ReflectorSet.piece) that the rays of ``grid`` first reflect off."""
    surfaces = np.unique(ray_map.surface[grid[grid >= 0]])
    return np.unique([ray_map.surfaces[k][0] for k in surfaces]).astype(np.int64)


def build_from_ray_map(ray_map: RayMap, accuracy_px: float = 1.0, leaf_model: str = "ray_patch") -> SampleBasedCamera:
    """One BSP tree per reflection group of an existing ray map (or several, its sheets)."""
    if leaf_model not in LEAF_MODELS:
        raise ValueError(f"leaf_model must be one of {sorted(LEAF_MODELS)}, got {leaf_model!r}")
    if not accuracy_px > 0:
        raise ValueError(f"accuracy_px must be positive, got {accuracy_px}")
    start = time.perf_counter()
    trees, grids, histories, cones, owned, surfaces = [], [], [], [], [], []
    whole = np.array([0.0, 0.0, ray_map.columns, ray_map.rows])
    model = LEAF_MODELS[leaf_model]
    for g, history in enumerate(ray_map.histories):
        for surface_set in surface_sets(ray_map, g):
            grid = ray_map.group_grid(g, surface_set)
            rays = grid[grid >= 0]
            sheets = (_build_sheets(ray_map, rays, grid, model, accuracy_px, whole) if model.splits_into_sheets
                      else [(build_bsp(ray_map, rays, grid, model, accuracy_px, max_duplication=None), whole)])
            for tree, cells in sheets:
                trees.append(tree)
                grids.append(grid)
                histories.append(history)
                surfaces.append(surface_set)
                cones.append(tree.cone)
                owned.append(cells)
    seconds = time.perf_counter() - start
    sbc = SampleBasedCamera(ray_map, trees, grids, leaf_model, histories,
                            cones=np.array(cones).reshape(-1, CONE_SIZE), owned=np.array(owned).reshape(-1, 4),
                            surfaces=surfaces)
    sbc.stats = _stats(ray_map, trees, grids, seconds)
    return sbc


def build_sample_based_camera(reflectors, view: View, bounds, max_order: int = 1, downsample: int = 2,
                              accuracy_px: float = 1.0, leaf_model: str = "ray_patch") -> SampleBasedCamera:
    """Trace the ray map of ``view`` and build its sample-based camera.

    ``reflectors`` is a list of :class:`Reflector` (or a prepared :class:`ReflectorSet`),
    ``bounds`` the scene box (lo, hi) where reflected rays end.
    """
    if int(downsample) < 1:
        raise ValueError(f"downsample must be >= 1, got {downsample}")
    if view.width // int(downsample) < 1 or view.height // int(downsample) < 1:
        raise SceneInputError(view.name, f"a {view.width}x{view.height} view has no ray at down-sampling {downsample}")
    start = time.perf_counter()
    reflector_set = reflectors if isinstance(reflectors, ReflectorSet) else ReflectorSet(list(reflectors))
    check_view_outside_reflectors(reflector_set, view)
    ray_map = trace_ray_map(reflector_set, view, bounds, int(downsample), int(max_order))
    trace_seconds = time.perf_counter() - start
    sbc = build_from_ray_map(ray_map, accuracy_px, leaf_model)
    start = time.perf_counter()
    sbc.mixed = trace_mixed_cells(reflector_set, ray_map, bounds, sbc.grids)
    sbc.stats["trace_seconds"] = trace_seconds + time.perf_counter() - start
    sbc.stats["n_mixed_cells"] = int(sum(len(m.heads) for m in {id(m): m for m in sbc.mixed}.values()))
    sbc.stats["nbytes"] += int(sum(m.nbytes for m in {id(m): m for m in sbc.mixed}.values()))
    start = time.perf_counter()
    sbc.folds = trace_fold_cells(reflector_set, ray_map, sbc.grids)
    sbc.stats["fold_seconds"] = time.perf_counter() - start
    sbc.stats["trace_seconds"] += sbc.stats["fold_seconds"]
    distinct = {id(f): f for f in sbc.folds}.values()
    sbc.stats["n_fold_cells"] = int(sum(len(f.valid) for f in distinct)) // (FOLD_SAMPLES * FOLD_SAMPLES)
    sbc.stats["nbytes"] += int(sum(f.nbytes for f in distinct))
    sbc.true_rays = reflector_set
    return sbc


def trace_fold_cells(reflector_set: ReflectorSet, ray_map: RayMap, grids: list) -> list:
    """FoldCells of every tree's group (one object per distinct grid, shared by its sheets)."""
    traced = {}
    for grid in grids:
        if id(grid) not in traced:
            traced[id(grid)] = _fold_cells(reflector_set, ray_map, grid)
    return [traced[id(grid)] for grid in grids]


def fold_cell_mask(ray_map: RayMap, corners: np.ndarray) -> np.ndarray:
    """(n,) bool: cells (four corner rays 00, 10, 01, 11 each) whose rays fold over
    somewhere between their tails and their longest head (rays_fold)."""
    return rays_fold(ray_map.tail[corners], ray_map.direction[corners], ray_map.head_distance[corners].max(axis=1))


def _orientations(tail: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """(n, 4, 3) coefficients q0, q1, q2 of each corner triangle's orientation
    q0 + q1 s + q2 s^2 (cross product of its edges at depth s, along the mean direction)."""
    mean = direction.mean(axis=1)
    out = np.empty((len(tail), len(FOLD_TRIANGLES), 3))
    for k, (a, b, c) in enumerate(FOLD_TRIANGLES):
        e1t, e1d = tail[:, b] - tail[:, a], direction[:, b] - direction[:, a]
        e2t, e2d = tail[:, c] - tail[:, a], direction[:, c] - direction[:, a]
        out[:, k, 0] = np.einsum("nd,nd->n", cross(e1t, e2t), mean)
        out[:, k, 1] = np.einsum("nd,nd->n", cross(e1t, e2d) + cross(e1d, e2t), mean)
        out[:, k, 2] = np.einsum("nd,nd->n", cross(e1d, e2d), mean)
    return out


def _mixed(q: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """(n, m) bool: at depth[:, m], do the four corner triangles disagree in orientation
    (one turns one way, another the other; a quad collapsed to a point is not folded)?"""
    value = q[:, :, None, 0] + depth[:, None] * (q[:, :, None, 1] + depth[:, None] * q[:, :, None, 2])
    return np.any(value > 0, axis=1) & np.any(value < 0, axis=1)


def rays_fold_at(tail: np.ndarray, direction: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """(n,) bool: at its depth, is each cell's quad of rays (n, 4, 3) folded over (its
    corner triangles disagree in orientation, so the bilinear patch is not one-to-one)?"""
    return _mixed(_orientations(tail, direction), depth[:, None])[:, 0]


def rays_fold(tail: np.ndarray, direction: np.ndarray, reach: np.ndarray) -> np.ndarray:
    """(n,) bool: is each cell's quad of rays (n, 4, 3; corners 00, 10, 01, 11) folded over
    at some depth in [0, reach]?

    Each corner triangle's orientation is a quadratic in the depth; the triangles can
    only start or stop disagreeing at a root of one of them, so the test is exact at
    the ends, the roots in [0, reach] and the midpoints between them. A quad that turns
    over as a whole (past a focus, all four triangles flip) stays one-to-one: no fold.
    """
    q = _orientations(tail, direction)
    a, b, c = q[..., 2], q[..., 1], q[..., 0]
    root = np.sqrt(np.maximum(b * b - 4 * a * c, 0.0))
    linear = np.abs(a) <= 1e-12 * (np.abs(b) + np.abs(c)) + 1e-300
    with np.errstate(divide="ignore", invalid="ignore"):
        roots = np.concatenate([np.where(linear, -c / b, (-b - root) / (2 * a)),
                                np.where(linear, np.nan, (-b + root) / (2 * a))], axis=1)
    roots = np.where(np.isfinite(roots), np.clip(roots, 0.0, reach[:, None]), 0.0)
    depths = np.sort(np.concatenate([np.zeros((len(q), 1)), reach[:, None], roots], axis=1), axis=1)
    depths = np.concatenate([depths, 0.5 * (depths[:, 1:] + depths[:, :-1])], axis=1)
    return _mixed(q, depths).any(axis=1)


def _fold_cells(reflector_set: ReflectorSet, ray_map: RayMap, grid: np.ndarray) -> FoldCells:
    rows, columns = grid.shape
    m = FOLD_SAMPLES
    index = np.full((rows, columns), -1, dtype=np.int64)
    corners = np.stack([grid[:-1, :-1], grid[:-1, 1:], grid[1:, :-1], grid[1:, 1:]], axis=-1)  # (rows-1, cols-1, 4)
    j, i = np.nonzero(np.all(corners >= 0, axis=-1))
    members = grid[grid >= 0]
    history = ray_map.histories[int(ray_map.group[members[0]])] if len(members) else ()
    if len(j) and len(history) == 1:  # first-order groups: sub-rays are view rays reflected once
        fold = fold_cell_mask(ray_map, corners[j, i])
        j, i = j[fold], i[fold]
    else:
        j = i = np.zeros(0, dtype=np.int64)
    empty = RayPatches(np.zeros((0, 3)), np.zeros((0, 2, 3)), np.zeros(0), np.zeros((0, 6, 3)),
                       np.zeros((0, 6, 3)), np.zeros((0, 6, 2)), np.zeros((0, 2)), np.zeros((0, 2)), True)
    if len(j) == 0:
        return FoldCells(index, empty, np.zeros(0, dtype=bool))
    index[j, i] = np.arange(len(j))
    lattice = np.arange(m + 1)
    lb, la = np.meshgrid(lattice, lattice, indexing="ij")  # [b, a]
    sub = np.stack([i[:, None] * m + la.reshape(-1), j[:, None] * m + lb.reshape(-1)], axis=-1)  # (n, (m+1)^2, 2)
    origins, incoming = ray_map.view.pixel_rays(ray_map.cell_pixels(sub.reshape(-1, 2) / m))
    hits = reflector_set.intersect(origins, incoming)
    ok = (hits.reflector == history[0]) & reflection_valid(incoming, hits.normal, hits.face_normal)
    ok &= np.isin(reflector_set.piece[np.maximum(hits.triangle, 0)], first_pieces(ray_map, grid))
    tails = origins + np.where(ok, hits.t, 0.0)[:, None] * incoming
    directions = reflect(incoming, hits.normal)
    n = len(j)
    tails, directions, ok = (x.reshape(n, m + 1, m + 1, -1) for x in (tails, directions, ok[:, None]))

    def corner(x, db, da):
        return x[:, db:db + m, da:da + m].reshape(n * m * m, -1)

    t = [corner(tails, 0, 0), corner(tails, 0, 1), corner(tails, 1, 0), corner(tails, 1, 1)]
    d = [corner(directions, 0, 0), corner(directions, 0, 1), corner(directions, 1, 0), corner(directions, 1, 1)]
    valid = (corner(ok, 0, 0) & corner(ok, 0, 1) & corner(ok, 1, 0) & corner(ok, 1, 1))[:, 0]

    def bilinear(c):  # coefficients 1, u, v, u^2, uv, v^2 of the bilinear patch through corners 00, 10, 01, 11
        zero = np.zeros_like(c[0])
        return np.stack([c[0], c[1] - c[0], c[2] - c[0], zero, c[3] - c[2] - c[1] + c[0], zero], axis=1)

    count = n * m * m
    lo = corner(sub.reshape(n, m + 1, m + 1, 2), 0, 0).astype(np.float64)
    patches = RayPatches(np.zeros((count, 3)), np.zeros((count, 2, 3)), np.ones(count), bilinear(t), bilinear(d),
                         np.zeros((count, 6, 2)), lo, lo + 1.0, True)
    return FoldCells(index, patches, valid)


def trace_mixed_cells(reflector_set: ReflectorSet, ray_map: RayMap, bounds, grids: list) -> list:
    """MixedCells of every tree's group (one object per distinct grid, shared by its sheets)."""
    lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
    lo, hi = np.minimum(lo, reflector_set.vertices.min(axis=0)), np.maximum(hi, reflector_set.vertices.max(axis=0))
    traced = {}
    for grid in grids:
        if id(grid) not in traced:
            traced[id(grid)] = _mixed_cells(reflector_set, ray_map, grid, lo, hi)
    return [traced[id(grid)] for grid in grids]


def _mixed_cells(reflector_set: ReflectorSet, ray_map: RayMap, grid: np.ndarray, lo, hi) -> MixedCells:
    rows, columns = grid.shape
    corners = np.stack([grid[:-1, :-1], grid[:-1, 1:], grid[1:, :-1], grid[1:, 1:]], axis=-1)  # (rows-1, cols-1, 4)
    complete = np.all(corners >= 0, axis=-1)
    blocked = ray_map.blocked[np.maximum(corners, 0)]
    j, i = np.nonzero(complete & blocked.any(axis=-1) & ~blocked.all(axis=-1))
    index = np.full((rows, columns), -1, dtype=np.int64)
    m = SUBCELL_SAMPLES
    if len(j) == 0:
        return MixedCells(index, np.zeros((0, m, m)))
    index[j, i] = np.arange(len(j))
    cell_corners = corners[j, i]  # (n, 4)
    fraction = (np.arange(m) + 0.5) / m
    fb, fa = np.meshgrid(fraction, fraction, indexing="ij")  # [b, a]
    fa, fb = fa.reshape(-1), fb.reshape(-1)
    weights = np.stack([(1 - fa) * (1 - fb), fa * (1 - fb), (1 - fa) * fb, fa * fb], axis=1)  # (m*m, 4)
    tails = np.einsum("sk,nkd->nsd", weights, ray_map.tail[cell_corners]).reshape(-1, 3)
    directions = np.einsum("sk,nkd->nsd", weights, ray_map.direction[cell_corners]).reshape(-1, 3)
    directions /= np.maximum(np.linalg.norm(directions, axis=1), 1e-300)[:, None]
    # Each sub-ray starts on the chord between the corner tails: the nearest corner's
    # triangle (and its one-ring) is its source, as for the traced rays.
    nearest = np.argmax(weights, axis=1)
    sources = ray_map.triangle[cell_corners[:, nearest]].reshape(-1)
    box = box_exit_distance(tails, directions, lo, hi)
    hits = reflector_set.intersect(tails, directions, box, sources)
    heads = np.where(hits.hit, hits.t, np.inf).reshape(len(j), m, m)
    return MixedCells(index, heads)


def check_view_outside_reflectors(reflector_set: ReflectorSet, view: View) -> None:
    """Raise a clear error when a perspective eye sits inside a closed reflector.

    From inside, rays in every direction meet the back of the same reflector first
    (test: the six axis directions and the view direction).
    """
    if not view.is_perspective:
        return
    directions = np.concatenate([np.eye(3), -np.eye(3), [-view.backward]])
    origins = np.broadcast_to(view.eye, directions.shape)
    hits = reflector_set.intersect(origins, directions)
    if not hits.hit.all():
        return
    back = np.einsum("ij,ij->i", reflector_set.face_normals[hits.triangle], directions) > 0
    owners = np.unique(hits.reflector)
    if back.all() and len(owners) == 1:
        name = reflector_set.reflectors[int(owners[0])].name
        raise SceneInputError(name, "the view is inside this reflector; move the camera outside it")


def _stats(ray_map: RayMap, trees: list, grids: list, seconds: float) -> dict:
    kinds = np.concatenate([t.leaf_kind for t in trees]) if trees else np.zeros(0, np.int8)
    rays_in_leaves = np.concatenate([t.leaf_rays for t in trees]) if trees else np.zeros(0)
    return {
        "n_groups": len(set(ray_map.histories)),
        "n_sheets": len(trees),
        "n_rays": int(ray_map.n_rays),
        "n_leaves": int(len(kinds)),
        "n_camera_leaves": int((kinds == CAMERA_LEAF).sum()),
        "n_raylist_leaves": int((kinds == RAY_LIST_LEAF).sum()),
        "n_banded_leaves": int(sum(int((t.leaf_fallback >= 0).sum()) for t in trees if t.leaf_fallback is not None)),
        "rays_per_leaf": float(rays_in_leaves.mean()) if len(rays_in_leaves) else 0.0,
        "max_depth": int(max((t.depth for t in trees), default=0)),
        "build_seconds": seconds,
        "nbytes": int(sum(t.nbytes for t in trees) + sum(g.nbytes for g in grids)),
    }
