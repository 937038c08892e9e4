# SPDX-License-Identifier: GPL-3.0-or-later
"""Ray octrees: where a point is seen from one grid node (Martin & Popescu 2004, section 4).

At a node, the reflector is ray traced through a cube map (six faces, ``cube_face_views``)
and every view ray that hits it is reflected: its *ray map* (section 4.1). The octree
covers the box where reflected rays end; each leaf lists the rays that cross it. The
paper subdivides a leaf whenever a new ray conflicts with one it holds (same trace: for
first-order rays of one reflector, any two rays), so every leaf crossed by two rays or
more is split to the maximum depth, and a leaf crossed by one ray stays large. Here the
octree is stored linearised (the paper saves it "as a binary file"): the occupied
leaves of its finest COARSER_LEVELS + 1 levels, each with the list of rays crossing it
(sorted leaf codes and a CSR table). A point is looked up in its finest occupied leaf:
where rays diverge, far from a convex mirror, they pass farther apart than a finest leaf,
and the leaf a level or two up holds the rays around the point, as the paper's larger
one-ray leaves do.

Projecting a point (what the paper does by "the ray closest to the point"):

1. the leaf holding the point gives its candidate rays, the points' distances to them
   pick seeds: the nearest ray, then the nearest whose first reflector point lies
   SEPARATION reflector sizes from those taken (another image, on a concave mirror);
2. our refinement: the ray map is a regular grid of rays per cube face, so a seed is
   moved continuously over it (bilinear interpolation of the four rays around it,
   Gauss-Newton on the point's distance to the interpolated ray) until the ray passes
   through the point. The closest ray alone errs by up to half a ray spacing at the
   point's distance (many pixels of the desired view); the interpolated ray by the
   interpolation's second-order error. (The rays leave from a mesh's flat facets with
   interpolated normals, which no smooth patch fits to better than the facets' sagitta,
   so no patch is fitted here.)

The answer is the first reflector point of that ray: the point's image at this node,
which :mod:`.grid` blends over the eight nodes of the grid cell holding the eye.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...geometry.spd_solve import solve_spd

#: Reflector sizes between the first reflector points of two seeds of distinct images.
SEPARATION = 0.1
#: Gauss-Newton steps of the refinement over the ray map, and the largest step (cells).
REFINE_ITERATIONS = 10
MAX_STEP_CELLS = 3.0
#: A seed whose step is shorter than this (cells) has converged and stops.
SETTLED_CELLS = 1e-7
#: A refined ray passes this close to its point (in reflector sizes) to be an image.
CONVERGED = 1e-6
#: Cells a complete ray-map cell is extrapolated beyond, toward the mirror's silhouette.
EXTRAPOLATE_CELLS = 0.25
#: The cell holding a point first, then those beside it (edges, then corners).
_CELL_OFFSETS = np.array([(0, 0), (-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (1, -1), (-1, 1), (1, 1)])
#: Two refined images closer than this (reflector sizes) are one.
SAME_IMAGE = 1e-3
#: Samples per leaf edge along each ray when listing the leaves it crosses.
SAMPLES_PER_LEAF = 2
#: Levels above the finest whose leaves are listed too (a point in an empty finest leaf
#: looks there).
COARSER_LEVELS = 3
#: Points projected at once (bounds the temporary (point, candidate ray) rows).
CHUNK_POINTS = 16384


@dataclass(frozen=True)
class RayOctree:
    """One node's reflected rays and the octree over them, in the grid's rigid frame."""

    lo: np.ndarray  # (3,) the root cube's lowest corner, and of the box where rays end
    size: float  # the root cube's edge
    hi: np.ndarray  # (3,) the box's highest corner (the cube is the box made cubic)
    depth: int  # the finest leaves are cubes of size / 2**depth
    reflector_size: float
    origins: np.ndarray  # (R, 3) first reflector point of each ray
    directions: np.ndarray  # (R, 3) unit reflected direction
    lengths: np.ndarray  # (R,) length of the ray inside the box (or up to the mirror)
    blocked: np.ndarray  # (R,) bool: the ray ends on the mirror (else it leaves the box, and goes on)
    centre: np.ndarray  # (3,) the centre of the rays' first reflector points
    pieces: np.ndarray  # (R,) smooth piece of the mirror the ray leaves from
    ray_grid: np.ndarray  # (F, n, n) the ray of each cube-face cell (row, column), -1 where none
    leaf_codes: np.ndarray  # (L,) sorted codes (:meth:`leaf_code`) of the leaves crossed by rays, all levels
    leaf_start: np.ndarray  # (L + 1,) each leaf's rays are leaf_rays[leaf_start[l]:leaf_start[l + 1]]
    leaf_rays: np.ndarray  # (E,)

    @property
    def leaf_size(self) -> float:
        return self.size / 2 ** self.depth

    @property
    def nbytes(self) -> int:
        return int(sum(np.asarray(getattr(self, k)).nbytes for k in _FIELDS))

    def to_arrays(self, prefix: str = "") -> dict:
        return {prefix + k: np.asarray(getattr(self, k)) for k in _FIELDS}

    @classmethod
    def from_arrays(cls, data, prefix: str = "") -> "RayOctree":
        values = {k: np.asarray(data[prefix + k]) for k in _FIELDS}
        for k in ("size", "reflector_size"):
            values[k] = float(values[k])
        values["depth"] = int(values["depth"])
        return cls(**values)

    def leaf_code(self, points: np.ndarray, level: int | None = None) -> np.ndarray:
        """(P,) code of the leaf of ``level`` (default: the finest) holding each point (:func:`leaf_code`)."""
        return leaf_code(points, self.lo, self.size, self.depth if level is None else level)

    def beyond(self, points: np.ndarray) -> np.ndarray:
        """(P,) bool: the points outside the box where the rays end."""
        return np.any((points < self.lo) | (points >= self.hi), axis=1)

    def lookup_positions(self, points: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """Where each point is looked up in the octree: itself inside the box where rays
        end; a point beyond it, where the segment from it to its ``targets`` row (a point
        of the mirror) enters the box: the reflected ray from that mirror point to the
        point crosses the box there."""
        outside = np.flatnonzero(self.beyond(points))
        if len(outside) == 0:
            return points
        start = points[outside]
        direction = targets[outside] - start
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (self.lo - start) / direction, (self.hi - start) / direction
        enter = np.nanmax(np.minimum(t1, t2), axis=1)
        inset = 1e-6 * self.size / np.maximum(np.linalg.norm(direction, axis=1), 1e-300)
        result = points.copy()
        result[outside] = start + np.clip(enter + inset, 0.0, 1.0)[:, None] * direction
        return result

    def images(self, points: np.ndarray, count: int) -> np.ndarray:
        """(P, count, 3) first reflector points where ``points`` are seen from this node
        (nearest seed first), NaN where fewer images."""
        points = np.asarray(points, dtype=np.float64)
        return np.concatenate([self._images(points[k:k + CHUNK_POINTS], count)
                               for k in range(0, len(points), CHUNK_POINTS)] or [np.zeros((0, count, 3))])

    def near_misses(self, points: np.ndarray) -> np.ndarray:
        """(P, 3) the first reflector point of each point's nearest ray (its first seed),
        NaN where it has none: for points without an image (:meth:`images`), mostly
        reflected between the ray map's last rays and the mirror's silhouette, beyond the
        refinement's extrapolation (EXTRAPOLATE_CELLS), where a polish on the mirror
        starts (:mod:`.grid`'s remedy 2)."""
        points = np.asarray(points, dtype=np.float64)
        found = np.full((len(points), 3), np.nan)
        for k in range(0, len(points), CHUNK_POINTS):
            owner, ray, _ = self._seed_rays(points[k:k + CHUNK_POINTS], 1)
            found[k + owner] = self.origins[ray]
        return found

    def _images(self, points: np.ndarray, count: int) -> np.ndarray:
        found = np.full((len(points), count, 3), np.nan)
        seed_owner, seed_ray, slot = self._seed_rays(points, count)
        x, ok = self._refine(points[seed_owner], seed_ray)
        found[seed_owner[ok], slot[ok]] = x[ok]
        for k in range(1, count):  # two seeds that refined to the same image
            same = np.linalg.norm(found[:, :k] - found[:, k:k + 1], axis=2) <= SAME_IMAGE * self.reflector_size
            found[same.any(axis=1), k] = np.nan
        order = np.argsort(np.isnan(found[..., 0]), axis=1, kind="stable")  # images first
        return np.take_along_axis(found, order[..., None], axis=1)

    def _seed_rays(self, points: np.ndarray, count: int):
        """Up to ``count`` seed rays per point (:meth:`_seeds`) among its leaf's candidates:
        (point, ray, slot) rows."""
        owner, ray = self._candidates(points, np.broadcast_to(self.centre, points.shape))
        beyond = self.beyond(points)
        if beyond[owner].any():
            # A point beyond the box, aimed first at the mirror's centre, is looked up
            # again aimed at its nearest candidate's mirror point (nearer its image's).
            first_owner, first_ray, _ = self._seeds(points, owner[beyond[owner]], ray[beyond[owner]], 1)
            again_owner, again_ray = self._candidates(points[first_owner], self.origins[first_ray])
            owner, ray = np.r_[owner, first_owner[again_owner]], np.r_[ray, again_ray]
        if len(owner) == 0:
            empty = np.zeros(0, np.int64)
            return empty, empty, empty
        return self._seeds(points, owner, ray, count)

    def _candidates(self, points: np.ndarray, targets: np.ndarray):
        """(point, ray) rows: every ray listed in the finest occupied leaf of every point
        (of its :meth:`lookup_positions`)."""
        if len(self.leaf_codes) == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        positions = self.lookup_positions(points, targets)
        leaf = np.full(len(points), -1)
        for level in range(self.depth, max(self.depth - COARSER_LEVELS, 0) - 1, -1):
            rows = np.flatnonzero(leaf < 0)
            code = self.leaf_code(positions[rows], level)
            at = np.minimum(np.searchsorted(self.leaf_codes, code), len(self.leaf_codes) - 1)
            found = (code >= 0) & (self.leaf_codes[at] == code)
            leaf[rows[found]] = at[found]
        rows = np.flatnonzero(leaf >= 0)
        start, stop = self.leaf_start[leaf[rows]], self.leaf_start[leaf[rows] + 1]
        counts = stop - start
        owner = np.repeat(rows, counts)
        offsets = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
        return owner, self.leaf_rays[np.repeat(start, counts) + offsets].astype(np.int64)

    def _seeds(self, points, owner, ray, count):
        """Up to ``count`` seed rays per point: the nearest ray in front of the mirror and
        before its end, then the nearest away from the images taken (SEPARATION)."""
        w = points[owner] - self.origins[ray]
        t = np.einsum("qd,qd->q", w, self.directions[ray])
        distance = np.linalg.norm(w - t[:, None] * self.directions[ray], axis=1)
        keep = (t >= 0) & ((t <= self.lengths[ray] + self.leaf_size) | ~self.blocked[ray])
        owner, ray, distance = owner[keep], ray[keep], distance[keep]
        order = np.lexsort((distance, owner))
        owner, ray = owner[order], ray[order]
        seeds = []
        taken = np.full((len(points), 0, 3), np.nan)
        for slot in range(count):
            if len(owner) == 0:
                break
            first = np.flatnonzero(np.r_[True, owner[1:] != owner[:-1]])
            chosen_owner, chosen_ray = owner[first], ray[first]
            seeds.append((chosen_owner, chosen_ray, np.full(len(first), slot)))
            picked = np.full((len(points), 1, 3), np.nan)
            picked[chosen_owner, 0] = self.origins[chosen_ray]
            taken = np.concatenate([taken, picked], axis=1)
            apart = np.linalg.norm(self.origins[ray][:, None] - taken[owner], axis=2)
            far = np.all(~(apart <= SEPARATION * self.reflector_size), axis=1)
            owner, ray = owner[far], ray[far]
        if not seeds:
            empty = np.zeros(0, np.int64)
            return empty, empty, empty
        return tuple(np.concatenate(part) for part in zip(*seeds))

    def _refine(self, points: np.ndarray, seed_ray: np.ndarray):
        """Move each seed over its face's ray grid until the interpolated ray passes
        through its point: (Q, 3) first reflector points and (Q,) converged."""
        faces, cells = self._ray_index()
        face, uv = faces[seed_ray], cells[seed_ray].astype(np.float64)
        n = self.ray_grid.shape[1]
        live = np.ones(len(points), bool)
        for _ in range(REFINE_ITERATIONS):
            rows = np.flatnonzero(live)
            if len(rows) == 0:
                break
            error, jacobian, ok = self._residual(face[rows], uv[rows], points[rows])
            live[rows[~ok]] = False
            rows, error, jacobian = rows[ok], error[ok], jacobian[ok]
            jtj = np.einsum("qdi,qdj->qij", jacobian, jacobian) + 1e-18 * np.eye(2)
            step = -solve_spd(jtj, np.einsum("qdi,qd->qi", jacobian, error))
            step *= np.minimum(1.0, MAX_STEP_CELLS / np.maximum(np.abs(step).max(axis=1), 1e-300))[:, None]
            uv[rows] = np.clip(uv[rows] + step, 0.0, n - 1.0)
            live[rows[np.abs(step).max(axis=1) < SETTLED_CELLS]] = False
        x, error, ok = self._at(face, uv, points)
        ok &= np.linalg.norm(error, axis=1) <= CONVERGED * self.reflector_size
        return x, ok

    def _ray_index(self):
        """(R,) face and (R, 2) (column, row) of every ray, from the ray grid (made once)."""
        cached = self.__dict__.get("_index")
        if cached is None:
            f, j, i = np.nonzero(self.ray_grid >= 0)
            rays = self.ray_grid[f, j, i]
            face, cell = np.zeros(len(self.origins), np.int64), np.zeros((len(self.origins), 2), np.int64)
            face[rays], cell[rays] = f, np.stack([i, j], axis=1)
            cached = (face, cell)
            object.__setattr__(self, "_index", cached)
        return cached

    def _corners(self, face, uv):
        """The four rays of the cell holding (u, v) in each face's grid, the fractions,
        and whether all four exist and leave from one smooth piece. Where that cell is
        incomplete (the mirror's silhouette, as seen from the node, crosses it), the
        nearest complete cell beside it is extrapolated, up to EXTRAPOLATE_CELLS cells
        beyond it: points reflected between the last ray and the silhouette."""
        n = self.ray_grid.shape[1]
        cell = np.floor(uv).astype(np.int64)
        corners = np.zeros((len(uv), 4), np.int64)
        frac = np.zeros((len(uv), 2))
        ok = np.zeros(len(uv), bool)
        for offset in _CELL_OFFSETS if EXTRAPOLATE_CELLS > 0 else _CELL_OFFSETS[:1]:
            rows = np.flatnonzero(~ok)
            base = np.clip(cell[rows] + offset, 0, n - 2)
            i, j, f = base[:, 0], base[:, 1], face[rows]
            found = np.stack([self.ray_grid[f, j, i], self.ray_grid[f, j, i + 1], self.ray_grid[f, j + 1, i],
                              self.ray_grid[f, j + 1, i + 1]], axis=1)
            pieces = self.pieces[np.maximum(found, 0)]
            fraction = uv[rows] - base
            good = (np.all(found >= 0, axis=1) & np.all(pieces == pieces[:, :1], axis=1)
                    & np.all((fraction >= -EXTRAPOLATE_CELLS) & (fraction <= 1 + EXTRAPOLATE_CELLS), axis=1))
            corners[rows[good]], frac[rows[good]], ok[rows[good]] = found[good], fraction[good], True
        return corners, frac, ok

    @staticmethod
    def _bilinear(values, frac):
        """Bilinear interpolation of (Q, 4, 3) corner values (00, 10, 01, 11) and its
        derivatives along u and v."""
        a, b = frac[:, 0, None], frac[:, 1, None]
        v00, v10, v01, v11 = values[:, 0], values[:, 1], values[:, 2], values[:, 3]
        value = (1 - a) * (1 - b) * v00 + a * (1 - b) * v10 + (1 - a) * b * v01 + a * b * v11
        d_u = (1 - b) * (v10 - v00) + b * (v11 - v01)
        d_v = (1 - a) * (v01 - v00) + a * (v11 - v10)
        return value, d_u, d_v

    def _at(self, face, uv, points):
        """First reflector point of the interpolated ray at (u, v), the point's offset
        from that ray, and whether it is usable (corners present, in front, before the end)."""
        corners, frac, ok = self._corners(face, uv)
        x, _, _ = self._bilinear(self.origins[corners], frac)
        d, _, _ = self._bilinear(self.directions[corners], frac)
        reach = np.where(self.blocked[corners], self.lengths[corners], np.inf)
        length = np.where(np.isinf(reach).all(axis=1), np.inf, np.min(reach, axis=1))
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        w = points - x
        t = np.einsum("qd,qd->q", w, d)
        ok &= (t >= 0) & (t <= length)
        return x, w - t[:, None] * d, ok

    def _residual(self, face, uv, points):
        """The point's offset from the interpolated ray (Q, 3), its Jacobian in (u, v)
        (Q, 3, 2) and whether the corners are usable."""
        corners, frac, ok = self._corners(face, uv)
        x, x_u, x_v = self._bilinear(self.origins[corners], frac)
        d, d_u, d_v = self._bilinear(self.directions[corners], frac)
        w = points - x
        dd = np.einsum("qd,qd->q", d, d)
        t = np.einsum("qd,qd->q", w, d) / dd
        error = w - t[:, None] * d
        columns = []
        for x_s, d_s in ((x_u, d_u), (x_v, d_v)):
            t_s = (np.einsum("qd,qd->q", -x_s, d) + np.einsum("qd,qd->q", w, d_s)) / dd \
                - 2.0 * t * np.einsum("qd,qd->q", d, d_s) / dd
            columns.append(-x_s - t_s[:, None] * d - t[:, None] * d_s)
        return error, np.stack(columns, axis=2), ok


_FIELDS = ("lo", "size", "hi", "depth", "reflector_size", "origins", "directions", "lengths", "blocked", "centre",
           "pieces", "ray_grid", "leaf_codes", "leaf_start", "leaf_rays")


def build_ray_octree(faces: list, resolution: int, box, depth: int, reflector_size: float) -> RayOctree:
    """The octree of one node's reflected rays.

    ``faces``: (face index, RayMap) of each cube face that sees the reflector, first-order
    rays; ``resolution``: cells along a face's side; ``box``: (lo, hi) where rays end (the
    root is the cube over it); ``depth``: the finest leaves' level.
    """
    lo, hi = (np.asarray(b, dtype=np.float64) for b in box)
    ray_grid = np.full((6, resolution, resolution), -1, dtype=np.int32)
    parts, count = [], 0
    for face, ray_map in faces:
        first = ray_map.order == 1
        cells = ray_map.cell[first]
        piece_of_history = np.array([surface[0] if surface else -1 for surface in ray_map.surfaces], dtype=np.int64)
        parts.append((ray_map.first_point[first], ray_map.direction[first], ray_map.head_distance[first],
                      ray_map.blocked[first], piece_of_history[ray_map.surface[first]]))
        ray_grid[face, cells[:, 1], cells[:, 0]] = count + np.arange(len(cells))
        count += len(cells)
    empty = (np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0, bool), np.zeros(0, np.int64))
    origins, directions, lengths, blocked, pieces = (np.concatenate(p) for p in zip(*(parts or [empty])))
    lengths = np.minimum(lengths, np.linalg.norm(hi - lo))
    centre = origins.mean(axis=0) if len(origins) else (lo + hi) / 2
    size = float(np.max(hi - lo))
    codes, start, rays = _leaf_lists(origins, directions, lengths, lo, size, int(depth))
    return RayOctree(lo, size, hi, int(depth), float(reflector_size), origins, directions, lengths, blocked, centre,
                     pieces.astype(np.int32), ray_grid, codes, start, rays)


def _leaf_lists(origins, directions, lengths, lo, size: float, depth: int):
    """The leaves each ray crosses, on the finest COARSER_LEVELS + 1 levels (sampled
    SAMPLES_PER_LEAF times per finest leaf edge): sorted leaf codes, CSR starts and ray
    lists."""
    step = size / 2 ** depth / SAMPLES_PER_LEAF
    samples = np.ceil(lengths / step).astype(np.int64) + 1
    ray = np.repeat(np.arange(len(samples)), samples)
    k = np.arange(int(samples.sum())) - np.repeat(np.cumsum(samples) - samples, samples)
    s = np.minimum(k * step, lengths[ray])
    positions = origins[ray] + s[:, None] * directions[ray]
    n_rays = max(len(samples), 1)
    pairs = []
    for level in range(depth, max(depth - COARSER_LEVELS, 0) - 1, -1):
        code = leaf_code(positions, lo, size, level)
        pairs.append(np.unique(code[code >= 0] * n_rays + ray[code >= 0]))
    leaf, ray = np.divmod(np.sort(np.concatenate(pairs)), n_rays)
    codes, first = np.unique(leaf, return_index=True)
    return codes, np.r_[first, len(leaf)].astype(np.int64), ray.astype(np.int32)


def leaf_code(points: np.ndarray, lo, size: float, level: int) -> np.ndarray:
    """(P,) code of the leaf of ``level`` holding each point of the root cube (corner
    ``lo``, edge ``size``), -1 outside it. Codes of level l start at (8**l - 1) / 7, as in
    a breadth-first numbering of a full octree."""
    n = 2 ** level
    ijk = np.floor((points - lo) / (size / n)).astype(np.int64)
    inside = np.all((ijk >= 0) & (ijk < n), axis=1)
    return np.where(inside, (8 ** level - 1) // 7 + ijk[:, 0] + n * (ijk[:, 1] + n * ijk[:, 2]), -1)
