# SPDX-License-Identifier: GPL-3.0-or-later
"""The cells of a sample-based camera's ray map where the bilinear ray patch is not
enough, traced finer once per camera (SBC paper, Popescu, Sacks, Mei 2006, section IV-C:
ray-list leaves interpolate a finer frustum; here per cell):

- *fold* cells (:class:`FoldCells`), where a caustic crosses the cell and its four
  corner rays fold over between tail and head: (FOLD_SAMPLES + 1)^2 true rays;
- *mixed* cells (:class:`MixedCells`), where an occluder's silhouette crosses the
  cell: SUBCELL_SAMPLES^2 in-between rays, whose heads bound a point's projection.

``sbc.py`` builds them with the camera and answers from them; ``drawing/methods/sbc_pack.py``
packs them for the GLSL twin. Every answer is checked on its cell's four traced rays
(:func:`check_on_rays`), a mixed cell's sub-rays bounding it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .ray_patch import RayPatches
from .raymap import RayMap, box_exit_distance, first_pieces
from ...geometry.raytrace import ReflectorSet, reflect, reflection_valid
from ...geometry.vectors import cross, lengths

#: A projected point may lie off the ray map's interpolated ray by this many cell spacings.
MISS_CELLS = 1.0
#: Sub-rays per side traced in each *mixed* cell (see MixedCells).
SUBCELL_SAMPLES = 8
#: Sub-cells per side traced in each *fold* cell (see FoldCells).
FOLD_SAMPLES = 8
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
    ok &= ~reflector_set.from_inside(incoming, hits.triangle)
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


def check_on_rays(ray_map: RayMap, table: np.ndarray, grid: np.ndarray, cells: np.ndarray, points: np.ndarray,
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
    four = np.flatnonzero((corners[0] >= 0) & (corners[1] >= 0) & (corners[2] >= 0) & (corners[3] >= 0))
    keep = keep[four]
    corners = [c[four] for c in corners]
    frac = cells[keep] - base[keep]
    fu, fv = frac[:, 0:1], frac[:, 1:2]
    rays = [table[c] for c in corners]
    mixed = ((1 - fu) * (1 - fv)) * rays[0] + (fu * (1 - fv)) * rays[1] + ((1 - fu) * fv) * rays[2] + (fu * fv) * rays[3]
    direction = mixed[:, 3:6] / np.maximum(lengths(mixed[:, 3:6]), 1e-300)[:, None]
    head_distance = mixed[:, 6]
    blocked = ray_map.blocked
    blocked = blocked[corners[0]] | blocked[corners[1]] | blocked[corners[2]] | blocked[corners[3]]
    if mixed_cells is not None and len(mixed_cells.heads):
        row = mixed_cells.index.reshape(-1)[first[four]]
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
    miss = lengths(offset - s[:, None] * direction)
    # Spacing of neighbouring rays at distance s (the larger axis of the cell).
    along_u = lengths(rays[1][:, 0:3] - rays[0][:, 0:3] + s[:, None] * (rays[1][:, 3:6] - rays[0][:, 3:6]))
    along_v = lengths(rays[2][:, 0:3] - rays[0][:, 0:3] + s[:, None] * (rays[2][:, 3:6] - rays[0][:, 3:6]))
    ok = ((miss <= MISS_CELLS * np.maximum(along_u, along_v) + tolerance) & (s >= -tolerance)
          & (~blocked | (s <= head_distance + tolerance)))
    hits = np.flatnonzero(ok)
    return keep[hits], s[hits], mixed[hits, 7], np.minimum(along_u, along_v)[hits]
