# SPDX-License-Identifier: GPL-3.0-or-later
"""Building a sample-based camera (SBC paper, Popescu, Sacks, Mei 2006, sections III-IV):
trace the view's ray map, split each reflection group by smooth piece of its mirrors
and into sheets where its rays cross, build a BSP tree of leaf cameras per sheet, and
trace the cells the leaves cannot model (:mod:`.sbc_cells`). The camera itself, and
how it projects, is :mod:`.sbc`.
"""

from __future__ import annotations

import time

import numpy as np

from .bsp import CAMERA_LEAF, MAX_DUPLICATION, RAY_LIST_LEAF, RaysCrossError, build_bsp
from ...errors import SceneInputError
from .ray_cones import CONE_SIZE
from .raymap import RayMap, trace_ray_map
from ...geometry.raytrace import ReflectorSet
from .sbc import LEAF_MODELS, SampleBasedCamera
from .sbc_cells import FOLD_SAMPLES, trace_fold_cells, trace_mixed_cells
from ...view import View

#: Groups of at most this many rays are never split into sheets.
MIN_SHEET_RAYS = 64


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


def build_from_ray_map(ray_map: RayMap, accuracy_px: float = 1.0, leaf_model: str = "ray_patch",
                       first_order_left_out=frozenset()) -> SampleBasedCamera:
    """One BSP tree per reflection group of an existing ray map (or several, its sheets),
    but the first-order groups of the reflectors in ``first_order_left_out``."""
    if leaf_model not in LEAF_MODELS:
        raise ValueError(f"leaf_model must be one of {sorted(LEAF_MODELS)}, got {leaf_model!r}")
    if not accuracy_px > 0:
        raise ValueError(f"accuracy_px must be positive, got {accuracy_px}")
    start = time.perf_counter()
    trees, grids, histories, cones, owned, surfaces = [], [], [], [], [], []
    whole = np.array([0.0, 0.0, ray_map.columns, ray_map.rows])
    model = LEAF_MODELS[leaf_model]
    for g, history in enumerate(ray_map.histories):
        if len(history) == 1 and history[0] in first_order_left_out:
            continue
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
                            surfaces=surfaces, first_order_left_out=frozenset(first_order_left_out))
    sbc.stats = _stats(ray_map, trees, grids, seconds)
    return sbc


def build_sample_based_camera(reflectors, view: View, bounds, max_order: int = 1, downsample: int = 2,
                              accuracy_px: float = 1.0, leaf_model: str = "ray_patch",
                              first_order_left_out=frozenset()) -> SampleBasedCamera:
    """Trace the ray map of ``view`` and build its sample-based camera.

    ``reflectors`` is a list of :class:`Reflector` (or a prepared :class:`ReflectorSet`),
    ``bounds`` the scene box (lo, hi) where reflected rays end. ``first_order_left_out``:
    indices of reflectors whose first-order reflections another method draws in this
    view (the iterative search, a morphing grid): the camera is then made for the higher
    orders they start, and their first-order groups, most of the ray map, get no BSP
    tree and no traced cells, which about halves the camera's build for two facing balls
    drawn by the search at Max Order 2 (docs/benchmarks/view_change.md).
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
    sbc = build_from_ray_map(ray_map, accuracy_px, leaf_model, first_order_left_out)
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


def check_view_outside_reflectors(reflector_set: ReflectorSet, view: View) -> None:
    """Raise a clear error when a perspective eye sits inside a closed reflector.

    From inside, rays in every direction meet the back of the same reflector first
    (test: the six axis directions and the view direction).
    """
    if not view.is_perspective:
        return
    inside = enclosing_reflector(reflector_set, view.eye, -view.backward)
    if inside is not None:
        name = reflector_set.reflectors[inside].name
        raise SceneInputError(name, "the view is inside this reflector; move the camera outside it")


#: ``clip_start_inside`` tests this many points squared across the view's near plane (the
#: centres of a square lattice of cells over the image).
CLIP_START_SAMPLES = 5


def clip_start_inside(reflector_set: ReflectorSet, view: View) -> list:
    """Names of the sealed reflectors (``ReflectorSet.seal_empty_interiors``) that the
    view's near clip plane cuts into (one of :data:`CLIP_START_SAMPLES` squared points
    across it inside one), the eye being outside: the view's rays start there inside a
    closed mirror that holds nothing, and see no light (the renderer draws those pixels
    black, as Cycles shows them; Render Image and the live view say so)."""
    steps = (np.arange(CLIP_START_SAMPLES) + 0.5) / CLIP_START_SAMPLES
    xs, ys = np.meshgrid(steps * view.width, steps * view.height)
    origins, _ = view.pixel_rays(np.c_[xs.ravel(), ys.ravel()])
    inside = np.unique(_enclosing_each(reflector_set, origins, -view.backward))
    return [reflector_set.reflectors[k].name for k in inside if k >= 0 and reflector_set.sealed[k]]


def enclosing_reflector(reflector_set: ReflectorSet, point, forward) -> int | None:
    """The reflector around ``point``, if any: rays in every direction (the six axis
    directions and ``forward``) meet the back of that one reflector first."""
    inside = int(_enclosing_each(reflector_set, np.asarray(point, dtype=np.float64)[None], forward)[0])
    return None if inside < 0 else inside


def _enclosing_each(reflector_set: ReflectorSet, points, forward) -> np.ndarray:
    """(P,) the reflector around each of ``points`` (P, 3) as :func:`enclosing_reflector`
    finds it, -1 where none; their rays traced together."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    directions = np.concatenate([np.eye(3), -np.eye(3), [np.asarray(forward, dtype=np.float64)]])
    origins = np.repeat(points, len(directions), axis=0)
    rays = np.tile(directions, (len(points), 1))
    hits = reflector_set.intersect(origins, rays)
    back = hits.hit & (np.einsum("ij,ij->i", reflector_set.face_normals[np.maximum(hits.triangle, 0)], rays) > 0)
    owner = np.where(back, hits.reflector, -1).reshape(len(points), len(directions))
    one = np.all(back.reshape(owner.shape), axis=1) & np.all(owner == owner[:, :1], axis=1)
    return np.where(one, owner[:, 0], -1)


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
