# SPDX-License-Identifier: GPL-3.0-or-later
"""Sample-based cameras: where does a 3D point appear, reflected, in this view?

Popescu, Sacks, Mei (2006). The reflected rays of the desired view (ray map, section
III-B) are split into reflection groups by history; each group gets a BSP tree of leaf
cameras (section IV). A point is projected in every group: it descends the group's
tree to a leaf, the leaf's model gives the ray-map position (u, v) of the ray through
the point, and the first reflector point is the point on the desired view ray of
(u, v) at the ray map's (interpolated) first-hit depth.

A projection is accepted where the four rays around (u, v) exist in the group (the
point reflects inside the reflector's footprint, not across its silhouette) and the
point lies on their interpolated ray: in front of the mirror, and before the next
reflector where one of the four rays meets one.

``leaf_model="ray_patch"`` (default) uses our ray-field patches; ``"pinhole"`` the
paper's pinhole cameras, kept as the baseline.
"""

from __future__ import annotations

import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from .bsp import CAMERA_LEAF, MAX_DUPLICATION, RAY_LIST_LEAF, BSPTree, RaysCrossError, build_bsp
from .errors import SceneInputError
from .pinhole import PinholeLeaves
from .ray_patch import RayPatchLeaves, invert_patches
from .raymap import RayMap, trace_ray_map
from .raytrace import ReflectorSet
from .view import View

LEAF_MODELS = {"ray_patch": RayPatchLeaves(), "pinhole": PinholeLeaves()}
#: Tolerance (cell units) for a ray-list cell's bilinear coordinates.
CELL_TOLERANCE = 1e-6
#: A projected point may lie off the ray map's interpolated ray by this many cell spacings.
MISS_CELLS = 1.0
#: Threads that project parts of the points at once, and the fewest points per thread.
PROJECT_THREADS = 4
THREAD_MIN_POINTS = 20000
#: Groups of at most this many rays are never split into sheets.
MIN_SHEET_RAYS = 64
#: Ray-list cells tried per point, nearest central ray first.
CANDIDATE_CELLS = 3


@dataclass(frozen=True)
class Projection:
    """Result of :meth:`SampleBasedCamera.project` for P points and G reflection groups."""

    groups: list  # G reflection histories, tuples of reflector indices
    reflector_points: np.ndarray  # (G, P, 3) first reflector point, NaN where not projected
    valid: np.ndarray  # (G, P) bool
    leaf_kind: np.ndarray  # (G, P) int8: 0 not projected, 1 camera leaf, 2 ray-list leaf
    pixels: np.ndarray  # (G, P, 2) desired-view pixel of the reflection, NaN where not projected
    ray_distance: np.ndarray  # (G, P) distance from the last reflector point along the ray


@dataclass
class SampleBasedCamera:
    """One view's sample-based camera: a ray map and one BSP tree per reflection group."""

    ray_map: RayMap
    trees: list
    grids: list
    model_name: str
    histories: list  # one reflection history per tree (a history repeats once per sheet)
    stats: dict = field(default_factory=dict)

    @property
    def groups(self) -> list:
        return list(self.histories)

    def project(self, points) -> Projection:
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
        parts = np.array_split(finite, workers)
        if workers == 1:
            self._project_points(points, parts[0], result)
        else:
            with ThreadPoolExecutor(workers) as pool:
                list(pool.map(lambda part: self._project_points(points, part, result), parts))
        return result

    def _project_points(self, points, index, result: Projection):
        for g, (tree, grid) in enumerate(zip(self.trees, self.grids)):
            self._project_group(g, tree, grid, points[index], index, result)

    def _project_group(self, g, tree: BSPTree, grid, points, point_index, result: Projection):
        leaf = tree.leaf[descend_tree(tree, points)]
        kind = tree.leaf_kind[leaf]
        row = tree.leaf_row[leaf]
        cells = np.full((len(points), 2), np.nan)
        accepted = np.zeros(len(points), dtype=bool)

        on_camera = np.flatnonzero(kind == CAMERA_LEAF)
        if len(on_camera):
            model = LEAF_MODELS[self.model_name]
            cells[on_camera], accepted[on_camera] = model.project(tree.cameras, row[on_camera], points[on_camera], self.ray_map)
        on_list = np.flatnonzero(kind == RAY_LIST_LEAF)
        if len(on_list) and tree.cells is not None:
            cells[on_list], accepted[on_list] = _project_ray_lists(tree, row[on_list], points[on_list])

        sample = _interpolate_rays(self.ray_map, grid, cells, accepted)
        offset = points - sample["tail"]
        s = np.einsum("pd,pd->p", offset, sample["direction"])
        tolerance = 1e-6 * (1.0 + sample["head_distance"])
        # The point must lie on the ray map's own ray at that cell, within one cell's
        # spacing: this checks every leaf's answer against the traced rays themselves.
        miss = np.linalg.norm(offset - s[:, None] * sample["direction"], axis=1)
        on_ray = miss <= MISS_CELLS * _cell_spacing(sample, s) + tolerance
        # Only a head on another reflector limits the segment: where a ray merely leaves
        # the scene box, every scene point along it is in front of its end.
        before_head = ~sample["blocked"] | (s <= sample["head_distance"] + tolerance)
        ok = sample["complete"] & on_ray & (s >= -tolerance) & before_head
        hits = np.flatnonzero(ok)
        pixels = self.ray_map.cell_pixels(cells[hits])
        origins, directions = self.ray_map.view.pixel_rays(pixels)
        target = point_index[hits]
        result.reflector_points[g, target] = origins + sample["first_depth"][hits, None] * directions
        result.pixels[g, target] = pixels
        result.valid[g, target] = True
        result.leaf_kind[g, target] = kind[hits]
        result.ray_distance[g, target] = s[hits]


def descend_tree(tree: BSPTree, points: np.ndarray) -> np.ndarray:
    """Node index of the leaf each point falls in (whole arrays, one step per tree level)."""
    node = np.zeros(len(points), dtype=np.int64)
    for _ in range(tree.depth + 1):
        inner = np.flatnonzero(tree.leaf[node] < 0)
        if len(inner) == 0:
            break
        n = node[inner]
        side = np.einsum("pd,pd->p", points[inner], tree.plane_normal[n]) >= tree.plane_offset[n]
        node[inner] = np.where(side, tree.left[n], tree.right[n])
    return node


def _project_ray_lists(tree: BSPTree, row, points):
    """Find, among a ray-list leaf's cells, the one whose bilinear ray patch holds the point.

    Newton runs only on the few cells whose central ray passes closest to the point.
    """
    start, stop = tree.cell_start[row], tree.cell_start[row + 1]
    count = stop - start
    pair_point = np.repeat(np.arange(len(points)), count)
    pair_cell = np.repeat(start - np.cumsum(count) + count, count) + np.arange(count.sum())
    pair_point, pair_cell = _closest_cells(tree.cells, pair_point, pair_cell, points)
    cells, distance, residual = invert_patches(tree.cells, pair_cell, points[pair_point])
    local = cells - tree.cells.lo[pair_cell]
    inside = (np.all((local >= -CELL_TOLERANCE) & (local <= 1 + CELL_TOLERANCE), axis=1)
              & (residual < 1e-6 * (1 + np.linalg.norm(points[pair_point], axis=1))) & (distance >= 0))
    result = np.full((len(points), 2), np.nan)
    found = np.zeros(len(points), dtype=bool)
    first = np.flatnonzero(inside)[::-1]  # reversed so the first match per point is written last
    result[pair_point[first]] = cells[first]
    found[pair_point[first]] = True
    return result, found


def _closest_cells(cells, pair_point, pair_cell, points, keep: int = CANDIDATE_CELLS):
    """Per point, the ``keep`` (point, cell) pairs whose cell-centre ray passes closest.

    Cells whose central ray passes farther from the point than twice the cell's size at
    that depth cannot hold it and are dropped first (no effect on the result, only on
    the work: a point usually lies near few of a ray-list leaf's cells).
    """
    centre_tail, centre_direction, size, spread = cells.centre_rays
    offset = points[pair_point] - centre_tail[pair_cell]
    along = np.maximum(np.einsum("ij,ij->i", offset, centre_direction[pair_cell]), 0.0)
    miss = np.linalg.norm(np.cross(offset, centre_direction[pair_cell]), axis=1)
    near = miss <= 2.0 * (size[pair_cell] + along * spread[pair_cell])
    pair_point, pair_cell, miss = pair_point[near], pair_cell[near], miss[near]
    order = np.lexsort((miss, pair_point))
    sorted_point = pair_point[order]
    group_start = np.flatnonzero(np.concatenate([[True], sorted_point[1:] != sorted_point[:-1]]))
    rank = np.arange(len(order)) - np.repeat(group_start, np.diff(np.concatenate([group_start, [len(order)]])))
    chosen = order[rank < keep]
    return pair_point[chosen], pair_cell[chosen]


def _interpolate_rays(ray_map: RayMap, grid: np.ndarray, cells: np.ndarray, accepted: np.ndarray) -> dict:
    """Bilinear interpolation of the ray map's rays at fractional cells of one group."""
    base = np.floor(np.nan_to_num(cells, nan=-10.0)).astype(np.int64)
    frac = np.nan_to_num(cells - base)
    rows, columns = grid.shape
    i0, j0 = base[:, 0], base[:, 1]
    inside = accepted & (i0 >= 0) & (j0 >= 0) & (i0 + 1 < columns) & (j0 + 1 < rows)
    i0c, j0c = np.clip(i0, 0, columns - 2), np.clip(j0, 0, rows - 2)
    corners = np.stack([grid[j0c, i0c], grid[j0c, i0c + 1], grid[j0c + 1, i0c], grid[j0c + 1, i0c + 1]], axis=1)
    complete = inside & np.all(corners >= 0, axis=1)
    corners = np.maximum(corners, 0)
    fu, fv = frac[:, 0], frac[:, 1]
    weights = np.stack([(1 - fu) * (1 - fv), fu * (1 - fv), (1 - fu) * fv, fu * fv], axis=1)
    direction = np.einsum("pk,pkd->pd", weights, ray_map.direction[corners])
    direction /= np.maximum(np.linalg.norm(direction, axis=1), 1e-300)[:, None]
    return {
        "complete": complete,
        "corner_tails": ray_map.tail[corners],
        "corner_directions": ray_map.direction[corners],
        "tail": np.einsum("pk,pkd->pd", weights, ray_map.tail[corners]),
        "direction": direction,
        "head_distance": np.einsum("pk,pk->p", weights, ray_map.head_distance[corners]),
        "blocked": ray_map.blocked[corners].any(axis=1),
        "first_depth": np.einsum("pk,pk->p", weights, ray_map.first_depth[corners]),
    }


def _cell_spacing(sample: dict, s: np.ndarray) -> np.ndarray:
    """Distance between neighbouring rays of the cell at ray distance ``s`` (the larger axis)."""
    ends = sample["corner_tails"] + s[:, None, None] * sample["corner_directions"]
    along_u = np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1)
    along_v = np.linalg.norm(ends[:, 2] - ends[:, 0], axis=1)
    return np.maximum(along_u, along_v)


def _build_sheets(ray_map: RayMap, rays: np.ndarray, grid: np.ndarray, model, accuracy_px: float) -> list:
    """Trees for one group's rays, split into sheets where the rays cross in space.

    Where rays of one history cross (a concave mirror's caustic, or two parts of a
    mirror reflecting the same region: the Chen-Arvo vase shows points twice), no
    plane separates them and the BSP duplicates rays without end. The rays are then
    halved in ray-map space (at the median cell along the longer side, both halves
    keeping the seam's line of rays) and each half gets its own tree, its own *sheet*,
    recursively. A point may project in several sheets of one history: those are its
    several images (or, right at a seam, one image twice).
    """
    try:
        return [build_bsp(ray_map, rays, grid, model, accuracy_px,
                          max_duplication=None if len(rays) <= MIN_SHEET_RAYS else MAX_DUPLICATION)]
    except RaysCrossError:
        cells = ray_map.cell[rays]
        axis = int(np.argmax(cells.max(axis=0) - cells.min(axis=0)))
        seam = np.floor(np.median(cells[:, axis]))
        # Both halves keep the seam's line of rays, so the cells across the seam (four
        # corner rays, two on each side) belong to the upper sheet: no line of holes.
        low, high = cells[:, axis] <= seam, cells[:, axis] >= seam
        if low.all() or high.all():
            return [build_bsp(ray_map, rays, grid, model, accuracy_px, max_duplication=None)]
        return (_build_sheets(ray_map, rays[low], grid, model, accuracy_px)
                + _build_sheets(ray_map, rays[high], grid, model, accuracy_px))


def build_from_ray_map(ray_map: RayMap, accuracy_px: float = 1.0, leaf_model: str = "ray_patch") -> SampleBasedCamera:
    """One BSP tree per reflection group of an existing ray map."""
    if leaf_model not in LEAF_MODELS:
        raise ValueError(f"leaf_model must be one of {sorted(LEAF_MODELS)}, got {leaf_model!r}")
    if not accuracy_px > 0:
        raise ValueError(f"accuracy_px must be positive, got {accuracy_px}")
    start = time.perf_counter()
    trees, grids, histories = [], [], []
    for g, history in enumerate(ray_map.histories):
        grid = ray_map.group_grid(g)
        model, rays = LEAF_MODELS[leaf_model], np.flatnonzero(ray_map.group == g)
        sheets = (_build_sheets(ray_map, rays, grid, model, accuracy_px) if model.splits_into_sheets
                  else [build_bsp(ray_map, rays, grid, model, accuracy_px, max_duplication=None)])
        for tree in sheets:
            trees.append(tree)
            grids.append(grid)
            histories.append(history)
    seconds = time.perf_counter() - start
    sbc = SampleBasedCamera(ray_map, trees, grids, leaf_model, histories)
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
    sbc.stats["trace_seconds"] = trace_seconds
    return sbc


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
        "rays_per_leaf": float(rays_in_leaves.mean()) if len(rays_in_leaves) else 0.0,
        "max_depth": int(max((t.depth for t in trees), default=0)),
        "build_seconds": seconds,
        "nbytes": int(sum(t.nbytes for t in trees) + sum(g.nbytes for g in grids)),
    }
