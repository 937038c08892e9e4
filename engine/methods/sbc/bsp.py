# SPDX-License-Identifier: GPL-3.0-or-later
"""BSP trees of leaf cameras over one reflection group (SBC paper, section IV, Fig. 10).

    BuildBSP(rays, accuracy):
        camera = Fit(rays)
        if Error(camera, rays) < accuracy: return Leaf(camera)
        (plane, positive, negative) = Split(rays)
        if the split fails: return Leaf(rays)
        return Node(plane, BuildBSP(positive), BuildBSP(negative))

The recursion is run breadth-first, one tree level at a time, with every node of the
level fitted, measured and split in whole-array operations (members are (node, ray)
rows). The split plane passes through the centroid of the tails, contains the mean ray
direction and is perpendicular to the tails' diameter (their principal axis across the
mean direction). A ray goes to the side(s) its *unit frustum* reaches: the tails and
heads of the ray and of its four diagonal neighbours (u +- 1, v +- 1); rays whose
frustum straddles the plane go to both children, so a point between rays always finds
all four rays around it in its leaf. A split fails when one side receives every ray;
the rays are then kept in a ray-list leaf, whose cells (four member rays around a
unit square of the ray map) project by bilinear ray patches.

Where a node's rays focus in front of the mirror, no patch holds near the focus however
small the node, yet it holds before and after: such a node becomes a camera leaf with a
*band* of depth along its rays whose points its own cells answer (``_depth_bands``).

A point is answered in the leaf it descends to (:func:`descend_tree`), by the leaf's ray
list where it lies in the leaf's band (:func:`to_fallback`); the leaves' bounding cones
(``ray_cones.py``) let projection skip the points a leaf cannot answer.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .ray_cones import ray_cones, reachable_rays
from .ray_patch import ERROR_SAMPLE_FRACTIONS, RayPatches, fit_patches
from .raymap import RayMap, grid_neighbour
from ...geometry.segments import range_offsets, segment_mean, segment_sum
from ...geometry.vectors import cross

MAX_DEPTH = 40
#: A tree whose leaves hold, in all, more than this many times the group's rays is
#: abandoned: its rays cross in space (several images, caustics) and no plane separates them.
MAX_DUPLICATION = 6.0


#: A split that fails on a node of more rays than this means crossing rays too.
MAX_RAY_LIST_RAYS = 64
#: A camera leaf's band where it has none (lo < s < hi holds for no s); see _depth_bands.
NO_BAND = np.array([0.0, 0.0])
#: Band ends open toward the tail or past the head (finite, for float32 textures).
BAND_INFINITY = 1e30
#: Nodes of at most this many rays may become banded camera leaves.
MAX_BAND_RAYS = 64
#: A band is excused only where at least this share of the node's rays focus in it.
FOCUSING_SHARE = 0.75
#: Fractions of the ray sampled between a band's coarse ends, to narrow it.
BAND_REFINEMENT = 8


class RaysCrossError(Exception):
    """The rays of a group overlap in space too much for planes to separate them."""
CAMERA_LEAF, RAY_LIST_LEAF = 1, 2


@dataclass(frozen=True)
class BSPTree:
    """Flat arrays of one group's tree; node 0 is the root.

    Internal nodes: ``plane_normal`` . p >= ``plane_offset`` goes to ``left``, else
    ``right``. Leaf nodes have ``leaf`` >= 0, an index into ``leaf_kind`` and
    ``leaf_row`` (row in ``cameras`` for camera leaves, in ``cell_start`` for ray lists).
    """

    plane_normal: np.ndarray
    plane_offset: np.ndarray
    left: np.ndarray
    right: np.ndarray
    leaf: np.ndarray
    leaf_kind: np.ndarray
    leaf_row: np.ndarray
    leaf_rays: np.ndarray  # (n_leaves,) rays per leaf (duplicates counted)
    cameras: object  # the leaf model's parameters, one row per camera leaf (None if none)
    cell_start: np.ndarray  # (n_raylist + 1,) CSR offsets into ``cells``
    cells: RayPatches | None  # bilinear patches of the ray-list leaves' cells
    depth: int
    leaf_cones: np.ndarray | None = None  # (n_leaves, CONE_SIZE) bounding cones (``ray_cones.py``)
    cone: np.ndarray | None = None  # (CONE_SIZE,) bounding cone of the whole tree
    #: (n_cameras, 2) per camera leaf, the band of distance along its rays, lo < s < hi,
    #: where its answers are not trusted (_depth_bands); NO_BAND where there is none.
    camera_band: np.ndarray | None = None
    #: (n_leaves,) per leaf, the ray-list row (into ``cell_start``) that answers a banded
    #: camera leaf's points in its band or where its Newton fails; -1 where none.
    leaf_fallback: np.ndarray | None = None
    #: (n_raylist + 1,) CSR offsets into ``list_rays``, and the rays each ray-list row
    #: holds: its leaf's rays, with those no complete cell of the leaf has (a strip one
    #: ray wide along a sharp edge of the mirror), which seed sbc's answers across it.
    list_ray_start: np.ndarray | None = None
    list_rays: np.ndarray | None = None

    @property
    def nbytes(self) -> int:
        optional = (self.leaf_cones, self.camera_band, self.leaf_fallback, self.list_ray_start, self.list_rays)
        arrays = (self.plane_normal, self.plane_offset, self.left, self.right, self.leaf, self.leaf_kind,
                  self.leaf_row, self.cell_start) + tuple(a for a in optional if a is not None)
        models = [m.nbytes for m in (self.cameras, self.cells) if m is not None]
        return int(sum(a.nbytes for a in arrays)) + int(sum(models))


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
    """Which points of camera leaves go to the leaf's ray list (:func:`_depth_bands`): those
    of a banded leaf whose distance along the ray lies in its band, or is NaN (Newton did
    not converge: near the band the patch is ill-conditioned). So do answers its fold
    cell refuses (``SampleBasedCamera._project_group``). An answer outside the leaf's
    cells is not handed on: outside its band the patch is accurate, so the point is not
    on the leaf's rays."""
    return (tree.leaf_fallback[leaf] >= 0) & (in_band(tree, camera_row, distance) | np.isnan(distance))


def in_band(tree: BSPTree, camera_row, distance) -> np.ndarray:
    """Whether distances along the rays of camera leaves lie in the leaves' bands
    (:func:`_depth_bands`), where their patches are not trusted; False where NaN."""
    band = tree.camera_band[camera_row]
    with np.errstate(invalid="ignore"):
        return (distance > band[:, 0]) & (distance < band[:, 1])


def diagonal_neighbours(ray_map: RayMap, grid: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """(R, 4) ray indices of each ray's unit-frustum corners in its group; itself where missing.

    ``grid`` is the group's ray index per cell (RayMap.group_grid).
    """
    i, j = ray_map.cell[rays, 0], ray_map.cell[rays, 1]
    corners = []
    for di, dj in ((-1, -1), (1, -1), (-1, 1), (1, 1)):
        neighbour = grid_neighbour(grid, i, j, di, dj)
        corners.append(np.where(neighbour >= 0, neighbour, rays))
    return np.stack(corners, axis=1)


def unit_frustum_points(ray_map: RayMap, grid: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """(R, 10, 3): tails and heads of each ray and its four diagonal neighbours (the paper's
    unit frustum)."""
    frustum = np.concatenate([rays[:, None], diagonal_neighbours(ray_map, grid, rays)], axis=1)
    return np.concatenate([ray_map.tail[frustum], ray_map.head[frustum]], axis=1)


def half_frustum_points(ray_map: RayMap, grid: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """(R, 10, 3): tail and head of each ray and the midpoints toward its diagonal neighbours.

    The paper assigns a ray to every side its unit frustum (the four diagonal
    neighbours) reaches, so that a leaf holds every ray around any point in it. Leaves
    here accept points up to half a cell beyond their rays, and every projection is
    checked against the ray map itself, so half the frustum suffices; near grazing
    angles, where neighbouring rays fan far apart at their heads, this cuts the
    duplication of rays across split planes several times over.
    """
    own = np.repeat(np.stack([ray_map.tail[rays], ray_map.head[rays]], axis=1), 5, axis=1)
    return 0.5 * (unit_frustum_points(ray_map, grid, rays) + own)


def build_bsp(ray_map: RayMap, rays: np.ndarray, grid: np.ndarray, model, accuracy_px: float,
              max_duplication: float | None = MAX_DUPLICATION) -> BSPTree:
    """Build the BSP tree of rays that share one history; ``grid`` is that group's
    ray index per cell (RayMap.group_grid).

    Raises :class:`RaysCrossError` when the rays held by the nodes of a level exceed
    ``max_duplication`` times the input, or a split fails on more than
    ``MAX_RAY_LIST_RAYS`` rays (with ``max_duplication=None`` neither is checked).
    """
    frustum_points = (half_frustum_points(ray_map, grid, rays) if model.half_frustum
                      else unit_frustum_points(ray_map, grid, rays))
    focal = focal_distances(ray_map, grid, rays) if model.depth_bands else None

    levels = []  # one record of whole arrays per tree level
    camera_parts, camera_bands, raylist_rows, raylist_rays, leaf_nodes, leaf_rays = [], [], [], [], [], []
    n_nodes, n_cameras, n_raylists = 1, 0, 0
    level_ids = np.zeros(1, dtype=np.int64)
    member_node = np.zeros(len(rays), dtype=np.int64)  # node rows local to the level
    member_slot = np.arange(len(rays))
    for depth in range(MAX_DEPTH + 1):
        n = len(level_ids)
        member_ray = rays[member_slot]
        params = model.fit(ray_map, member_ray, member_node, n)
        counts = np.bincount(member_node, minlength=n)
        well_posed = model.well_posed(params, counts)
        is_camera = _within_accuracy(ray_map, model, params, member_ray, member_node, accuracy_px, well_posed)
        band = np.broadcast_to(NO_BAND, (n, 2))
        if model.depth_bands:
            banded, band = _depth_bands(ray_map, grid, model, params, member_ray, member_node, accuracy_px,
                                        well_posed & ~is_camera & (counts <= MAX_BAND_RAYS),
                                        focal[member_slot])
            is_camera |= banded
        plane_normal, plane_offset = _split_planes(ray_map, member_ray, member_node, n)
        side = (np.einsum("mkd,md->mk", frustum_points[member_slot], plane_normal[member_node])
                - plane_offset[member_node, None])
        positive, negative = side.max(axis=1) >= 0, side.min(axis=1) < 0
        fails = ((np.bincount(member_node, weights=positive, minlength=n) == counts)
                 | (np.bincount(member_node, weights=negative, minlength=n) == counts) | (depth == MAX_DEPTH)
                 | ~well_posed)  # subsets of an ill-posed node are ill-posed too: stop here
        kind = np.where(is_camera, CAMERA_LEAF, np.where(fails, RAY_LIST_LEAF, 0))
        if max_duplication is not None and np.any((kind == RAY_LIST_LEAF) & (counts > MAX_RAY_LIST_RAYS)):
            raise RaysCrossError(f"a split of {counts[kind == RAY_LIST_LEAF].max()} rays failed at depth {depth}")

        row = np.full(n, -1, dtype=np.int64)
        cameras_here, raylists_here = kind == CAMERA_LEAF, kind == RAY_LIST_LEAF
        row[cameras_here] = n_cameras + np.arange(cameras_here.sum())
        # Ray-list rows: ray-list leaves, and banded camera leaves' fallbacks.
        listed = raylists_here | (cameras_here & (band[:, 0] < band[:, 1]))
        list_row = np.full(n, -1, dtype=np.int64)
        list_row[listed] = n_raylists + np.arange(listed.sum())
        row[raylists_here] = list_row[raylists_here]
        fallback = np.where(cameras_here, list_row, -1)
        if cameras_here.any():
            camera_parts.append(params.take(np.flatnonzero(cameras_here)))
            camera_bands.append(band[cameras_here])
        in_leaf = kind[member_node] > 0
        leaf_nodes.append(level_ids[member_node[in_leaf]])
        leaf_rays.append(member_ray[in_leaf])
        in_raylist = listed[member_node]
        raylist_rows.append(list_row[member_node[in_raylist]])
        raylist_rays.append(member_ray[in_raylist])
        n_cameras += int(cameras_here.sum())
        n_raylists += int(listed.sum())

        splits = kind == 0
        child = np.full((n, 2), -1, dtype=np.int64)
        child[splits] = n_nodes + np.arange(2 * splits.sum()).reshape(-1, 2)
        levels.append((level_ids, kind, row, counts, plane_normal, plane_offset, child, fallback))
        if not splits.any():
            break
        n_nodes += 2 * int(splits.sum())
        goes_left, goes_right = splits[member_node] & positive, splits[member_node] & negative
        local_child = np.full((n, 2), -1, dtype=np.int64)
        local_child[splits] = np.arange(2 * splits.sum()).reshape(-1, 2)
        member_node = np.concatenate([local_child[member_node[goes_left], 0], local_child[member_node[goes_right], 1]])
        member_slot = np.concatenate([member_slot[goes_left], member_slot[goes_right]])
        if max_duplication is not None and len(member_slot) > max_duplication * len(rays):
            raise RaysCrossError(f"{len(member_slot)} memberships for {len(rays)} rays at depth {depth + 1}")
        level_ids = child[splits].reshape(-1)

    raylist_rows, raylist_rays = np.concatenate(raylist_rows), np.concatenate(raylist_rays)
    cell_start, cells = _raylist_cells(ray_map, grid, raylist_rows, raylist_rays, n_raylists)
    order = np.argsort(raylist_rows, kind="stable")
    list_ray_start = range_offsets(raylist_rows, n_raylists)
    tree = _assemble_tree(levels, n_nodes, model, camera_parts, camera_bands, cell_start, cells, depth)
    reach_ray, reach_leaf = reachable_rays(ray_map, grid, np.concatenate(leaf_rays),
                                           tree.leaf[np.concatenate(leaf_nodes)], len(tree.leaf_kind))
    cones = ray_cones(ray_map, grid, reach_ray, reach_leaf, len(tree.leaf_kind))
    whole = ray_cones(ray_map, grid, np.unique(reach_ray), np.zeros(len(np.unique(reach_ray)), np.int64), 1)[0]
    return dataclasses.replace(tree, leaf_cones=cones, cone=whole, list_ray_start=list_ray_start,
                               list_rays=raylist_rays[order])


def _assemble_tree(levels, n_nodes, model, camera_parts, camera_bands, cell_start, cells, depth) -> BSPTree:
    ids, kind, row, counts, normal, offset, child, fallback = (np.concatenate(parts) for parts in zip(*levels))
    order = np.argsort(ids)
    kind, row, counts, normal, offset, child, fallback = (
        kind[order], row[order], counts[order], normal[order], offset[order], child[order], fallback[order])
    is_leaf = kind > 0
    leaf = np.full(n_nodes, -1, dtype=np.int64)
    leaf[is_leaf] = np.arange(is_leaf.sum())
    return BSPTree(
        plane_normal=np.where(is_leaf[:, None], 0.0, normal), plane_offset=np.where(is_leaf, 0.0, offset),
        left=child[:, 0], right=child[:, 1], leaf=leaf, leaf_kind=kind[is_leaf].astype(np.int8),
        leaf_row=row[is_leaf], leaf_rays=counts[is_leaf],
        cameras=model.concatenate(camera_parts) if camera_parts else None,
        cell_start=cell_start, cells=cells, depth=depth,
        camera_band=np.concatenate(camera_bands) if camera_bands else np.zeros((0, 2)),
        leaf_fallback=fallback[is_leaf],
    )


#: Errors of a level's members are measured in stages: every ERROR_PROBE_STRIDES[0]-th row
#: first, then every [1]-th of the rows still unmeasured in nodes still passing, ..., then
#: the rest. Each stage is one Newton call, which costs about as much as ~500 error samples
#: in numpy's per-call overhead, so a stage is only split off from at least
#: ERROR_PROBE_MIN_ROWS rows.
ERROR_PROBE_STRIDES = (8, 2)
ERROR_PROBE_MIN_ROWS = 256


def _within_accuracy(ray_map, model, params, member_ray, member_node, accuracy_px, candidates) -> np.ndarray:
    """(n,) bool: every error sample of the node's rays projects within ``accuracy_px``
    (the test of BuildBSP, SBC paper IV Fig. 10: Error(camera, rays) < accuracy).

    The same answer as measuring every sample of every candidate node and comparing the
    nodes' largest errors with the accuracy, for less work: a node fails on its first bad
    sample, so errors are measured on strided probes of the members first and only the
    nodes still passing are measured on more. In the upper levels nearly every node
    fails the first probe, which is most of the saving (measuring every sample's Newton
    inversion would be half of a morphing node's build); nodes that are not ``candidates``
    (ill-posed) are never measured. Each sample is measured as before, so the tree is
    the same.
    """
    passing = candidates.copy()
    unmeasured = np.ones(len(member_ray), dtype=bool)
    for stride in ERROR_PROBE_STRIDES + (1,):
        rows = np.flatnonzero(unmeasured & passing[member_node])
        if stride > 1 and len(rows) < ERROR_PROBE_MIN_ROWS:
            continue
        rows = rows[::stride]
        if len(rows) == 0:
            break
        unmeasured[rows] = False
        owner, good = _sample_within(ray_map, model, params, member_ray[rows], member_node[rows], accuracy_px)
        passing[member_node[rows[owner[~good]]]] = False
    return passing


def _sample_within(ray_map, model, params, member_ray, member_node, accuracy_px):
    """Error samples of members (owner row per sample) and whether each is within accuracy."""
    owner, points = model.error_samples(ray_map, member_ray)
    return owner, _projects_within(ray_map, model, params, member_ray[owner], member_node[owner], points,
                                   accuracy_px)


def _projects_within(ray_map, model, params, ray, node, points, accuracy_px) -> np.ndarray:
    """Whether each point, sampled on ``ray``, projects in ``node``'s leaf model within
    ``accuracy_px`` desired-view pixels of that ray's cell."""
    cells, inside, _ = model.project(params, node, points, ray_map)
    error = np.linalg.norm(cells - ray_map.cell[ray], axis=1) * ray_map.downsample
    with np.errstate(invalid="ignore"):
        return inside & (error <= accuracy_px)


def _depth_bands(ray_map, grid, model, params, member_ray, member_node, accuracy_px, candidates, focal):
    """Camera leaves that hold along their rays everywhere but in one band of depth.

    Where a leaf's rays focus (the neck of a vase, any concave stretch of mirror), they
    cross near their focal distance: a point there lies on several of the leaf's rays
    and its cell is ill-conditioned, so no patch keeps within the accuracy over that
    depth however small the leaf, and the node would end as a ray list. Before and
    after the crossing the patch holds. Such a node becomes a camera leaf with a *band*:
    the distances along its rays between the nearest passing error samples on either
    side of all its failing ones. Answers in the band, and points whose Newton fails,
    are answered by the leaf's ray list (its cells, as a ray-list leaf's); every answer
    outside it keeps the measured accuracy. The band is found at the error samples of
    ``model.error_samples``, then narrowed at BAND_REFINEMENT more fractions between
    its ends. A node is banded only where that is the cause: the patch holds next to
    the mirror (the band starts past the first samples) and at least FOCUSING_SHARE of
    its rays focus inside the band (``focal_distances``); where the patch is merely too
    coarse (a crease, a tight fillet) splitting the node does better.

    Returns (n,) which ``candidates`` are banded leaves and their (n, 2) bands (lo, hi)
    in distance along the ray (NO_BAND for the others).
    """
    n = len(candidates)
    band = np.tile(NO_BAND, (n, 1))
    with np.errstate(invalid="ignore"):
        ahead = np.any(focal > 0, axis=1)  # a focus in front of the mirror: necessary for a band
    candidates = candidates & (np.bincount(member_node, weights=ahead, minlength=n)
                               >= FOCUSING_SHARE * np.bincount(member_node, minlength=n))
    rows = np.flatnonzero(candidates[member_node])
    if len(rows) == 0:
        return np.zeros(n, dtype=bool), band
    rays, nodes = member_ray[rows], member_node[rows]
    coarse = np.broadcast_to(ERROR_SAMPLE_FRACTIONS, (len(rows), len(ERROR_SAMPLE_FRACTIONS)))
    samples = [_fraction_samples(ray_map, model, params, rays, nodes, coarse, accuracy_px)]
    low, high = _band_ends(*samples[0], n)
    # Narrow the band between its coarse ends (0 and 1 where the tail or head fails).
    start, stop = np.maximum(low, 0.0)[nodes], np.minimum(high, 1.0)[nodes]
    steps = np.linspace(0.0, 1.0, BAND_REFINEMENT + 2)[1:-1]
    samples.append(_fraction_samples(ray_map, model, params, rays, nodes,
                                     start[:, None] + (stop - start)[:, None] * steps, accuracy_px))
    low, high = _band_ends(*(np.concatenate(column) for column in zip(*samples)), n)
    head = ray_map.head_distance[rays]
    shortest, longest = np.full(n, np.inf), np.zeros(n)
    np.minimum.at(shortest, nodes, head)
    np.maximum.at(longest, nodes, head)
    with np.errstate(invalid="ignore"):
        lo = np.maximum(low * shortest, -BAND_INFINITY)
        hi = np.minimum(high * longest, BAND_INFINITY)
        focuses = np.any((focal[rows] > lo[nodes, None]) & (focal[rows] < hi[nodes, None]), axis=1)
    focusing = np.bincount(nodes[focuses], minlength=n) >= FOCUSING_SHARE * np.bincount(nodes, minlength=n)
    # The band's points need cells to be answered in.
    with_cells = np.bincount(_complete_cells(ray_map, grid, nodes, rays)[0], minlength=n) > 0
    banded = candidates & (low > 0) & focusing & with_cells
    band[banded, 0], band[banded, 1] = lo[banded], hi[banded]
    return banded, band


def focal_distances(ray_map: RayMap, grid: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """(R, 2) distances along each ray where its neighbours cross it (its focal points),
    NaN where there is none (or a neighbour is missing).

    The rays t(u, v) + s r(u, v) around a ray focus where the Jacobian columns
    t_u + s r_u, t_v + s r_v and r are coplanar: det(t_u + s r_u, t_v + s r_v, r) = 0, a
    quadratic in s, with derivatives by central differences over the ray map (the two
    focal distances of the reflected wavefront, Chen-Arvo 2000 section 3; where the
    ray field folds over, its caustic).
    """
    i, j = ray_map.cell[rays, 0], ray_map.cell[rays, 1]
    east, west, north, south = (grid_neighbour(grid, i, j, di, dj) for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1)))
    complete = (east >= 0) & (west >= 0) & (north >= 0) & (south >= 0)
    t, r = ray_map.tail, ray_map.direction
    e, w, nn, ss = (np.maximum(x, 0) for x in (east, west, north, south))
    t_u, r_u, t_v, r_v = t[e] - t[w], r[e] - r[w], t[nn] - t[ss], r[nn] - r[ss]
    direction = r[rays]

    def det(a, b):
        return np.einsum("rd,rd->r", cross(a, b), direction)

    c0, c1, c2 = det(t_u, t_v), det(t_u, r_v) + det(r_u, t_v), det(r_u, r_v)
    with np.errstate(divide="ignore", invalid="ignore"):
        root = np.sqrt(c1 * c1 - 4 * c0 * c2)
        focal = np.stack([(-c1 - root) / (2 * c2), (-c1 + root) / (2 * c2)], axis=1)
    focal[~complete] = np.nan
    return focal


def _fraction_samples(ray_map, model, params, rays, nodes, fractions, accuracy_px):
    """(node, fraction, within accuracy) of every error sample at ``fractions`` (R, K) of
    the rays' tail-to-head segments."""
    owner, points = model.error_samples(ray_map, rays, fractions)
    return nodes[owner], fractions.reshape(-1), _projects_within(ray_map, model, params, rays[owner], nodes[owner],
                                                                 points, accuracy_px)


def _band_ends(node, fraction, good, n):
    """Per node, the largest passing fraction below every failing sample (-inf if none)
    and the smallest passing one above them all (+inf if none); NaN where none fails."""
    first_fail, last_fail = np.full(n, np.inf), np.full(n, -np.inf)
    np.minimum.at(first_fail, node[~good], fraction[~good])
    np.maximum.at(last_fail, node[~good], fraction[~good])
    below = good & (fraction < first_fail[node])
    above = good & (fraction > last_fail[node])
    low, high = np.full(n, -np.inf), np.full(n, np.inf)
    np.maximum.at(low, node[below], fraction[below])
    np.minimum.at(high, node[above], fraction[above])
    fails = np.isfinite(first_fail)
    return np.where(fails, low, np.nan), np.where(fails, high, np.nan)


def _split_planes(ray_map, member_ray, member_node, n):
    """Plane through the tails' centroid, along the mean direction, across the tails' diameter."""
    tails = ray_map.tail[member_ray]
    centroid = segment_mean(tails, member_node, n)
    mean_direction = segment_mean(ray_map.direction[member_ray], member_node, n)
    mean_direction /= np.maximum(np.linalg.norm(mean_direction, axis=1), 1e-300)[:, None]
    offset = tails - centroid[member_node]
    offset -= np.einsum("md,md->m", offset, mean_direction[member_node])[:, None] * mean_direction[member_node]
    covariance = segment_sum(offset[:, :, None] * offset[:, None, :], member_node, n)
    _, vectors = np.linalg.eigh(covariance)
    normal = vectors[:, :, 2]
    return normal, np.einsum("nd,nd->n", normal, centroid)


def _complete_cells(ray_map: RayMap, grid: np.ndarray, owner: np.ndarray, ray: np.ndarray):
    """Unit cells of the ray map whose four corner rays all belong to one owner (members
    given as (owner, ray) rows): (owner, (C, 4) corner rays 00, 10, 01, 11) per cell."""
    i, j = ray_map.cell[ray, 0], ray_map.cell[ray, 1]
    inside = (i + 1 < ray_map.columns) & (j + 1 < ray_map.rows)
    owner, ray, i, j = owner[inside], ray[inside], i[inside], j[inside]
    corners = np.stack([ray, grid[j, i + 1], grid[j + 1, i], grid[j + 1, i + 1]], axis=1)
    member_keys = owner * ray_map.n_rays + ray
    complete = np.all(corners >= 0, axis=1)
    for k in range(1, 4):
        complete &= np.isin(owner * ray_map.n_rays + corners[:, k], member_keys)
    return owner[complete], corners[complete]


def _raylist_cells(ray_map: RayMap, grid: np.ndarray, leaf_row, ray, n_raylists):
    """Unit cells whose four corner rays all belong to one ray-list leaf, as bilinear patches.

    Returns CSR offsets (n_raylists + 1,) and the patches, sorted by ray-list leaf.
    """
    if len(ray) == 0:
        return np.zeros(n_raylists + 1, dtype=np.int64), None
    leaf_row, corners = _complete_cells(ray_map, grid, leaf_row, ray)
    order = np.argsort(leaf_row, kind="stable")
    leaf_row, corners = leaf_row[order], corners[order]
    cell_start = range_offsets(leaf_row, n_raylists)
    if len(corners) == 0:
        return cell_start, None
    rays = corners.reshape(-1)
    node = np.repeat(np.arange(len(corners)), 4)
    patches = fit_patches(ray_map.cell[rays], ray_map.tail[rays], ray_map.direction[rays], node, len(corners),
                          bilinear=True)
    return cell_start, patches
