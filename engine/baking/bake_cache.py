# SPDX-License-Identifier: GPL-3.0-or-later
"""The on-disk cache of baked morphing grids (SBC paper VI: the grid is a preprocess).

Layout under the cache directory (the Blender layer passes one folder per .blend file,
``blender/morph_bake.cache_directory``, so files never share or delete each other's
grids)::

    <reflector name>-<key[:16]>-<shape[:8]>/grid.npz           manifest: key, shape, box, settings,
                                                               geometry
    <reflector name>-<key[:16]>-<shape[:8]>/node_00012.npz     one node: a panoramic camera (six
                                                               faces' SBC arrays) or a ray octree
    <reflector name>-<key[:16]>-<shape[:8]>/node_00013.inside  a node inside the mirror (no camera)

Every file is plain arrays (``np.savez``; node files compressed, their arrays packed into
one buffer, ``packed_arrays``), read with ``allow_pickle=False``, and written
atomically (a temporary name, then ``os.replace``), so that several processes, on one
machine or on a render farm's, can bake ranges of one grid's nodes into the same folder
at once: the manifest is the same bytes whoever writes it, a node is either absent or
whole, and a node already baked (its file present and of this grid) is not baked again.
A grid is usable once every node has its file.

A grid is identified by two things. Its *key* is a SHA-256 of the reflector's topology,
the grid settings and the engine (its version and the bytes of the modules a bake runs).
Its *shape* is the geometry in the reflector's rigid frame: the manifest holds it,
compared with the current one to 1e-6 of its size (a rigidly moved mirror comes back to
its frame only to float32 rounding, so positions cannot be hashed), and names it by a
SHA-256 of the bytes the first bake stored. A grid is found by its key and the shape it
was baked for (:func:`find_grid`), and every node file carries both (:func:`node_key`),
so a mirror whose vertices moved (same topology, same object transform) gets a new
folder and every node baked afresh, and a node file of another shape or grid is refused.
A renamed mirror takes its grid along (:func:`adopt_grid`).
So a rigidly moved reflector keeps its cache, any change of shape, scale or settings
makes it stale, and a cache baked for other geometry or settings is never loaded.
Missing, stale, incomplete and corrupt caches raise :class:`CacheError` with a message
for the user, never a traceback. A node file found damaged when it is
read is renamed ``*.damaged``: the grid then reads as incomplete, and the next bake
builds that node again.

Nodes are read lazily (the eight of the current tetrahedron's cube, a few kept), as the paper
keeps only two layers of its grid in memory.
"""

from __future__ import annotations

import functools
import hashlib
import os
import re
import shutil
import threading
import time
import zipfile
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import SceneInputError
from ..methods.octree import OctreeGrid, build_octree_node, octree_node_arrays, octree_node_from_arrays
from ..methods.morphing.morphing import ENGINE_VERSION, MirrorOnDemand, MorphingGrid
from ..methods.morphing.morph_grid import (NODE_INSIDE, OCTREE, TETRAHEDRAL, MorphSettings, NodeCamera, TetrahedralGrid,
                                           build_node)
from ..scene import Reflector
from ..methods.sbc.sbc_arrays import sbc_from_arrays, sbc_to_arrays
from .packed_arrays import pack_arrays, unpack_arrays

MANIFEST = "grid.npz"
#: Suffix of a node inside the mirror (no camera: its file holds only the key).
INSIDE_SUFFIX = ".inside"
#: Suffix a damaged node file is renamed to when it is read.
DAMAGED_SUFFIX = ".damaged"
#: Nodes kept in memory by a loaded grid (a view reads its cell's eight: a tetrahedron's
#: four and the rest of its cube, or an octree cell's; neighbours come next).
NODES_IN_MEMORY = 16
#: A temporary file untouched this long (s) is a write that never finished: writing a
#: node takes seconds, so no process baking into the folder is still writing it.
ABANDONED_AFTER_S = 600.0
#: Largest difference (in reflector sizes; unit normals: absolute) between the baked and
#: the current geometry in the rigid frame for a cache to be used.
GEOMETRY_TOLERANCE = 1e-6


class CacheError(SceneInputError):
    """A morphing cache that cannot be used; ``reason`` is 'missing', 'stale',
    'incomplete' or 'corrupt'."""

    def __init__(self, object_name: str, reason: str, problem: str):
        self.reason = reason
        super().__init__(object_name, problem)


@functools.lru_cache(maxsize=1)
def engine_fingerprint() -> str:
    """SHA-256 of every engine module (``engine/**/*.py``, the methods' sub-packages too): a
    cache baked by other engine code is stale. Conservative: a change anywhere in the
    engine asks for a new bake."""
    digest = hashlib.sha256()
    root = Path(__file__).resolve().parents[1]  # engine/
    for path in sorted(root.rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()


def cache_key(local_reflector: Reflector, settings: MorphSettings) -> str:
    """SHA-256 of the mesh's topology, the settings and the engine (version and code).

    Positions and normals are not hashed but compared with a tolerance at load
    (:data:`GEOMETRY_TOLERANCE`): Blender's object matrices are float32, so a rigidly
    moved mirror comes back to its frame only to about 1e-9, and any rounding before
    a hash would sometimes fall on the other side of a rounding boundary.
    """
    digest = hashlib.sha256()
    digest.update(repr((ENGINE_VERSION, engine_fingerprint(), settings.as_tuple(),
                        len(local_reflector.vertices))).encode())
    digest.update(np.ascontiguousarray(local_reflector.triangles, dtype=np.int64).tobytes())
    return digest.hexdigest()


def shape_key(local_reflector: Reflector) -> str:
    """SHA-256 of the geometry's bytes in the rigid frame: the name of a shape's grid
    folder when it is first baked (later bakes and loads find it by tolerance)."""
    digest = hashlib.sha256()
    for array in (local_reflector.vertices, local_reflector.normals):
        digest.update(np.ascontiguousarray(array, dtype=np.float64).tobytes())
    return digest.hexdigest()


def node_key(key: str, shape: str) -> str:
    """What every file of one grid carries: its key and its shape."""
    return f"{key}:{shape}"


def same_geometry(local_reflector: Reflector, vertices: np.ndarray, normals: np.ndarray) -> bool:
    """The stored geometry (in the rigid frame) matches this reflector's to the tolerance."""
    lo, hi = local_reflector.bounds
    size = max(float(np.max(hi - lo)), 1e-12)
    return (vertices.shape == local_reflector.vertices.shape and normals.shape == local_reflector.normals.shape
            and float(np.max(np.abs(vertices - local_reflector.vertices), initial=0.0)) <= GEOMETRY_TOLERANCE * size
            and float(np.max(np.abs(normals - local_reflector.normals), initial=0.0)) <= GEOMETRY_TOLERANCE)


def safe_name(name: str) -> str:
    """``name`` as a folder name: letters, digits, ``_.-`` (others ``_``), 60 at most."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)[:60] or "reflector"


def grid_directory(cache_dir, reflector_name: str, key: str, shape: str) -> Path:
    return Path(cache_dir) / f"{safe_name(reflector_name)}-{key[:16]}-{shape[:8]}"


def grid_folders(cache_dir, reflector_name: str, key: str = "") -> list[Path]:
    """Cache folders of this reflector: of any key, or of ``key`` (any shape)."""
    root = Path(cache_dir)
    if not root.is_dir():
        return []
    stem = re.escape(safe_name(reflector_name)) + "-" + (re.escape(key[:16]) if key else "[0-9a-f]{16}")
    pattern = re.compile(stem + r"(-[0-9a-f]{8})?$")
    return sorted(p for p in root.iterdir() if p.is_dir() and pattern.match(p.name))


def _shape_of(directory: Path, local_reflector: Reflector, key: str) -> str | None:
    """The shape of the grid in ``directory`` where it is of ``key`` and of this
    reflector's current geometry (to :data:`GEOMETRY_TOLERANCE`), else None (also where
    its manifest cannot be read: :func:`load_grid` reports that when it is the only one)."""
    try:
        with np.load(directory / MANIFEST, allow_pickle=False) as manifest:
            shape = str(manifest["shape_key"])
            matches = str(manifest["key"]) == node_key(key, shape) and same_geometry(
                local_reflector, manifest["vertices"], manifest["normals"])
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None
    return shape if matches else None


def find_grid(cache_dir, local_reflector: Reflector, key: str) -> tuple[Path, str] | None:
    """The folder and shape of this reflector's grid of ``key`` baked for its current
    geometry, or None."""
    for directory in grid_folders(cache_dir, local_reflector.name, key):
        shape = _shape_of(directory, local_reflector, key)
        if shape is not None:
            return directory, shape
    return None


def adopt_grid(cache_dir, local_reflector: Reflector, key: str, names_in_use) -> Path | None:
    """A renamed mirror's grid: where this reflector has no grid of ``key`` for its
    shape, one baked under a name no object has now (``names_in_use``: every object's)
    for the same key and shape is moved to this reflector's name, so renaming a mirror
    (or undoing the rename) costs no bake. Returns the grid's new folder, or None. The
    manifest keeps the name it was baked under; nothing reads it."""
    root = Path(cache_dir)
    if not root.is_dir() or find_grid(cache_dir, local_reflector, key) is not None:
        return None
    in_use = {safe_name(name) for name in names_in_use}
    pattern = re.compile(r"(.+)-" + re.escape(key[:16]) + r"-[0-9a-f]{8}$")
    for directory in sorted(root.iterdir()):
        match = pattern.match(directory.name)
        if match is None or match.group(1) in in_use or not directory.is_dir():
            continue
        shape = _shape_of(directory, local_reflector, key)
        if shape is None:
            continue
        target = grid_directory(cache_dir, local_reflector.name, key, shape)
        try:
            os.rename(directory, target)  # atomic; refused where the target exists and is not empty
        except OSError:
            continue
        return target
    return None


def node_file(directory: Path, node: int) -> Path:
    return Path(directory) / f"node_{node:05d}.npz"


def inside_file(directory: Path, node: int) -> Path:
    return Path(directory) / f"node_{node:05d}{INSIDE_SUFFIX}"


def _atomic(path: Path, write) -> None:
    """``write(temporary path)``, then the temporary file renamed to ``path`` (atomic)."""
    path = Path(path)
    temporary = path.with_name(f".{path.name}.{os.getpid()}-{os.urandom(4).hex()}.tmp")
    try:
        write(temporary)
        os.replace(temporary, path)
    finally:
        if temporary.exists():
            temporary.unlink()


def remove_abandoned(directory: Path, older_than_s: float = ABANDONED_AFTER_S) -> int:
    """Remove the temporary files of writes that never finished (a worker killed while
    it wrote, a disk that filled up): ``.*.tmp`` files untouched for ``older_than_s``
    (other processes may be writing the recent ones). Returns how many."""
    removed = 0
    cutoff = time.time() - older_than_s
    for path in Path(directory).glob(".*.tmp"):
        try:
            if path.stat().st_mtime < cutoff:
                path.unlink()
                removed += 1
        except OSError:  # gone meanwhile, or not ours to remove
            continue
    return removed


def write_node(directory: Path, node: int, key: str, arrays: dict | None) -> None:
    """One node's file, atomically: its camera's arrays, or (``arrays`` None) the marker
    of a node inside the mirror. Both carry the grid's key."""
    if arrays is None:
        _atomic(inside_file(directory, node), lambda path: path.write_text(key, encoding="ascii"))
    else:
        def write(path):
            with open(path, "wb") as stream:
                np.savez_compressed(stream, key=np.array(key), **pack_arrays(arrays))

        _atomic(node_file(directory, node), write)


def node_is_baked(directory: Path, node: int, key: str) -> bool:
    """Whether ``node`` has a whole file of this key: the marker of a node inside the
    mirror, or a node file whose zip directory reads and whose key matches (the camera's
    arrays are not decompressed). A damaged or foreign file counts as not baked."""
    inside = inside_file(directory, node)
    if inside.is_file():
        try:
            return inside.read_text(encoding="ascii") == key
        except (OSError, UnicodeDecodeError):
            return False
    path = node_file(directory, node)
    if not path.is_file():
        return False
    try:
        with np.load(path, allow_pickle=False) as data:
            return str(data["key"]) == key
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return False


def baked_nodes(directory: Path, n_nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """(N,) bool: nodes with a file (camera or inside marker) and (N,) int8 status, from
    the folder's listing alone."""
    present, status = np.zeros(n_nodes, bool), np.zeros(n_nodes, np.int8)
    directory = Path(directory)
    if not directory.is_dir():
        return present, status
    pattern = re.compile(r"node_(\d{5})(\.npz|" + re.escape(INSIDE_SUFFIX) + r")$")
    for path in directory.iterdir():
        match = pattern.match(path.name)
        if match and int(match.group(1)) < n_nodes:
            node = int(match.group(1))
            present[node] = True
            if match.group(2) == INSIDE_SUFFIX:
                status[node] = NODE_INSIDE
    return present, status


def node_arrays(camera: NodeCamera) -> dict:
    """A node's six faces as arrays (faces that see nothing are absent)."""
    out = {"faces": np.array([f is not None for f in camera.faces]), "status": np.array(camera.status),
           "seconds": np.array(camera.seconds)}
    for k, sbc in enumerate(camera.faces):
        if sbc is not None:
            out.update(sbc_to_arrays(sbc, prefix=f"f{k}_"))
    return out


def node_from_arrays(data) -> NodeCamera:
    faces = [sbc_from_arrays(data, prefix=f"f{k}_", name=f"face{k}") if present else None
             for k, present in enumerate(data["faces"])]
    return NodeCamera(int(data["status"]), faces, float(data["seconds"]))


@dataclass(frozen=True)
class GridKind:
    """How one kind of grid (``MorphSettings.kind``) builds, stores and reads its nodes."""

    build: object  # (reflector_set, eye, bounds, settings) -> node
    to_arrays: object  # node -> dict of arrays
    from_arrays: object  # arrays -> node
    grid: type  # the grid class that blends them


GRID_KINDS = {TETRAHEDRAL: GridKind(build_node, node_arrays, node_from_arrays, MorphingGrid),
              OCTREE: GridKind(build_octree_node, octree_node_arrays, octree_node_from_arrays, OctreeGrid)}


def write_manifest(directory: Path, key: str, shape: str, local_reflector: Reflector, grid: TetrahedralGrid,
                   settings: MorphSettings) -> None:
    """The grid's manifest, atomically (the same bytes from every process baking one
    shape: ``shape`` hashes the geometry it stores)."""
    lo, hi = local_reflector.bounds
    reflector_name, reflector_size = local_reflector.name, float(np.max(hi - lo))

    def write(path):
        with open(path, "wb") as stream:
            np.savez(stream, key=np.array(node_key(key, shape)), shape_key=np.array(shape),
                     engine=np.array(ENGINE_VERSION),
                     vertices=local_reflector.vertices, normals=local_reflector.normals,
                     name=np.array(reflector_name), lo=grid.lo, hi=grid.hi, shape=np.array(grid.shape),
                     settings=np.array(repr(settings.as_tuple())), margin=np.array(settings.margin),
                     face_resolution=np.array(settings.face_resolution), downsample=np.array(settings.downsample),
                     accuracy_px=np.array(settings.accuracy_px), overlap_cells=np.array(settings.overlap_cells),
                     extension=np.array(settings.extension), kind=np.array(settings.kind),
                     octree_depth=np.array(settings.octree_depth), reflector_size=np.array(reflector_size))

    _atomic(Path(directory) / MANIFEST, write)


def _read(path: Path, object_name: str):
    """All arrays of an .npz, or a CacheError saying the file is unreadable."""
    try:
        with np.load(path, allow_pickle=False) as data:
            return {k: data[k] for k in data.files}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as error:
        raise CacheError(object_name, "corrupt", f"the morphing cache file {path.name} is unreadable "
                         f"({type(error).__name__}: {error}); clear it and bake again") from None


def read_node_arrays(path: Path, object_name: str = "") -> dict:
    """A node file's arrays as :func:`write_node` was given them, with its ``key``; a
    CacheError where the file is unreadable, KeyError or ValueError where its packed
    arrays are malformed."""
    data = _read(path, object_name)
    return {"key": data["key"], **unpack_arrays(data)}


class _LazyNodes:
    """Node cameras read from their files on first use; the last few kept. A file that
    cannot be read, or that belongs to another grid, is renamed ``*.damaged`` (the next
    bake builds the node again) and raises :class:`CacheError` naming it."""

    def __init__(self, directory: Path, object_name: str, key: str, from_arrays=node_from_arrays):
        self.directory, self.object_name, self.key = directory, object_name, key
        self.from_arrays = from_arrays
        self._cache: OrderedDict = OrderedDict()
        # A thread prefetching node images and the main thread read nodes at once.
        self._lock = threading.Lock()

    def __getitem__(self, node: int) -> NodeCamera:
        node = int(node)
        with self._lock:
            if node in self._cache:
                self._cache.move_to_end(node)
                return self._cache[node]
        path = node_file(self.directory, node)
        try:
            data = read_node_arrays(path, self.object_name)
            if str(data.get("key", "")) != self.key:
                raise CacheError(self.object_name, "corrupt", f"the morphing cache file {path.name} belongs to "
                                 "another grid")
            camera = self.from_arrays(data)
        except (KeyError, ValueError, IndexError, CacheError) as error:
            if path.is_file():
                os.replace(path, path.with_name(path.name + DAMAGED_SUFFIX))
            problem = error.problem if isinstance(error, CacheError) else (
                f"the morphing cache file {path.name} is incomplete ({type(error).__name__}: {error})")
            raise CacheError(self.object_name, "corrupt", f"{problem} (in {self.directory}); runtime mode until "
                             "Bake Morphing Grid builds the node again") from None
        with self._lock:
            self._cache[node] = camera
            while len(self._cache) > NODES_IN_MEMORY:
                self._cache.popitem(last=False)
        return camera


def load_grid(cache_dir, local_reflector: Reflector, key: str, reflector_index: int = 0,
              polish: bool = False) -> MorphingGrid:
    """The baked grid of this reflector (in its rigid frame) for this key; CacheError
    (missing / stale / corrupt) else. ``polish``: its nodes' grazing and extended images
    are polished on the mirror (``MorphingGrid.mirror``)."""
    reflector_name = local_reflector.name
    found = find_grid(cache_dir, local_reflector, key)
    if found is None:
        for directory in grid_folders(cache_dir, reflector_name, key):
            if (directory / MANIFEST).is_file():
                _read(directory / MANIFEST, reflector_name)  # an unreadable manifest is said as such
        if grid_folders(cache_dir, reflector_name):
            raise CacheError(reflector_name, "stale", "the morphing cache was baked for other geometry or "
                             "settings; bake again (runtime mode until then)")
        raise CacheError(reflector_name, "missing", "no morphing cache yet; bake it (runtime mode until then)")
    directory, shape = found
    manifest = _read(directory / MANIFEST, reflector_name)
    try:
        shape_of_grid = tuple(int(n) for n in manifest["shape"])
        settings = MorphSettings(grid=shape_of_grid, margin=float(manifest["margin"]),
                                 face_resolution=int(manifest["face_resolution"]),
                                 downsample=int(manifest["downsample"]), accuracy_px=float(manifest["accuracy_px"]),
                                 overlap_cells=int(manifest["overlap_cells"]), extension=float(manifest["extension"]),
                                 kind=str(manifest["kind"]), octree_depth=int(manifest["octree_depth"]))
        grid = TetrahedralGrid(np.asarray(manifest["lo"], float), np.asarray(manifest["hi"], float), shape_of_grid)
        size = float(manifest["reflector_size"])
    except (KeyError, ValueError, TypeError, SceneInputError) as error:
        raise CacheError(reflector_name, "corrupt", f"the morphing cache manifest is incomplete ({error}); "
                         "clear it and bake again") from None
    if str(manifest.get("engine", "")) != ENGINE_VERSION:
        raise CacheError(reflector_name, "stale", "the morphing cache was baked for other geometry or settings; "
                         "bake again (runtime mode until then)")
    present, status = baked_nodes(directory, grid.n_nodes)
    if not present.all():
        raise CacheError(reflector_name, "incomplete", f"the morphing cache has {int(present.sum())} of "
                         f"{grid.n_nodes} nodes (first missing: node {int(np.argmin(present))}); bake again to "
                         "finish it (runtime mode until then)")
    kind = GRID_KINDS[settings.kind]
    return kind.grid(reflector_name, reflector_index, grid, settings, status,
                     _LazyNodes(directory, reflector_name, node_key(key, shape), kind.from_arrays), size,
                     mirror=MirrorOnDemand(local_reflector, settings) if polish else None)


def cache_state(cache_dir, local_reflector: Reflector, key: str) -> str:
    """'ready', 'stale', 'incomplete' or 'missing' from the manifest and the folder's
    listing (no node file is read)."""
    try:
        load_grid(cache_dir, local_reflector, key)
    except CacheError as error:
        return error.reason
    return "ready"


def clear_cache(cache_dir, reflector_name: str | None = None) -> int:
    """Remove the baked grids of one reflector (all reflectors if None); returns folders removed."""
    root = Path(cache_dir)
    if not root.is_dir():
        return 0
    if reflector_name is None:
        folders = [p for p in root.iterdir() if p.is_dir()]
    else:
        folders = grid_folders(cache_dir, reflector_name) + [
            p for p in root.iterdir() if p.is_dir() and p.name.startswith(safe_name(reflector_name) + "-")
            and ".partial-" in p.name]
    for folder in folders:
        shutil.rmtree(folder, ignore_errors=True)
    return len(folders)


def remove_stale(cache_dir, reflector_name: str, final: Path) -> int:
    """Remove this reflector's grids but ``final`` (a finished bake replaced them: other
    keys or shapes)."""
    stale = [old for old in grid_folders(cache_dir, reflector_name) if old != final]
    for old in stale:
        shutil.rmtree(old, ignore_errors=True)
    return len(stale)
