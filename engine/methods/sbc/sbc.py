# SPDX-License-Identifier: GPL-3.0-or-later
"""Sample-based cameras: where does a 3D point appear, reflected, in this view?

Popescu, Sacks, Mei (2006). The reflected rays of the desired view (ray map, section
III-B) are split into reflection groups by history, and a group further by the smooth
pieces of its mirrors (``sbc_build.surface_sets``: across a sharp edge the rays jump); each gets
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
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from .bsp import CAMERA_LEAF, RAY_LIST_LEAF, BSPTree, descend_tree, to_fallback
from .pinhole import PinholeLeaves
from ...projection import Projection
from .ray_cones import CONE_SIZE, in_cones
from .ray_patch import RayPatchLeaves, invert_patches
from .raymap import RayMap, first_pieces, neighbour_spacing
from ...geometry.raytrace import ReflectorSet
from .sbc_cells import FOLD_SAMPLES, FoldCells, check_on_rays, rays_fold_at
from .sbc_edges import (EDGE_REACH_CELLS, SeedRays, complete, complete_quads, edge_seeds, nearest_ray_seeds,
                        sub_ray_seeds, touched_quads, touches)
from ...geometry.segments import expand_ranges, ranks_in_runs
from ...geometry.vectors import lengths
from ...reference.true_rays import polish_by_continuation, polish_on_true_rays

LEAF_MODELS = {"ray_patch": RayPatchLeaves(), "pinhole": PinholeLeaves()}
#: Tolerance (cell units) for a ray-list cell's bilinear coordinates.
CELL_TOLERANCE = 1e-6
#: Threads that project parts of the points at once, and the fewest points per thread.
PROJECT_THREADS = 4
THREAD_MIN_POINTS = 16384
#: Points projected together: small enough that each step's temporaries stay in the cache.
PROJECT_BLOCK = 16384
#: Ray-list cells tried per point, nearest central ray first.
CANDIDATE_CELLS = 3
#: The same for the ray list of a banded camera leaf (bsp._depth_bands), whose cells are
#: many and whose band lies where its rays cross, so several centre rays pass close.
BAND_CANDIDATES = 8
#: Fold sub-cells tried per point, nearest central ray first.
FOLD_CANDIDATES = 16
#: Rays of a higher order's last ring that seed the true-ray polish of an answer in turn.
RING_SEEDS = 3


@dataclass
class SampleBasedCamera:
    """One view's sample-based camera: a ray map and one BSP tree per reflection group."""

    ray_map: RayMap
    trees: list
    grids: list
    model_name: str
    histories: list  # one reflection history per tree (a history repeats once per sheet)
    stats: dict = field(default_factory=dict)
    #: (trees, CONE_SIZE) per tree, a cone around where its rays can project (``ray_cones.ray_cones``), or None.
    cones: np.ndarray | None = None
    #: Per tree, its group's MixedCells (shared by the sheets of a group), or None where not traced.
    mixed: list | None = None
    #: Per tree, its group's FoldCells (shared by the sheets of a group), or None where not traced.
    folds: list | None = None
    #: The reflectors, where first-order answers of ray-list leaves and fold cells are
    #: polished on the true reflected rays (true_rays.py); None: answers as interpolated.
    true_rays: ReflectorSet | None = None
    #: (trees, 4) per tree, the ray-map cells its sheet owns, lo <= cell < hi as
    #: (lo u, lo v, hi u, hi v) (``sbc_build._build_sheets``); None: each tree owns every cell.
    owned: np.ndarray | None = None
    #: Per tree, the surface histories (indices into ``ray_map.surfaces``) whose rays it
    #: holds (``sbc_build.surface_sets``), or None for all of its group's; None: all trees hold all.
    surfaces: list | None = None
    #: Reflectors whose first-order reflections other methods draw in this view (the
    #: iterative search, a morphing grid, perturbation): the camera has no tree for them
    #: (``sbc_build.build_sample_based_camera``), only for the higher orders they start.
    first_order_left_out: frozenset = frozenset()

    @property
    def groups(self) -> list:
        return list(self.histories)

    def project(self, points, polish: bool = True) -> Projection:
        """Project world points (P, 3) in every group. With ``polish`` (and ``true_rays``
        set), first-order answers of ray-list leaves and fold cells, and every answer of a
        higher order, are polished on the true reflected rays (``true_rays.py``); without,
        every answer is the interpolated one (what the GLSL twin computes)."""
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
            if len(self.histories[g]) > 1:
                # A higher order's answer that did not polish from where it was found (a
                # leaf's patch extrapolated, or refused by the ray checks) starts again
                # from the footprint's last ring, from the ray passing closest, then the
                # next: near the footprint's edge the path bends fast, and the closest
                # passing ray may lie across the image from the point's.
                retry = np.flatnonzero(edge & ~keep)
                seed_cells, seed_distance = nearest_ray_seeds(self._ring_seeds[g], points[target[retry]], RING_SEEDS)
                seeds = self.ray_map.cell_pixels(seed_cells)
                tried = pixels[retry]
                for rank in range(RING_SEEDS):
                    fresh = (~keep[retry] & np.isfinite(seed_distance[:, rank])
                             & (np.abs(seeds[:, rank] - tried).max(axis=1) > 0.5))
                    again = retry[fresh]
                    pixels[again], s[again] = seeds[fresh, rank], seed_distance[fresh, rank]
                    keep[again] = self._polish(g, again, pixels, reflector_points, s, points[target], spacing,
                                               seeded=True)[again]
            if self.owned is not None:
                # Polished from a seed, an image across an edge may come to rest in another sheet's cells.
                keep[edge] &= self._owns(g, pixels[edge] / self.ray_map.downsample - 0.5)
            # Answers across an edge were never checked against the rays' heads: the
            # reflected segment must reach the point past every reflector.
            check = np.flatnonzero(edge & keep)
            if len(check) and len(self.histories[g]) == 1:  # a higher order's polish checked its last segment
                offset = points[target[check]] - reflector_points[check]
                length = lengths(offset)
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
        tree ``g``: those in the sheet's bounding cone (``ray_cones.py``)."""
        if self.cones is None:
            return np.arange(len(points))
        return np.flatnonzero(in_cones(np.broadcast_to(self.cones[g], (len(points), CONE_SIZE)), points))

    def _project_group(self, g, tree: BSPTree, grid, points, point_index, result: Projection, pending):
        leaf = tree.leaf[descend_tree(tree, points)]
        if tree.leaf_cones is not None:
            # Points outside their leaf's bounding cone cannot project there (``ray_cones.py``).
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
                seed_cells, seed_distance = edge_seeds(self.ray_map, tree, row[seeded], points[seeded],
                                                        self._edge_rays[g], self._ray_spacing[g])
                reached = np.flatnonzero(np.isfinite(seed_distance))
                cells[seeded[reached]] = seed_cells[reached]
                edge = np.concatenate([edge, seeded[reached]])
                edge_distance = np.concatenate([edge_distance, seed_distance[reached]])
        if edges and len(self.histories[g]) > 1:
            # A higher order's footprint is small and its leaves' patches extrapolate
            # poorly past it: a point no leaf answers is seeded by the footprint's last
            # ring of rays (the one passing closest), and polished on the true rays.
            rest = np.setdiff1d(np.flatnonzero(~accepted), edge)
            seed_cells, seed_distance = (seeds[:, 0] for seeds in nearest_ray_seeds(self._ring_seeds[g], points[rest]))
            reached = np.flatnonzero(np.isfinite(seed_distance))
            cells[rest[reached]] = seed_cells[reached]
            edge = np.concatenate([edge, rest[reached]])
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
        hits, s, first_depth, spacing = check_on_rays(self.ray_map, self._ray_table, grid, cells, points, mixed)
        if edges and len(self.histories[g]) > 1 and len(hits) < len(cells):
            # A higher order's interpolated rays bend fast near a mirror's silhouette: an
            # answer they refuse is tried again on the true rays, from where it is.
            failed = np.setdiff1d(np.arange(len(cells)), hits)
            pending.append((g, target[failed], self.ray_map.cell_pixels(cells[failed]),
                            np.full((len(failed), 3), np.nan), np.full(len(failed), np.nan), kind[failed],
                            np.zeros(len(failed)), np.ones(len(failed), dtype=bool)))
        pixels = self.ray_map.cell_pixels(cells[hits])
        origins, directions = self.ray_map.view.pixel_rays(pixels)
        target, kind = target[hits], kind[hits]
        reflector_points = origins + first_depth[:, None] * directions
        if pending is not None:
            risky = self._risky(g, kind, cells[hits])
            if len(risky):
                # A higher order's answer that does not polish is seeded again, as one at its edge is.
                pending.append((g, target[risky], pixels[risky], reflector_points[risky], s[risky], kind[risky],
                                spacing[risky], np.full(len(risky), len(self.histories[g]) > 1)))
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
        """Whether tree ``g``'s answers may lie past its rays, and are then found on the
        true rays: a first-order tree holding some of its reflector's smooth pieces only
        (``sbc_build.surface_sets``: its reflector goes on past its rays' edge), or a
        higher order (the last ring of its footprint's cells, where a ray leaves the path's
        mirrors)."""
        if self.true_rays is None:
            return False
        return len(self.histories[g]) > 1 or (self.surfaces is not None and self.surfaces[g] is not None)

    def _across_edge(self, g: int, cells, distance) -> np.ndarray:
        """Indices of leaf answers (``cells``, ray ``distance``) of tree ``g`` that lie just
        past its rays, in front of the mirror: first order, in a cell whose four rays exist
        in the history but not all in the tree's surfaces (the ray map cannot check them:
        the cell's rays straddle a sharp edge of the mirror); higher order, in a cell of the
        footprint's last ring (some of its four rays in the group, not all: the others
        left the path's mirrors, at a silhouette of one of them).

        Between the last ray of one smooth piece and the first of the next, the tree's
        cells end, yet the piece goes on up to the edge and reflects points there; a
        higher-order footprint goes on up to where its path leaves a mirror, which is
        between rays too (on two facing spheres, a fifth to a third of the second-order
        images lie in that last ring at d = 2). The leaf's model (a camera leaf's patch, a
        ray-list leaf's nearest cell patch), extrapolated less than EDGE_REACH_CELLS past
        its rays, seeds the true-ray polish, which keeps an image only on the tree's pieces
        and along its whole history (``polish_on_true_rays``).
        """
        with np.errstate(invalid="ignore"):
            near = np.flatnonzero(np.isfinite(cells).all(axis=1) & (distance >= 0))
        if len(self.histories[g]) > 1:
            return near[~complete(self.grids[g], cells[near]) & touches(self.grids[g], cells[near])]
        return near[complete(self._history_grids[g], cells[near]) & ~complete(self.grids[g], cells[near])]

    @functools.cached_property
    def _edge_rays(self) -> list:
        """Per tree, (R,) bool: its rays at a corner of a cell whose four rays exist in the
        history but not all in the tree (the rays along a sharp edge of its mirror,
        ``_across_edge``), or for a higher order at a corner of its footprint's last ring;
        None for a tree without edges. Sheets of one set share theirs."""
        masks = {}
        for g, (grid, history) in enumerate(zip(self.grids, self._history_grids)):
            if self._has_edges(g) and id(grid) not in masks:
                if len(self.histories[g]) > 1:  # the last ring of the footprint
                    edge = touched_quads(grid >= 0) & ~complete_quads(grid)
                else:
                    edge = complete_quads(history) & ~complete_quads(grid)
                corner = np.zeros(grid.shape, dtype=bool)
                for dj in (0, 1):
                    for di in (0, 1):
                        corner[dj:dj + edge.shape[0], di:di + edge.shape[1]] |= edge
                mask = np.zeros(self.ray_map.n_rays, dtype=bool)
                mask[grid[corner & (grid >= 0)]] = True
                masks[id(grid)] = mask
        return [masks.get(id(grid)) if self._has_edges(g) else None for g, grid in enumerate(self.grids)]

    @functools.cached_property
    def _ring_seeds(self) -> list:
        """Per higher-order tree, the SeedRays of its footprint's last ring: the ray map's
        rays there and sub-rays traced between them (``sbc_edges.sub_ray_seeds``); None
        for a first-order tree. Sheets of one set share theirs."""
        seeds = {}
        for g, grid in enumerate(self.grids):
            history = tuple(self.histories[g])
            if len(history) > 1 and self._has_edges(g) and id(grid) not in seeds:
                first = (history[0],)
                first_order = (self.ray_map.group_grid(self.ray_map.histories.index(first))
                               if first in self.ray_map.histories else np.full(grid.shape, -1))
                seeds[id(grid)] = (SeedRays.of_rays(self.ray_map, np.flatnonzero(self._edge_rays[g]),
                                                    self._ray_spacing[g])
                                   + sub_ray_seeds(self.true_rays, self.ray_map, history, grid, first_order))
        return [seeds.get(id(grid)) for grid in self.grids]

    @functools.cached_property
    def _ray_spacing(self) -> list:
        """Per tree, (tail, direction) (R,) each: how far its rays lie from their
        neighbours in its grid (``raymap.neighbour_spacing``), 0 for rays not in it; None for
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
        """Indices of group ``g``'s answers to polish: first order, from a ray-list leaf or in
        a fold cell; every answer of a higher order, whose footprint is a few cells across
        and whose interpolated rays bend fast (the image of a small sphere in a large one:
        5 % of them 1-2.5 px off at d = 2, accepted by the ray checks)."""
        if self.true_rays is None:
            return np.zeros(0, dtype=np.int64)
        if len(self.histories[g]) > 1:
            return np.arange(len(kind))
        return np.flatnonzero((kind == RAY_LIST_LEAF) | _in_fold_cells(self.folds, g, cells))

    def _polish(self, g, risky, pixels, reflector_points, s, points, spacing, seeded: bool = False) -> np.ndarray:
        """Polish group ``g``'s ``risky`` answers (``_risky``) in place on the true reflected
        rays (true_rays.py); returns which answers stand. ``spacing``: the ray spacing at
        each point (world units per cell). ``seeded``: the pixels are rays of the ray map
        passing near the points, polished from by continuation (``polish_by_continuation``)."""
        keep = np.ones(len(pixels), dtype=bool)
        if len(risky):
            pieces = first_pieces(self.ray_map, self.grids[g]) if self.surfaces and self.surfaces[g] else None
            near = self.ray_map.triangles_at(self.grids[g], pixels[risky] / self.ray_map.downsample - 0.5)
            if seeded:
                pixels[risky], reflector_points[risky], s[risky], ok = polish_by_continuation(
                    self.true_rays, self.ray_map.view, self.histories[g], pixels[risky], points[risky],
                    self.ray_map.downsample, pieces=pieces, near_triangles=near)
            else:
                pixels[risky], reflector_points[risky], s[risky], ok = polish_on_true_rays(
                    self.true_rays, self.ray_map.view, self.histories[g], pixels[risky], points[risky],
                    self.ray_map.downsample, spacing[risky] / self.ray_map.downsample, pieces, near)
            keep[risky[~ok]] = False
        return keep

    def polish_answers(self, g: int, pixels, points, kind):
        """What ``project`` does after its interpolated answers, for answers of group ``g``
        found elsewhere (the GLSL twin, ``drawing/methods/sbc_triangles.py``): desired-view
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
        hits, _, _, confirmed = check_on_rays(self.ray_map, self._ray_table, self.grids[g], cells, points, mixed)
        spacing[hits] = confirmed
        ok = self._polish(g, self._risky(g, kind, cells), pixels, reflector_points, s, points, spacing)
        return pixels, reflector_points, s, ok

    @functools.cached_property
    def _ray_table(self) -> np.ndarray:
        """(R, 8) rows tail, direction, head distance, first-hit depth: one gather per corner."""
        m = self.ray_map
        return np.concatenate([m.tail, m.direction, m.head_distance[:, None], m.first_depth[:, None]], axis=1)


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
    chosen = order[ranks_in_runs(sorted_point) < (keep if np.isscalar(keep) else keep[sorted_point])]
    return pair_point[chosen], pair_cell[chosen]
