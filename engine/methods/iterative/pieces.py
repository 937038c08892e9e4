# SPDX-License-Identifier: GPL-3.0-or-later
"""A closed mirror no one point sees whole, searched as a few star-shaped pieces.

The iterative search (Roger & Holzschuch 2006) needs the mirror as one radius per
direction around a centre O (section 3.3.1): a torus, a teapot with handle and spout, a
metaball of fused capsules are not. The sample-based camera paper splits such a
reflector into pieces, one reflection group each (Popescu et al. 2006, section VII, the
car in seven parts, Fig. 20a); here a piece is the part of the mirror seen well from one
point *inside* it:

- From a point O inside the closed solid, the first surface along any ray is the wall,
  and the segment from O to it lies inside the solid. So the cube map of first hits
  around O (:mod:`.reflector_map`) is exact wherever it has a value, and its
  inside test (closer to O than r) is exact too: other pieces and other mirrors block a
  reflected segment through the solid just as a star-shaped mirror's map does.
- A texel keeps its value only where the ray meets the wall at a cosine of at least
  :data:`.star.MIN_COSINE` (what the search can settle on) and not beside a jump of the
  radius to a farther wall (:data:`JUMP_SHARE`): a bilinear lookup across a jump would
  invent a surface between two walls. The rest is a hole (r = 0): what the piece does
  not hold, another one does.
- Centres are tried halfway through the solid, on inward rays from surface samples (the
  middle of a torus's tube, of a handle, of a spout); a greedy cover takes the centre
  that sees the most area not yet seen until every sample is seen or
  :data:`MAX_PIECES` are taken, and the full-resolution maps are checked once more on
  every triangle (:func:`uncovered_share`).

Each piece is searched on its own (a point reflected in two pieces has two images, both
drawn): Newton starts from every patch of the surface the piece adds to the earlier
ones whose normals can reflect the point toward the eye (:func:`piece_patches`,
:func:`piece_map`; ``search.patch_admits``), and runs on the piece's whole map. The
reflected meshes' law-of-reflection and hidden-point tests keep each image on the pixels
where the mirror really shows it, so pieces may overlap. A piece finds one image of a
point; where it holds two (a fold), the other piece that starts there
(:data:`STARTS_PER_POINT`) may find the second.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ...geometry.raytrace import ReflectorSet
from ...geometry.vectors import dot, lengths
from ...projection import Projection
from ...scene import Reflector
from ...view import View
from .patches import face_cells, grouped_patches, texel_grid
from .reflector_map import MapBake, ReflectorMap, texel_directions
from .search import IterativeReflector
from .star import MIN_COSINE

#: At most this many pieces: each is one search of every diffuse vertex per frame.
MAX_PIECES = 12
#: Centres tried: halfway along inward rays from this many surface samples.
CANDIDATE_CENTRES = 96
#: Surface samples (triangle centroids, by area) the greedy cover counts.
COVER_SAMPLES = 1500
#: A sample counts as seen from a centre only at this share above the texels' cosine
#: limit: the full-resolution map, masked at MIN_COSINE, then holds it with a margin.
COVER_MARGIN = 1.2
#: The cover stops when what the next piece would add is below this share of the area.
LEAST_GAIN = 1e-3
#: A mirror whose pieces leave more than this share of its area unseen is refused. What
#: they leave are slivers seen nearly edge-on from every centre tried (0.5 % of Blender's
#: default torus); an image missed there fails the accuracy check, which hands the mirror
#: on to the next method.
MAX_UNCOVERED = 1e-2
#: A texel beside a neighbour whose radius differs by more than this share of its own
#: lies on a jump between two walls. Where the cosine is at least MIN_COSINE the radius
#: changes by at most r tan(acos MIN_COSINE) (3.9 r) per radian, 0.03 r across a texel of
#: a 256 face: ten times less.
JUMP_SHARE = 0.3
#: Patches along each cube face's side (``piece_patches``): where the search starts.
#: Finer patches have narrower normal cones but cost a test each per point, and on a
#: torus find no more of its exact images.
PATCH_CELLS = 4
#: Each part of the surface is a start in this many pieces at most (where that many
#: hold it): a piece finds one image of a point, so where it holds two (a torus's folds)
#: another piece finds the second (on a torus 99.0 % of the exact images, against 98.2 %
#: from one piece, for 1.7 times the Newton steps).
STARTS_PER_POINT = 2
#: Patches are made of the texels on a grid this many apart (what an earlier piece holds
#: is tested on them: a lookup per texel per earlier map).
PATCH_STRIDE = 4
#: A triangle centroid is held by a piece where the map's radius along its direction is
#: within this share of the mirror's size of its distance.
HELD_TOLERANCE = 2e-3


@dataclass(frozen=True)
class StarPieces:
    """The verdict on splitting one closed mirror: ``centres`` (K, 3) of the pieces
    taken, ``uncovered`` the share of its area no piece holds, ``reason`` empty where
    the pieces may be searched, else why not (for the panel)."""

    name: str
    centres: np.ndarray
    uncovered: float
    reason: str

    @property
    def usable(self) -> bool:
        return not self.reason


def _outward_faces(reflector: Reflector, turn: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(centroids, outward unit face normals, areas) of the triangles; ``turn`` is the
    mesh's winding (+1 counter-clockwise seen from outside, -1 the other way)."""
    corners = reflector.vertices[reflector.triangles]
    face = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    double_area = np.maximum(lengths(face), 1e-300)
    return corners.mean(axis=1), turn * face / double_area[:, None], 0.5 * double_area


def _size(reflector: Reflector) -> float:
    """The mirror's bounding-box diagonal."""
    lo, hi = reflector.bounds
    return float(np.linalg.norm(hi - lo))


def interior_centres(reflector_set: ReflectorSet, centroids, normals, count: int, rng) -> np.ndarray:
    """Up to ``count`` points halfway between a surface sample and the wall its inward
    ray meets next: the middle of the solid under it (a tube's axis, a body's core)."""
    rows = rng.choice(len(centroids), min(count, len(centroids)), replace=False)
    start = centroids[rows] - 1e-6 * reflector_set.scale * normals[rows]
    hits = reflector_set.intersect(start, -normals[rows])
    return start[hits.hit] - 0.5 * hits.t[hits.hit, None] * normals[rows][hits.hit]


def ray_first_surface(reflector_set: ReflectorSet) -> Callable:
    """``first_surface(centre, directions) -> (K,) distance`` to the first surface along
    unit ``directions`` from ``centre`` (inf where none), traced on the CPU."""
    def first_surface(centre, directions):
        return reflector_set.intersect(np.broadcast_to(centre, directions.shape), directions).t
    return first_surface


def open_refusal(name: str) -> str:
    """Why a mirror that is not star-shaped and not closed is not split into pieces."""
    return f"{name!r} is not star-shaped and not a closed surface, so it cannot be split into pieces seen from inside"


def map_first_surface(bake: Callable) -> Callable:
    """``first_surface`` as :func:`ray_first_surface`, read from a map baked around the
    centre (``bake(centre) -> MapBake``, e.g. on the GPU: one draw instead of a ray per
    sample); inf where the map has a hole."""
    def first_surface(centre, directions):
        radius, _, valid = bake(centre).reflector_map.surface(directions)
        return np.where(valid, radius, np.inf)
    return first_surface


def seen_from(first_surface: Callable, centre, points, normals, size: float) -> np.ndarray:
    """(K,) bool: ``points`` are the first surface from ``centre`` (within
    :data:`HELD_TOLERANCE` of the mirror's ``size``) and face it at a cosine of at least
    MIN_COSINE times COVER_MARGIN (their outward ``normals``)."""
    offset = points - centre
    distance = np.maximum(lengths(offset), 1e-300)
    direction = offset / distance[:, None]
    first = first_surface(centre, direction)
    return (first >= distance - HELD_TOLERANCE * size) & (dot(direction, normals) >= COVER_MARGIN * MIN_COSINE)


def choose_centres(reflector: Reflector, reflector_set: ReflectorSet | None = None,
                   first_surface: Callable | None = None, seed: int = 0) -> StarPieces:
    """The pieces' centres of a closed mirror by a greedy cover of surface samples (the
    centre seeing most of the area not yet seen first), or the reason there are none.
    ``first_surface``: as :func:`ray_first_surface` (the default), e.g. from GPU maps."""
    reflector_set = reflector_set or ReflectorSet([reflector])
    turn = reflector_set.windings[0]
    if turn == 0:
        return StarPieces(reflector.name, np.zeros((0, 3)), 1.0, open_refusal(reflector.name))
    centroids, normals, areas = _outward_faces(reflector, turn)
    rng = np.random.default_rng(seed)
    candidates = interior_centres(reflector_set, centroids, normals, CANDIDATE_CENTRES, rng)
    samples = rng.choice(len(centroids), min(COVER_SAMPLES, len(centroids)), replace=False,
                         p=areas / areas.sum())
    first_surface = first_surface or ray_first_surface(reflector_set)
    size = _size(reflector)
    seen = np.array([seen_from(first_surface, c, centroids[samples], normals[samples], size)
                     for c in candidates]).reshape(len(candidates), len(samples))
    weight = areas[samples] / areas[samples].sum()
    covered = np.zeros(len(samples), dtype=bool)
    chosen = []
    while len(chosen) < MAX_PIECES and len(candidates):
        gain = (seen & ~covered) @ weight
        best = int(np.argmax(gain))
        if gain[best] < LEAST_GAIN:
            break
        chosen.append(best)
        covered |= seen[best]
    uncovered = float(weight[~covered].sum())
    reason = ""
    if uncovered > MAX_UNCOVERED:
        reason = (f"{reflector.name!r} is not star-shaped, and {len(chosen)} pieces seen from inside it leave "
                  f"{100 * uncovered:.1f} % of its surface unseen (a thin part, a deep crease)")
    return StarPieces(reflector.name, candidates[chosen], uncovered, reason)


def piece_map(bake: MapBake, earlier: tuple = (), size: float = 1.0) -> ReflectorMap:
    """The map of one piece: ``bake`` (every first hit from its centre, with
    ``texel_cosine``) with holes where the cosine is below MIN_COSINE or the radius
    jumps to another wall (:data:`JUMP_SHARE`), and the patches of the surface it adds
    to the ``earlier`` pieces' maps (:func:`piece_patches`; ``size``: the mirror's)."""
    rmap = bake.reflector_map
    side = rmap.face_size + 2
    radius = rmap.texels[..., 0].reshape(6, side, side).astype(np.float64)
    keep = (radius > 0) & (bake.texel_cosine.reshape(6, side, side) >= MIN_COSINE)
    jump = np.zeros_like(keep)
    for axis in (1, 2):
        a = radius.take(np.arange(side - 1), axis=axis)
        b = radius.take(np.arange(1, side), axis=axis)
        step = (a > 0) & (b > 0) & (np.abs(a - b) > JUMP_SHARE * np.minimum(a, b))
        index = [slice(None)] * 3
        index[axis] = slice(0, side - 1)
        jump[tuple(index)] |= step
        index[axis] = slice(1, side)
        jump[tuple(index)] |= step
    texels = rmap.texels.copy()
    texels[~(keep & ~jump).reshape(texels.shape[:2])] = 0.0
    kept = texels[..., 0][texels[..., 0] > 0]
    piece = ReflectorMap(rmap.centre, rmap.face_size, texels, False,
                         float(kept.min()) if len(kept) else 0.0, float(kept.max()) if len(kept) else 0.0)
    return dataclasses.replace(piece, patches=piece_patches(piece, earlier, size))


def piece_patches(rmap: ReflectorMap, earlier: tuple = (), size: float = 1.0, cells: int = PATCH_CELLS) -> np.ndarray:
    """The search's starts on a piece's map: the surface it adds to the ``earlier``
    pieces' maps (texels on a grid :data:`PATCH_STRIDE` apart whose point fewer than
    :data:`STARTS_PER_POINT` earlier maps hold within :data:`HELD_TOLERANCE` of
    ``size``), grouped by a ``cells`` x ``cells``
    grid on each cube face, each group a patch with the mean direction of its texels
    (where Newton starts), the cone of its normals and its bounding sphere
    (``ReflectorMap.patches``: what lets a search skip the patches that cannot hold a
    point's reflection). Newton runs on the whole map, so an image near a border is
    found from either side, and a point is searched from each part of the surface a
    few times, not once per piece that sees it (the greedy order puts the largest
    pieces first)."""
    directions = texel_directions(rmap.face_size).reshape(-1, 3)
    texels = rmap.texels.reshape(-1, 4).astype(np.float64)
    _, row, column = texel_grid(rmap.face_size)
    sampled = np.flatnonzero((texels[:, 0] > 0) & (row % PATCH_STRIDE == 0) & (column % PATCH_STRIDE == 0))
    position = texels[sampled, :1] * directions[sampled]
    holders = np.zeros(len(sampled), dtype=np.int64)
    for other in earlier:
        holders += _holds(other, rmap.centre + position, HELD_TOLERANCE * size)
    added = sampled[holders < STARTS_PER_POINT]
    return grouped_patches(rmap, added, face_cells(rmap.face_size, cells)[added])


def uncovered_share(reflector: Reflector, maps: list) -> float:
    """Share of the mirror's area whose triangle centroid no piece map holds (its radius
    along the centroid's direction within :data:`HELD_TOLERANCE` of the distance)."""
    centroids, _, areas = _outward_faces(reflector, 1)
    held = np.zeros(len(centroids), dtype=bool)
    tolerance = HELD_TOLERANCE * _size(reflector)
    for rmap in maps:
        held |= _holds(rmap, centroids, tolerance)
    return float(areas[~held].sum() / areas.sum())


def _holds(rmap: ReflectorMap, points: np.ndarray, tolerance: float) -> np.ndarray:
    """(K,) bool: the map's radius along each point's direction is within ``tolerance``
    of its distance (the point is on the surface the map holds)."""
    offset = points - rmap.centre
    distance = np.maximum(lengths(offset), 1e-300)
    radius, _, valid = rmap.surface(offset / distance[:, None])
    return valid & (np.abs(radius - distance) <= tolerance)


def split_into_pieces(reflector: Reflector, bake: Callable, first_surface: Callable | None = None
                      ) -> tuple[StarPieces, list]:
    """(verdict, piece maps) of a closed mirror that is not star-shaped: the centres
    (:func:`choose_centres`), each one's full-resolution map (``bake(reflector, centre)``
    -> MapBake with ``texel_cosine``) with its holes and the patches it adds
    (:func:`piece_map`), and the share of the area they leave unseen checked again on
    every triangle."""
    pieces = choose_centres(reflector, first_surface=first_surface)
    if not pieces.usable:
        return pieces, []
    maps, size = [], _size(reflector)
    for centre in pieces.centres:
        maps.append(piece_map(bake(reflector, centre), tuple(maps), size))
    # A piece whose surface the earlier ones hold adds no start: it is not searched.
    kept = [k for k, rmap in enumerate(maps) if len(rmap.patches)]
    maps, centres = [maps[k] for k in kept], pieces.centres[kept]
    uncovered = uncovered_share(reflector, maps)
    reason = ""
    if uncovered > MAX_UNCOVERED:
        reason = (f"{reflector.name!r} is not star-shaped, and its {len(maps)} pieces seen from inside leave "
                  f"{100 * uncovered:.1f} % of its surface unseen at full resolution")
    return StarPieces(pieces.name, centres, uncovered, reason), (maps if not reason else [])


@dataclass
class IterativePieces:
    """The iterative method for one mirror searched as star-shaped pieces, behind the
    common interface: one reflection group per piece (the same first-order history,
    repeated: a point may appear in several pieces)."""

    index: int
    name: str
    pieces: list  # IterativeReflector per piece, each with the others' maps as occluders
    shape: StarPieces | None = None

    @classmethod
    def of_maps(cls, index: int, name: str, maps: list, accuracy_px: float = 1.0, shape=None) -> "IterativePieces":
        pieces = [IterativeReflector(index, name, rmap, accuracy_px, piece=k) for k, rmap in enumerate(maps)]
        for piece in pieces:
            piece.occluders = tuple(other.reflector_map for other in pieces if other is not piece)
        return cls(index, name, pieces, shape)

    @property
    def groups(self) -> list:
        return [(self.index,)] * len(self.pieces)

    def project(self, view: View, points) -> Projection:
        parts = [piece.project(view, points) for piece in self.pieces]
        return Projection(groups=self.groups,
                          **{name: np.concatenate([getattr(p, name) for p in parts])
                             for name in ("reflector_points", "valid", "leaf_kind", "pixels", "ray_distance")})


def searched_methods(engines) -> list:
    """Every searched map's method among the iterative engines of a plan: a star-shaped
    mirror's own, or each piece of one searched as pieces."""
    return [method for engine in engines for method in getattr(engine, "pieces", [engine])]
