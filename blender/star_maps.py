# SPDX-License-Identifier: GPL-3.0-or-later
"""Which reflectors are star-shaped, and their cube maps: made once per reflector shape.

The iterative search (Roger & Holzschuch 2006) needs a reflector star-shaped around a
centre and its cube map (``engine/methods/iterative/star.py``, ``reflector_map.py``); a
closed mirror that is not is searched as pieces seen from inside it, one map each
(``engine/methods/iterative/pieces.py``, :func:`piece_maps`). The
verdict and the maps are kept per shape (compared up to a translation with the
:data:`CACHED_MAPS` kept): a viewport orbit, an animation frame in which the mirror did
not change, or a mirror moved without turning reuses them (the map moves with its
centre). The map is baked on the GPU when it is initialised
(``drawing/methods/iterative_bake.py``, milliseconds), else traced on the CPU.
"""

from __future__ import annotations

import dataclasses
import hashlib
from dataclasses import dataclass

import numpy as np

from ..engine.geometry.closed_surfaces import winding
from ..engine.geometry.raytrace import ReflectorSet
from ..engine.methods.iterative import StarShape, check_star_shaped
from ..engine.methods.iterative.fold_patches import fold_patches, folded
from ..engine.methods.iterative.reflector_map import bake_reflector_map
from ..engine.methods.iterative.pieces import StarPieces, map_first_surface, split_into_pieces
from ..engine.methods.iterative.star import verdict
from ..drawing.methods.iterative_bake import GPUMapBaker
from .gpu_init import gpu_ready

#: Cube-map face size of the iterative search's reflector maps (texels along a side).
FACE_SIZE = 256
#: Reflector geometries whose verdict and map are kept.
CACHED_MAPS = 16
#: Face size of the maps that choose the pieces' centres (one per candidate centre).
CHOOSE_FACE_SIZE = 64


_maps: list = []  # _Entry, most recently used last


def _baker(reflector):
    """``bake(centre, face_size) -> MapBake`` of the reflector's maps: rasterised on the
    GPU when it is ready (one upload for every map), else traced on the CPU."""
    if gpu_ready():
        return GPUMapBaker(reflector).bake
    reflector_set = ReflectorSet([reflector])
    return lambda centre, face_size: bake_reflector_map(reflector_set, centre, face_size)


#: Vertex positions of two captures of one shape (relative to their first vertex) may
#: differ by this share of its size: Blender's float32 matrices move the float64 capture.
SHAPE_TOLERANCE = 1e-9


@dataclass(frozen=True)
class _Entry:
    """One cached verdict and map, with the shape they were made for."""

    topology: str
    face_size: int
    offsets: np.ndarray  # vertex positions relative to the first vertex
    normals: np.ndarray
    origin: np.ndarray  # the first vertex
    shape: StarShape
    reflector_map: object
    #: (StarPieces, piece maps) once :func:`piece_maps` asked for them.
    pieces: tuple | None = None
    #: Whether the mesh closes a solid, once :func:`closed_surface` asked.
    closed: bool | None = None

    def matches(self, reflector, topology: str, face_size: int) -> bool:
        if (self.topology, self.face_size) != (topology, face_size):
            return False
        offsets = reflector.vertices - reflector.vertices[0]
        tolerance = SHAPE_TOLERANCE * max(float(np.abs(offsets).max()), 1e-300)
        return bool(np.abs(offsets - self.offsets).max() <= tolerance
                    and np.abs(reflector.normals - self.normals).max() <= 1e-9)

    def moved_to(self, reflector):
        """The verdict and map, moved with the reflector's first vertex."""
        shift = reflector.vertices[0] - self.origin
        return dataclasses.replace(self.shape, centre=self.shape.centre + shift), _moved(self.reflector_map, shift)

    def pieces_moved_to(self, reflector):
        """The pieces' verdict and maps, moved with the reflector's first vertex."""
        return _pieces_moved(self.pieces, reflector.vertices[0] - self.origin)


def _moved(rmap, shift):
    """A map moved by ``shift`` (its texels, and a piece's patches, are relative to its centre)."""
    return None if rmap is None else dataclasses.replace(rmap, centre=rmap.centre + shift)


def _pieces_moved(pieces: tuple, shift) -> tuple:
    """(StarPieces, piece maps) moved by ``shift``."""
    shape, maps = pieces
    return dataclasses.replace(shape, centres=shape.centres + shift), [_moved(rmap, shift) for rmap in maps]


def _topology(reflector) -> str:
    digest = hashlib.sha1(np.ascontiguousarray(reflector.triangles).tobytes())
    digest.update(str(len(reflector.vertices)).encode())
    return digest.hexdigest()


def _entry(reflector, face_size: int | None) -> _Entry:
    """The cache entry of the reflector's shape, made most recently used: found, or made
    (the star-shape verdict, and where star-shaped the full-resolution map, whose rays
    are checked again: a thin fold, a small hole)."""
    face_size = FACE_SIZE if face_size is None else int(face_size)
    topology = _topology(reflector)
    for index, entry in enumerate(_maps):
        if entry.matches(reflector, topology, face_size):
            _maps.append(_maps.pop(index))
            return entry
    bake_map = _baker(reflector)
    shape = check_star_shaped(reflector, bake_map=bake_map)
    rmap = None
    if shape.star_shaped:
        bake = bake_map(shape.centre, face_size)
        shape = verdict(reflector.name, shape.centre, bake, shape.hidden_share)
        rmap = folded(bake.reflector_map, patched=False) if shape.star_shaped else None
    _maps.append(_Entry(topology, face_size, reflector.vertices - reflector.vertices[0], reflector.normals.copy(),
                        reflector.vertices[0].copy(), shape, rmap))
    del _maps[:-CACHED_MAPS]
    return _maps[-1]


def star_map(reflector, face_size: int | None = None, patched: bool = False):
    """(StarShape, ReflectorMap or None) of one reflector, cached by its shape: a mirror
    moved without turning reuses its verdict and its map, moved with it
    (``face_size``: default :data:`FACE_SIZE`). A map that folds its reflections says so
    (``images``); the search's starts on it (``patches``) come with ``patched``, made
    once (a second's work on a 20k-triangle mirror that Auto, which traces it, skips)."""
    entry = _entry(reflector, face_size)
    rmap = entry.reflector_map
    if patched and rmap is not None and rmap.images > 1 and rmap.patches is None:
        # _entry left the entry last (most recently used): it is replaced there.
        entry = _maps[-1] = dataclasses.replace(entry, reflector_map=dataclasses.replace(
            rmap, patches=fold_patches(rmap)))
    return entry.moved_to(reflector)


def closed_surface(reflector, face_size: int | None = None) -> bool:
    """Whether the reflector closes a solid (``closed_surfaces.winding``), cached with its
    verdict: only a closed mirror is split into pieces."""
    entry = _entry(reflector, face_size)
    if entry.closed is None:
        _maps[-1] = entry = dataclasses.replace(entry, closed=winding(reflector.vertices, reflector.triangles) != 0)
    return entry.closed


def piece_maps(reflector, face_size: int | None = None) -> tuple[StarPieces, list]:
    """(StarPieces, piece maps, empty where refused) of a closed reflector that is not
    star-shaped (:func:`star_map` says so first), cached with its verdict: the pieces'
    centres are chosen from maps baked on the GPU when it is ready (else rays on the
    CPU), and each piece's map baked as :func:`star_map`'s."""
    entry = _entry(reflector, face_size)
    if entry.pieces is None:
        face_size = entry.face_size
        bake_map = _baker(reflector)  # on the GPU, one upload for every candidate's and piece's map
        choose = map_first_surface(lambda centre: bake_map(centre, CHOOSE_FACE_SIZE)) if gpu_ready() else None
        shape, maps = split_into_pieces(reflector, lambda _, centre: bake_map(centre, face_size), choose)
        # Kept where the entry's shape was first captured, as its map is.
        pieces = _pieces_moved((shape, maps), entry.origin - reflector.vertices[0])
        _maps[-1] = entry = dataclasses.replace(entry, pieces=pieces)
    return entry.pieces_moved_to(reflector)


def forget() -> None:
    """Drop the cached verdicts and maps (another file is loaded, or unregister)."""
    _maps.clear()
