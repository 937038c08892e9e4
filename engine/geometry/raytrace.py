# SPDX-License-Identifier: GPL-3.0-or-later
"""CPU ray tracing of the reflectors: nearest hits, occlusion, mirror reflection.

All reflectors of a scene are traced together through one :class:`ReflectorSet`, so a
ray's nearest hit is the nearest over every reflector and occlusion by the other
reflectors comes for free. Rays are processed in chunks, each chunk as whole arrays
(breadth-first BVH descent, batched Moller-Trumbore), so full-resolution ray maps are
practical in numpy.

Surface model (docs/overview.md, Conventions): flat triangles carrying interpolated vertex normals. Mirrors
are two-sided, as in Cycles: at a hit, the geometric and the interpolated normal are
turned toward the side the ray comes from. A reflection is *valid* where the incoming
ray is in front of the interpolated normal and the reflected ray leaves the front of
the triangle; near silhouettes, interpolated normals can break either condition.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from . import closed_surfaces
from .bvh import build_bvh, descend, ray_box_test
from ..errors import SceneInputError
from ..scene import Reflector, smooth_pieces
from .segments import expand_ranges
from .triangle_grid import TriangleGrid, edge_neighbours
from .vectors import cross_rows, dot_rows

RAY_CHUNK = 1 << 16
#: (ray, triangle) candidate pairs tested at a time.
PAIR_CHUNK = 1 << 17
#: Triangles whose corners the constructor holds at a time.
BUILD_BLOCK = 1 << 16
#: Relative (to the scene size) distance below which a hit is taken as the ray's own origin.
SELF_HIT_EPSILON = 1e-9
#: A closed reflector is sealed (:meth:`ReflectorSet.seal_empty_interiors`) only when at
#: most this many diffuse vertices lie in its bounding box, each tested for inside.
SEAL_TESTED_VERTICES = 4096
#: ... and a diffuse vertex holds it open only this share of its diagonal or more inside.
SEAL_DEPTH = 1e-4
#: How far from the surface (a share of the scene's size) ``triangle_grid`` finds a triangle.
NEAR_SURFACE = 0.05


@dataclass(frozen=True)
class RayHits:
    """Nearest hits of R rays; entries of rays that hit nothing are -1 / inf / NaN."""

    t: np.ndarray  # (R,) distance along the unit ray, inf for a miss
    triangle: np.ndarray  # (R,) index into ReflectorSet triangles, -1 for a miss
    reflector: np.ndarray  # (R,) reflector index, -1 for a miss
    barycentric: np.ndarray  # (R, 3) weights of the triangle's three corners
    position: np.ndarray  # (R, 3)
    normal: np.ndarray  # (R, 3) interpolated normal, turned toward the ray's origin
    face_normal: np.ndarray  # (R, 3) geometric normal, turned toward the ray's origin

    @property
    def hit(self) -> np.ndarray:
        return self.triangle >= 0

    @classmethod
    def misses(cls, n_rays: int) -> "RayHits":
        """``n_rays`` rays that hit nothing."""
        nan3 = np.full((n_rays, 3), np.nan)
        return cls(np.full(n_rays, np.inf), np.full(n_rays, -1), np.full(n_rays, -1), nan3, nan3.copy(),
                   nan3.copy(), nan3.copy())


def reflect(directions: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Mirror directions about unit normals: d - 2 (d . n) n."""
    return directions - 2.0 * np.einsum("ij,ij->i", directions, normals)[:, None] * normals


def reflection_valid(directions: np.ndarray, normals: np.ndarray, face_normals: np.ndarray) -> np.ndarray:
    """Incoming ray in front of the (oriented) interpolated normal, reflected ray leaving the face."""
    reflected = reflect(directions, normals)
    return (np.einsum("ij,ij->i", directions, normals) < 0) & (np.einsum("ij,ij->i", reflected, face_normals) > 0)


def _nearest_per_ray(rays, triangles, t, u, v):
    """Of (ray, triangle) hits, each ray's nearest: its rays (sorted), t, triangles and (u, v)."""
    order = np.lexsort((t, rays))
    rays, triangles, t, u, v = rays[order], triangles[order], t[order], u[order], v[order]
    first = np.ones(len(rays), dtype=bool)
    first[1:] = rays[1:] != rays[:-1]
    return rays[first], t[first], triangles[first], np.stack([u[first], v[first]], axis=1)


def _joined(arrays: list, dtype) -> np.ndarray:
    """The arrays end to end as ``dtype``; a single one of that type as it is, not copied."""
    return np.asarray(arrays[0], dtype=dtype) if len(arrays) == 1 else np.concatenate(arrays).astype(dtype, copy=False)


class FaceNormals:
    """The unit geometric normals (e1 x e2, normalised) of a :class:`ReflectorSet`'s
    triangles, (T, 3) as indexed (``face_normals[triangles]``) or as an array
    (``np.asarray``), made from its corner rows when asked for: every use takes those
    of the triangles some rays hit, and a million-triangle mirror's held 25 MB. The
    same arithmetic as a whole (T, 3) array's, so the same values."""

    def __init__(self, corner_rows: np.ndarray):
        self._rows = corner_rows

    def __len__(self) -> int:
        return self._rows.shape[1]

    @property
    def shape(self) -> tuple:
        return (len(self), 3)

    def __getitem__(self, index) -> np.ndarray:
        rows = self._rows[3:9, index]
        face = np.stack(cross_rows(rows[0:3], rows[3:6]), axis=-1)
        return face / np.maximum(np.linalg.norm(face, axis=-1), 1e-300)[..., None]

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        normals = self[:]
        return normals if dtype is None else normals.astype(dtype)


class ReflectorSet:
    """All reflectors of a scene, concatenated, with one BVH for tracing and solving."""

    def __init__(self, reflectors: list[Reflector], leaf_size: int = 4):
        if not reflectors:
            raise SceneInputError("scene", "has no reflector: mark at least one object as a reflector")
        self.reflectors = list(reflectors)
        offsets = np.cumsum([0] + [len(r.vertices) for r in reflectors])
        # One reflector's arrays are used as they are (a million-triangle mirror's copies: 48 MB).
        self.vertices = _joined([r.vertices for r in reflectors], np.float64)
        self.normals = _joined([r.normals for r in reflectors], np.float64)
        self.triangles = _joined([r.triangles + o if o else r.triangles for r, o in zip(reflectors, offsets)], np.int64)
        self.owner = np.concatenate(
            [np.full(len(r.triangles), i, dtype=np.int64) for i, r in enumerate(reflectors)]
        )
        # Split vertices (sharp edges, custom normals) share positions: weld them so that
        # triangles meeting at a split still count as neighbours (the triangles themselves
        # where nothing is split). First what needs temporaries, while little is held.
        self.welded_triangles = closed_surfaces.welded_corners(self.vertices, self.triangles)
        # Smooth pieces never span reflectors: each reflector's vertices are its own.
        self.piece = smooth_pieces(self.triangles, len(self.vertices))
        # v0, e1 and e2 as nine rows: one gather gives a batch's corners coordinate by
        # coordinate; the (T, 3) arrays are views of them. Filled a block of triangles at
        # a time: a million-triangle mirror's (T, 3, 3) corners and their copies cost
        # 300 MB at once.
        n_triangles = len(self.triangles)
        self.corner_rows = np.empty((9, n_triangles))
        for start in range(0, n_triangles, BUILD_BLOCK):
            corners = self.vertices[self.triangles[start:start + BUILD_BLOCK]]
            rows = self.corner_rows[:, start:start + BUILD_BLOCK]
            rows[0:3] = corners[:, 0].T
            rows[3:6] = (corners[:, 1] - corners[:, 0]).T
            rows[6:9] = (corners[:, 2] - corners[:, 0]).T
        del corners, rows
        self.v0, self.e1, self.e2 = (self.corner_rows[k:k + 3].T for k in (0, 3, 6))
        self.face_normals = FaceNormals(self.corner_rows)
        lo, hi = self.vertices.min(axis=0), self.vertices.max(axis=0)
        self.scale = float(max(np.linalg.norm(hi - lo), 1e-12))
        self.bvh = build_bvh(self.vertices, self.triangles, self.normals, leaf_size=leaf_size)
        #: Per reflector, its winding (``closed_surfaces.winding``) where it is a closed
        #: solid that holds no diffuse geometry (:meth:`seal_empty_interiors`), else 0.
        self.sealed = np.zeros(len(self.reflectors), dtype=np.int64)

    def seal_empty_interiors(self, meshes) -> None:
        """Seal the closed reflectors whose inside holds no vertex of ``meshes`` (the
        diffuse objects, each with ``vertices``): a ray that meets one from inside (a
        view ray starting there: the camera's clip start cutting into a mirror ball, the
        eye on it) would bounce inside without end and can show no object, so
        :meth:`from_inside` lets the ray map end it there instead of tracing and fitting
        every bounce (sbc_fig3's ball seen from 5 % of its radius with the clip start
        inside it: 764 sheets and 58 s for a 320x240 frame, against 1.1 s from the scene
        camera). A reflector with more than :data:`SEAL_TESTED_VERTICES` diffuse vertices
        in its bounding box is left open (not tested). Call again when the meshes change."""
        self.sealed[:] = 0
        diffuse = [np.asarray(m.vertices, np.float64).reshape(-1, 3) for m in meshes]
        for index, (reflector, sense) in enumerate(zip(self.reflectors, self.windings)):
            if sense == 0:
                continue
            lo, hi = reflector.vertices.min(axis=0), reflector.vertices.max(axis=0)
            near = np.concatenate([np.zeros((0, 3))] + [v[np.all((v >= lo) & (v <= hi), axis=1)] for v in diffuse])
            if len(near) > SEAL_TESTED_VERTICES or self._holds(index, near):
                continue
            self.sealed[index] = sense

    def _holds(self, index: int, points) -> bool:
        """Whether a point of ``points`` lies inside the closed reflector ``index`` deeper
        than :data:`SEAL_DEPTH` of its size: a point on its surface (a floor it stands on,
        touching it at its lowest vertex) opens nothing."""
        inside = self._inside(index, points)
        if not inside.any():
            return False
        reflector = self.reflectors[index]
        reach = SEAL_DEPTH * float(np.linalg.norm(np.ptp(reflector.vertices, axis=0)))
        probes = points[inside][:, None, :] + reach * np.concatenate([np.eye(3), -np.eye(3)])[None]
        return bool(self._inside(index, probes.reshape(-1, 3)).reshape(-1, 6).all(axis=1).any())

    def _inside(self, index: int, points) -> np.ndarray:
        """(P,) bool: ``points`` inside the closed reflector ``index``: the parity of its
        triangles each of three rays crosses, the majority of the three, as
        ``closed_surfaces.inside`` counts them, with the crossings found through the BVH
        (a million-triangle ball: 1.5 s for the floor's vertex that touches it, every
        time a diffuse object moved, by testing every triangle)."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        votes = np.zeros(len(points), dtype=np.int64)
        probes = closed_surfaces.PROBE_DIRECTIONS
        for direction in probes / np.linalg.norm(probes, axis=1, keepdims=True):
            directions = np.ascontiguousarray(np.broadcast_to(direction, points.shape))
            test = ray_box_test(self.bvh, points, directions, np.zeros(len(points)), np.full(len(points), np.inf))
            rays, triangles = descend(self.bvh, np.arange(len(points)), test)
            mine = self.owner[triangles] == index
            rays, triangles = rays[mine], triangles[mine]
            t, _, _, _ = self.hit_triangles(points[rays], directions[rays], triangles)
            with np.errstate(invalid="ignore"):
                crossed = t > 0.0
            votes += np.bincount(rays[crossed], minlength=len(points)) % 2
        return votes >= 2

    def from_inside(self, directions, triangles) -> np.ndarray:
        """(n,) bool: rays (``directions``) meeting ``triangles`` of a sealed reflector from
        its inside, where no object can be seen (:meth:`seal_empty_interiors`)."""
        triangles = np.asarray(triangles, dtype=np.int64)
        sense = self.sealed[self.owner[np.maximum(triangles, 0)]]
        toward = np.einsum("ij,ij->i", directions, self.face_normals[np.maximum(triangles, 0)]) * sense
        return (triangles >= 0) & (sense != 0) & (toward > 0)

    @property
    def nbytes(self) -> int:
        arrays = (self.vertices, self.normals, self.triangles, self.owner, self.corner_rows, self.piece)
        if self.welded_triangles is not self.triangles:
            arrays += (self.welded_triangles,)
        return int(sum(a.nbytes for a in arrays)) + self.bvh.nbytes

    def surface(self, triangles: np.ndarray, barycentric: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions and unit interpolated normals at barycentric coordinates of triangles."""
        corners = self.triangles[triangles]
        positions = np.einsum("ij,ijk->ik", barycentric, self.vertices[corners])
        normals = np.einsum("ij,ijk->ik", barycentric, self.normals[corners])
        normals /= np.maximum(np.linalg.norm(normals, axis=1), 1e-300)[:, None]
        return positions, normals

    def neighbours(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """(K,) bool: triangles a and b share a (welded) vertex; -1 never does."""
        shared = (self.welded_triangles[a][:, :, None] == self.welded_triangles[b][:, None, :]).any(axis=(1, 2))
        return shared & (a >= 0) & (b >= 0)

    def intersect(self, origins, directions, t_max=np.inf, source_triangles=None, near_triangles=None,
                  t_guess=None) -> RayHits:
        """Nearest reflector hit of each ray (unit ``directions``) with t in (eps, t_max].

        ``source_triangles`` (R,) excludes hits on the triangle a ray starts from and its
        one-ring neighbours (facet self-hits of reflected rays), -1 for none.

        ``near_triangles`` (R,), -1 where unknown: a triangle each ray is expected to hit
        close to (where a previous, nearby ray hit). The rings around them are tried
        first, and where one is hit the BVH searches only in front of that hit: the same
        nearest hit, without visiting the boxes behind the first surface (a view ray
        through a subdivided monkey head crossed 15 leaves and 183 boxes).

        ``t_guess`` (R,), inf where unknown: a distance the nearest hit likely lies within.
        The BVH is searched up to it first, and again beyond it only for the rays that
        found nothing: the same nearest hit again, cheaper where the guess holds.
        """
        origins = np.asarray(origins, dtype=np.float64)
        directions = np.asarray(directions, dtype=np.float64)
        n_rays = len(origins)
        t_max = np.broadcast_to(np.asarray(t_max, dtype=np.float64), (n_rays,))
        sources = (np.full(n_rays, -1, dtype=np.int64) if source_triangles is None
                   else np.asarray(source_triangles, dtype=np.int64))
        best_t = np.full(n_rays, np.inf)
        best_triangle = np.full(n_rays, -1, dtype=np.int64)
        best_uv = np.full((n_rays, 2), np.nan)
        if near_triangles is not None:
            rays, t, triangles, uv = self._ring_hits(origins, directions, near_triangles, t_max, sources)
            best_t[rays], best_triangle[rays], best_uv[rays] = t, triangles, uv
            # Found again by the BVH below (the same test, the same t), unless a nearer one is.
            t_max = np.where(best_triangle >= 0, np.minimum(t_max, best_t * (1.0 + 1e-9)), t_max)
        searched = np.arange(n_rays)
        if t_guess is not None:
            reach = np.minimum(t_max, t_guess)
            found = self._bvh_hits(origins, directions, reach, sources, best_t, best_triangle, best_uv, searched)
            searched = np.flatnonzero(~found & (reach < t_max))
        self._bvh_hits(origins, directions, t_max, sources, best_t, best_triangle, best_uv, searched)
        return self._hits(origins, directions, best_t, best_triangle, best_uv)

    def _bvh_hits(self, origins, directions, t_max, sources, best_t, best_triangle, best_uv, rays_in) -> np.ndarray:
        """Nearest hits within (eps, t_max] of the rays ``rays_in`` over the whole mesh,
        written into ``best_*`` where found; returns (R,) which rays found one."""
        found = np.zeros(len(origins), dtype=bool)
        for start in range(0, len(rays_in), RAY_CHUNK):
            chunk = rays_in[start:start + RAY_CHUNK]
            rays, t, triangles, uv = self._chunk_hits(origins[chunk], directions[chunk], t_max[chunk], sources[chunk])
            best_t[chunk[rays]], best_triangle[chunk[rays]], best_uv[chunk[rays]] = t, triangles, uv
            found[chunk[rays]] = True
        return found

    def _past_plane(self, origins, directions, triangles) -> np.ndarray:
        """(R,) a likely bound on where rays meet the surface near ``triangles`` (inf for a
        triangle -1, or a plane the ray runs along or away from): their distance to the
        triangle's plane, plus a tenth and 1 % of the scene's size (the surface curves away
        from its tangent plane). A guess for ``intersect(t_guess=)``, not a promise."""
        safe = np.maximum(triangles, 0)
        normal = self.face_normals[safe]
        facing = np.einsum("ij,ij->i", directions, normal)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.einsum("ij,ij->i", self.v0[safe] - origins, normal) / facing
        usable = (triangles >= 0) & (np.abs(facing) > 1e-6) & (t > 0)
        return np.where(usable, 1.1 * t + 0.01 * self.scale, np.inf)

    def _ring_hits(self, origins, directions, near_triangles, t_max=np.inf, sources=None):
        """Each ray's nearest hit among the ring (``ring``) of its triangle in
        ``near_triangles`` (-1: none, no hit), within (eps, t_max] and off its source
        triangle's ring: (rays that hit, t, triangles, (u, v))."""
        near_triangles = np.asarray(near_triangles, dtype=np.int64)
        guessed = np.flatnonzero(near_triangles >= 0)
        owner, triangles = self.ring(near_triangles[guessed])
        owner = guessed[owner]
        t, u, v, _ = self.hit_triangles(origins[owner], directions[owner], triangles)
        with np.errstate(invalid="ignore"):
            keep = (t > SELF_HIT_EPSILON * self.scale) & (t <= np.broadcast_to(t_max, (len(origins),))[owner])
        if sources is not None:
            keep &= self._off_source(sources[owner], triangles)
        return _nearest_per_ray(owner[keep], triangles[keep], t[keep], u[keep], v[keep])

    def _off_source(self, sources, triangles) -> np.ndarray:
        """(K,) bool: a hit on ``triangles`` is not a self-hit of a ray leaving ``sources``
        (-1: from no surface): neither that triangle nor one of its one-ring."""
        keep = np.ones(len(triangles), dtype=bool)
        from_surface = np.flatnonzero(sources >= 0)
        keep[from_surface] = (~self.neighbours(sources[from_surface], triangles[from_surface])
                              & (triangles[from_surface] != sources[from_surface]))
        return keep

    def intersect_near(self, origins, directions, near_triangles, source_triangles=None) -> RayHits:
        """Hits of rays expected to land next to known triangles (``near_triangles`` (R,),
        -1 where unknown): the nearest hit among each ray's triangle and those sharing a
        vertex with it (``ring``); rays that hit none of them, or have no guess, get the
        nearest hit over all triangles (``intersect``). ``source_triangles`` as in ``intersect``.

        Not always the nearest hit: another part of the mesh, not in the ring, may lie in
        front. For rays iterated in small steps over one surface (true_rays.py), whose
        final answer is then checked with ``intersect``, it avoids a BVH descent per step.
        """
        origins = np.asarray(origins, dtype=np.float64)
        directions = np.asarray(directions, dtype=np.float64)
        near_triangles = np.asarray(near_triangles, dtype=np.int64)
        sources = None if source_triangles is None else np.asarray(source_triangles, dtype=np.int64)
        rays, t, triangles, uv = self._ring_hits(origins, directions, near_triangles, sources=sources)
        best_t = np.full(len(origins), np.inf)
        best_triangle = np.full(len(origins), -1, dtype=np.int64)
        best_uv = np.full((len(origins), 2), np.nan)
        best_t[rays], best_triangle[rays], best_uv[rays] = t, triangles, uv
        missed = np.flatnonzero(best_triangle < 0)
        if len(missed):
            hits = self.intersect(origins[missed], directions[missed],
                                  source_triangles=None if sources is None else sources[missed],
                                  t_guess=self._past_plane(origins[missed], directions[missed], near_triangles[missed]))
            best_t[missed] = hits.t
            best_triangle[missed] = hits.triangle
            best_uv[missed] = hits.barycentric[:, 1:]
        return self._hits(origins, directions, best_t, best_triangle, best_uv)

    @functools.cached_property
    def bounding_sphere(self) -> tuple[np.ndarray, float]:
        """(centre, radius): the sphere around the vertices' box centre through the
        farthest vertex; every triangle lies inside it."""
        centre = 0.5 * (self.vertices.min(axis=0) + self.vertices.max(axis=0))
        offset = self.vertices - centre
        return centre, float(np.sqrt(np.max(np.einsum("vd,vd->v", offset, offset))))

    @functools.cached_property
    def triangle_grid(self) -> TriangleGrid:
        """A triangle near any point within ``NEAR_SURFACE`` of the scene's size from the
        surface (``triangle_grid.py``), built on first use."""
        return TriangleGrid(self.vertices, self.triangles, NEAR_SURFACE * self.scale)

    @functools.cached_property
    def windings(self) -> tuple:
        """Per reflector, ``closed_surfaces.winding``: +1 or -1 where it closes a solid,
        else 0 (over the welded triangles this set holds already)."""
        ends = np.cumsum([0] + [len(r.triangles) for r in self.reflectors])
        return tuple(closed_surfaces.winding(r.vertices, r.triangles, self.welded_triangles[start:end])
                     for r, start, end in zip(self.reflectors, ends[:-1], ends[1:]))

    @functools.cached_property
    def closed_sides(self) -> np.ndarray:
        """(T,) int8: +1 where a triangle's winding normal (e1 x e2) points out of the
        solid its reflector closes, -1 where it points in, 0 on a reflector that closes
        none (``closed_surfaces.winding``). An eye on a closed mirror's inner side of a
        face sees that face through the rest of the mirror, or from inside it."""
        return np.array(self.windings, dtype=np.int8)[self.owner]

    @functools.cached_property
    def edge_neighbours(self) -> np.ndarray:
        """(T, 3) the triangle across the edge opposite each corner, -1 on an open edge
        (``triangle_grid.edge_neighbours``)."""
        return edge_neighbours(self.welded_triangles)

    @functools.cached_property
    def fans(self) -> tuple[np.ndarray, np.ndarray]:
        """CSR (start (V + 1,), triangles) of the triangles around each welded vertex.
        A triangle's ring (those sharing a vertex with it) is its corners' fans: 3 T
        entries, where the rings themselves held 13 T and cost seconds to pair up."""
        corner_vertex = self.welded_triangles.reshape(-1)
        start = np.zeros(len(self.vertices) + 1, dtype=np.int64)
        np.cumsum(np.bincount(corner_vertex, minlength=len(self.vertices)), out=start[1:])
        if len(corner_vertex) >= 2 ** 32:
            return start, np.argsort(corner_vertex, kind="stable") // 3
        # The corners by vertex, then by index (a stable sort by vertex) as one sort, in
        # place, of (vertex, corner) keys; the triangles in 32 bits: the fans of a
        # million-triangle mirror hold 12 MB, not 24, and their making 36 MB, not 48.
        keys = corner_vertex.astype(np.uint64)
        keys <<= np.uint64(32)
        for first in range(0, len(keys), BUILD_BLOCK):
            keys[first:first + BUILD_BLOCK] |= np.arange(first, min(first + BUILD_BLOCK, len(keys)), dtype=np.uint64)
        keys.sort()
        fan = np.empty(len(keys), dtype=np.int32)
        for first in range(0, len(keys), BUILD_BLOCK):
            fan[first:first + BUILD_BLOCK] = (keys[first:first + BUILD_BLOCK] & np.uint64(0xFFFFFFFF)) // np.uint64(3)
        return start, fan

    def ring(self, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(owner, member): for each of ``triangles`` (K,), every triangle sharing a
        (welded) vertex with it, itself included, once: ``owner`` its row in
        ``triangles``. A member of the fans of two of its corners is kept in the first."""
        start, fan = self.fans
        corners = self.welded_triangles[triangles]  # (K, 3)
        owner, member = expand_ranges(start[corners.reshape(-1)], np.diff(start)[corners.reshape(-1)])
        corner, owner = owner % 3, owner // 3
        member = fan[member]
        around = self.welded_triangles[member]  # (M, 3)
        earlier = np.zeros(len(member), dtype=bool)
        for k in (0, 1):  # the member also holds an earlier corner of its owner
            earlier |= (corner > k) & (around == corners[owner, k][:, None]).any(axis=1)
        return owner[~earlier], member[~earlier]

    def occluded(self, origins, directions, distances, source_triangles=None) -> np.ndarray:
        """(R,) bool: a reflector lies on the segment of length ``distances`` along each ray."""
        distances = np.asarray(distances, dtype=np.float64) * (1.0 - 1e-9)
        return self.intersect(origins, directions, distances, source_triangles).hit

    def _chunk_hits(self, origins, directions, t_max, sources):
        t_min = np.full(len(origins), SELF_HIT_EPSILON * self.scale)
        test = ray_box_test(self.bvh, origins, directions, t_min, t_max)
        candidates = descend(self.bvh, np.arange(len(origins)), test)
        hits = []
        # The candidate pairs a block at a time: their corners and the test's temporaries
        # are ~150 bytes a pair (rays through a million-triangle mirror's far side: a
        # million pairs for a chunk); the hits they keep are few.
        for start in range(0, max(1, len(candidates[0])), PAIR_CHUNK):
            rays, triangles = (c[start:start + PAIR_CHUNK] for c in candidates)
            t, u, v, _ = self.hit_triangles(origins[rays], directions[rays], triangles)
            with np.errstate(invalid="ignore"):
                keep = (t > t_min[rays]) & (t <= t_max[rays])
            # Rays from a reflector skip the triangle they start from and its one-ring.
            keep[keep] &= self._off_source(sources[rays[keep]], triangles[keep])
            hits.append((rays[keep], triangles[keep], t[keep], u[keep], v[keep]))
        return _nearest_per_ray(*(hits[0] if len(hits) == 1 else map(np.concatenate, zip(*hits))))

    def hit_triangles(self, origins, directions, triangles):
        """Batched Moller-Trumbore of ray i against triangle i.

        Returns (t, u, v, det): t is NaN where the pair misses (outside the triangle, or
        the ray parallel to its plane); u, v weigh corners 1 and 2; det is the test's
        determinant, -(d . face normal) times twice the area.
        """
        rows = self.corner_rows[:, triangles]
        v0, e1, e2 = rows[0:3], rows[3:6], rows[6:9]
        d = np.ascontiguousarray(directions.T)
        p = cross_rows(d, e2)
        det = dot_rows(e1, p)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            s = origins.T - v0
            u = dot_rows(s, p) * inv
            q = cross_rows(s, e1)
            v = dot_rows(d, q) * inv
            t = dot_rows(e2, q) * inv
            tolerance = 1e-12
            # A ray parallel to the plane has NaN or infinite u, v: not inside.
            inside = (np.abs(det) > 1e-300) & (u >= -tolerance) & (v >= -tolerance) & (u + v <= 1 + tolerance)
        return np.where(inside, t, np.nan), u, v, det

    def _hits(self, origins, directions, t, triangles, uv) -> RayHits:
        hit = triangles >= 0
        barycentric = np.full((len(t), 3), np.nan)
        barycentric[hit] = np.stack([1 - uv[hit, 0] - uv[hit, 1], uv[hit, 0], uv[hit, 1]], axis=1)
        position = np.full((len(t), 3), np.nan)
        normal = np.full((len(t), 3), np.nan)
        face = np.full((len(t), 3), np.nan)
        # Positions from the ray (exactly on it), normals from the surface, both-sided.
        position[hit] = origins[hit] + t[hit, None] * directions[hit]
        _, normal[hit] = self.surface(triangles[hit], barycentric[hit])
        face[hit] = self.face_normals[triangles[hit]]
        flip = np.einsum("ij,ij->i", face[hit], directions[hit]) > 0
        face[hit] = np.where(flip[:, None], -face[hit], face[hit])
        normal[hit] = np.where(flip[:, None], -normal[hit], normal[hit])
        reflector = np.where(hit, self.owner[np.maximum(triangles, 0)], -1)
        return RayHits(t, triangles, reflector, barycentric, position, normal, face)
