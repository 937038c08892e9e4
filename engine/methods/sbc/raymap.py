# SPDX-License-Identifier: GPL-3.0-or-later
"""Ray maps: the reflected rays of a desired view, one per down-sampled pixel and order.

SBC paper (Popescu, Sacks, Mei 2006), section III-B: a view ray that hits a reflector is
reflected, and traced on through the reflectors alone (not the diffuse scene) for
higher orders. Each reflected segment is stored as a ray with

- its *reflection history*: the reflectors met so far, e.g. (0,) or (0, 1);
- its *first reflector point* (where the reflection appears in the view);
- its *tail* (the last reflector point) and unit *direction*;
- its *head*: the end of the segment, at the next reflector it hits or where it
  leaves the scene box, whichever comes first, since points beyond are not seen there.

Rays are stored flat (one row per pixel and order) with the ray-map cell (column, row)
they come from; ray-map cell (i, j) is the desired-view pixel centre (d (i + 0.5),
d (j + 0.5)) for down-sampling factor d.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import SceneInputError
from ...geometry.raytrace import ReflectorSet, reflect, reflection_valid
from ...geometry.vectors import cross
from ...view import View


@dataclass(frozen=True)
class RayMap:
    """Reflected rays of one view; row k describes one ray of one ray-map cell."""

    view: View
    downsample: int
    columns: int
    rows: int
    histories: list  # list of tuples of reflector indices; ``group`` indexes it
    cell: np.ndarray  # (R, 2) int ray-map cell (i, j)
    order: np.ndarray  # (R,) int reflection order, 1 = first
    group: np.ndarray  # (R,) int index into histories
    first_point: np.ndarray  # (R, 3)
    first_depth: np.ndarray  # (R,) distance from the view ray's origin to the first point
    tail: np.ndarray  # (R, 3)
    direction: np.ndarray  # (R, 3) unit
    head_distance: np.ndarray  # (R,) length of the segment from tail to head
    triangle: np.ndarray  # (R,) triangle of the tail
    blocked: np.ndarray  # (R,) bool: the head is on a reflector (else where the ray leaves the box)
    #: Surface histories: the smooth pieces (ReflectorSet.piece) met so far, as
    #: ``histories`` lists the reflectors; ``surface`` indexes it. The ray field is
    #: continuous over the rays of one surface history, and jumps between two.
    surfaces: list
    surface: np.ndarray  # (R,) int index into surfaces

    @property
    def head(self) -> np.ndarray:
        return self.tail + self.head_distance[:, None] * self.direction

    @property
    def n_rays(self) -> int:
        return len(self.order)

    def cell_pixels(self, cells: np.ndarray) -> np.ndarray:
        """Desired-view pixel coordinates of (fractional) ray-map cells."""
        return (np.asarray(cells, dtype=np.float64) + 0.5) * self.downsample

    def triangles_at(self, grid: np.ndarray, cells: np.ndarray) -> np.ndarray:
        """(P,) the tail triangle of ``grid``'s ray (``group_grid``) at the cell nearest each
        of ``cells`` (P, 2), -1 where that cell has none or lies off the map: where a
        view ray through an answer's pixel most likely meets the first reflector."""
        cells = np.rint(np.asarray(cells, dtype=np.float64)).astype(np.int64)
        on_map = (cells >= 0).all(axis=1) & (cells[:, 0] < grid.shape[1]) & (cells[:, 1] < grid.shape[0])
        ray = np.full(len(cells), -1, dtype=np.int64)
        ray[on_map] = grid[cells[on_map, 1], cells[on_map, 0]]
        return np.where(ray >= 0, self.triangle[np.maximum(ray, 0)], -1)

    def group_grid(self, group: int, surfaces=None) -> np.ndarray:
        """(rows, columns) int: the ray index of ``group`` at each cell, -1 where none;
        with ``surfaces`` (indices into ``self.surfaces``), only the rays of those."""
        grid = np.full((self.rows, self.columns), -1, dtype=np.int64)
        member = self.group == group
        if surfaces is not None:
            member &= np.isin(self.surface, surfaces)
        members = np.flatnonzero(member)
        grid[self.cell[members, 1], self.cell[members, 0]] = members
        return grid


def box_exit_distance(origins: np.ndarray, directions: np.ndarray, lo, hi) -> np.ndarray:
    """Distance along each ray to where it leaves the axis-aligned box (0 if already out)."""
    safe = np.where(np.abs(directions) < 1e-30, 1e-30, directions)
    t0 = (np.asarray(lo) - origins) / safe
    t1 = (np.asarray(hi) - origins) / safe
    return np.maximum(np.maximum(t0, t1).min(axis=1), 0.0)


def trace_ray_map(reflector_set: ReflectorSet, view: View, bounds, downsample: int = 2,
                  max_order: int = 1) -> RayMap:
    """Ray map by CPU ray tracing: view rays, then reflected rays up to ``max_order``."""
    pixels = view.pixel_grid(downsample)
    origins, directions = view.pixel_rays(pixels)
    hit, triangle, depth, normal, face_normal = _primary_hits(reflector_set, origins, directions)
    return reflect_primary_hits(reflector_set, view, bounds, downsample, max_order,
                                hit, triangle, depth, origins, directions, normal, face_normal)


#: Relative widening of the reflectors' bounding sphere when culling view rays (rounding).
SPHERE_CULL_MARGIN = 1e-6


def _primary_hits(reflector_set: ReflectorSet, origins: np.ndarray, directions: np.ndarray):
    """First hits of view rays (hit, triangle, depth, normal, face normal), as from
    ``reflector_set.intersect`` but tracing only the rays whose line passes through the
    reflectors' bounding sphere: no other ray can meet a triangle (each lies in the
    convex hull of its vertices). A morphing node's cube faces see the mirror in a few
    percent of their rays (SBC paper VI), so this skips most of their BVH descents.
    Every ray gets exactly the hit that tracing it in full gives.
    """
    centre, radius = reflector_set.bounding_sphere
    radius *= 1.0 + SPHERE_CULL_MARGIN
    across = cross(centre - origins, directions)  # its length: the line's distance to the centre
    near = np.flatnonzero(np.einsum("rd,rd->r", across, across) <= radius * radius)
    n = len(origins)
    hit, triangle, depth = np.zeros(n, dtype=bool), np.full(n, -1, dtype=np.int64), np.full(n, np.inf)
    normal, face_normal = np.full((n, 3), np.nan), np.full((n, 3), np.nan)
    # First up to each ray's closest approach to the centre: a hit there is the nearest
    # one, and the BVH leaves out the far side of the mirror (a ray through a closed
    # mirror meets it twice). Rays without a hit there are traced again in full.
    closest = np.einsum("rd,rd->r", centre - origins[near], directions[near])
    for rays, reach in ((near, closest), (None, np.inf)):
        if rays is None:
            rays = near[~hit[near]]
        if len(rays) == 0:
            continue
        hits = reflector_set.intersect(origins[rays], directions[rays], reach)
        hit[rays], triangle[rays], depth[rays] = hits.hit, hits.triangle, hits.t
        normal[rays], face_normal[rays] = hits.normal, hits.face_normal
    return hit, triangle, depth, normal, face_normal


def reflect_primary_hits(reflector_set, view, bounds, downsample, max_order, hit, triangle, depth,
                         origins, directions, normals, face_normals) -> RayMap:
    """Build the ray map from first hits of the view rays, however they were found.

    The CPU tracer and the GPU rasteriser (drawing) both end here, so the two
    producers share every step after the first hit.
    """
    if max_order < 1:
        raise ValueError(f"max_order must be >= 1, got {max_order}")
    lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
    if not np.all(hi > lo):
        raise SceneInputError("scene bounds", f"need lo < hi on every axis, got {lo} and {hi}")
    lo, hi = np.minimum(lo, reflector_set.vertices.min(axis=0)), np.maximum(hi, reflector_set.vertices.max(axis=0))
    columns, rows = view.width // downsample, view.height // downsample
    cells = np.stack(np.meshgrid(np.arange(columns), np.arange(rows)), axis=-1).reshape(-1, 2)

    alive = np.flatnonzero(hit)
    tail = origins[alive] + depth[alive, None] * directions[alive]
    incoming = directions[alive]
    normal, face = normals[alive], face_normals[alive]
    source = triangle[alive]
    first_point, first_depth = tail.copy(), depth[alive]
    history = reflector_set.owner[source][:, None]
    pieces = reflector_set.piece[source][:, None]
    rays = []
    for order in range(1, max_order + 1):
        valid = reflection_valid(incoming, normal, face) & ~reflector_set.from_inside(incoming, source)
        keep = np.flatnonzero(valid)
        alive, tail, incoming, source = alive[keep], tail[keep], incoming[keep], source[keep]
        normal, first_point, first_depth, history = normal[keep], first_point[keep], first_depth[keep], history[keep]
        pieces = pieces[keep]
        outgoing = reflect(incoming, normal)
        box = box_exit_distance(tail, outgoing, lo, hi)
        nxt = reflector_set.intersect(tail, outgoing, box, source)
        head_distance = np.where(nxt.hit, nxt.t, box)
        rays.append((alive, order, history, first_point, first_depth, tail, outgoing, head_distance, source,
                     nxt.hit.copy(), pieces))
        more = np.flatnonzero(nxt.hit)
        alive, tail, incoming, source = alive[more], nxt.position[more], outgoing[more], nxt.triangle[more]
        normal, face = nxt.normal[more], nxt.face_normal[more]
        first_point, first_depth = first_point[more], first_depth[more]
        history = np.concatenate([history[more], nxt.reflector[more, None]], axis=1)
        pieces = np.concatenate([pieces[more], reflector_set.piece[nxt.triangle[more], None]], axis=1)
    return assemble_ray_map(view, downsample, columns, rows, cells, rays)


def assemble_ray_map(view, downsample, columns, rows, cells, rays) -> RayMap:
    """Concatenate the rays of every order; number the histories, lower orders first.
    ``rays``: per order, (ray-map cell indices, order, (R, order) histories, first points,
    first depths, tails, directions, head distances, tail triangles, blocked,
    (R, order) surface histories); the refracted ray map (``engine/glass``) ends here too."""
    histories, group = _number_histories([r[2] for r in rays])
    surfaces, surface = _number_histories([r[10] for r in rays])

    def stacked(k):
        return np.concatenate([r[k] for r in rays])

    return RayMap(
        view=view, downsample=downsample, columns=columns, rows=rows, histories=histories,
        cell=cells[stacked(0)], order=np.concatenate([np.full(len(r[0]), r[1]) for r in rays]).astype(np.int64),
        group=group, first_point=stacked(3), first_depth=stacked(4), tail=stacked(5),
        direction=stacked(6), head_distance=stacked(7), triangle=stacked(8), blocked=stacked(9),
        surfaces=surfaces, surface=surface,
    )


def _number_histories(per_order: list) -> tuple[list, np.ndarray]:
    """Distinct rows of the (rays, order) arrays of every order, as tuples numbered lower
    orders first, then lexicographically; and each ray's number."""
    max_order = len(per_order)
    padded = np.concatenate([np.pad(h, ((0, 0), (0, max_order - h.shape[1])), constant_values=-1) for h in per_order])
    unique, index = np.unique(padded, axis=0, return_inverse=True)
    rank = np.argsort((unique >= 0).sum(axis=1), kind="stable")  # by order, then lexicographic
    renumber = np.empty(len(unique), dtype=np.int64)
    renumber[rank] = np.arange(len(unique))
    return [tuple(int(x) for x in unique[k][unique[k] >= 0]) for k in rank], renumber[index.reshape(-1)]


def first_pieces(ray_map: RayMap, grid: np.ndarray) -> np.ndarray:
    """The smooth pieces (ReflectorSet.piece) that the rays of ``grid`` first reflect off."""
    surfaces = np.unique(ray_map.surface[grid[grid >= 0]])
    return np.unique([ray_map.surfaces[k][0] for k in surfaces]).astype(np.int64)


def grid_neighbour(grid: np.ndarray, i: np.ndarray, j: np.ndarray, di: int, dj: int) -> np.ndarray:
    """Ray index at cell (i + di, j + dj) of ``grid`` (RayMap.group_grid), -1 where there
    is none or the cell lies outside."""
    rows, columns = grid.shape
    ii, jj = i + di, j + dj
    inside = (ii >= 0) & (ii < columns) & (jj >= 0) & (jj < rows)
    return np.where(inside, grid[np.clip(jj, 0, rows - 1), np.clip(ii, 0, columns - 1)], -1)


def neighbour_spacing(ray_map: RayMap, grid: np.ndarray, rays: np.ndarray):
    """How far each ray's tail and unit direction (R,) lie from those of its four
    neighbours in ``grid`` (the largest; 0 where it has none): a point at distance s
    along the ray lies between it and its neighbours within tail + s * direction."""
    i, j = ray_map.cell[rays, 0], ray_map.cell[rays, 1]
    tail, direction = np.zeros(len(rays)), np.zeros(len(rays))
    for di, dj in ((1, 0), (0, 1), (-1, 0), (0, -1)):
        neighbour = grid_neighbour(grid, i, j, di, dj)
        other = np.where(neighbour >= 0, neighbour, rays)
        tail = np.maximum(tail, np.linalg.norm(ray_map.tail[other] - ray_map.tail[rays], axis=1))
        direction = np.maximum(direction, np.linalg.norm(ray_map.direction[other] - ray_map.direction[rays], axis=1))
    return tail, direction
