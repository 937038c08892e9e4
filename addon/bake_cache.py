# SPDX-License-Identifier: GPL-3.0-or-later
"""The on-disk cache of baked morphing grids (SBC paper VI: the grid is a preprocess).

Layout under the cache directory (the Blender layer passes
``bpy.utils.extension_path_user(__package__, path="morphing", create=True)``)::

    <reflector name>-<key[:16]>/grid.npz          manifest: key, box, node status, settings
    <reflector name>-<key[:16]>/node_00012.npz    one panoramic camera (six faces' SBC arrays)

Every file is plain arrays (``np.savez``; node files compressed) and is read with
``allow_pickle=False``. The folder's key is a SHA-256 of the reflector's topology, the
grid settings and the engine (its version and the bytes of the modules a bake runs);
the manifest also holds the geometry in the reflector's rigid frame, compared with the
current one to 1e-6 of its size at load. So a rigidly moved reflector keeps its cache,
any change of shape, scale or settings makes it stale, and a cache baked for other
geometry or settings is never loaded. Missing, stale and corrupt caches raise
:class:`CacheError` with a message for the user, never a traceback.

Nodes are read lazily (the four of the current tetrahedron, a few kept), as the paper
keeps only two layers of its grid in memory.
"""

from __future__ import annotations

import functools
import hashlib
import os
import re
import shutil
import zipfile
from collections import OrderedDict
from pathlib import Path

import numpy as np

from .errors import SceneInputError
from .morphing import ENGINE_VERSION, NODE_OK, MorphingGrid, MorphSettings, NodeCamera, TetrahedralGrid
from .scene import Reflector
from .sbc_arrays import sbc_from_arrays, sbc_to_arrays

MANIFEST = "grid.npz"
#: Nodes kept in memory by a loaded grid (a tetrahedron needs four; neighbours come next).
NODES_IN_MEMORY = 16
#: Largest difference (in reflector sizes; unit normals: absolute) between the baked and
#: the current geometry in the rigid frame for a cache to be used.
GEOMETRY_TOLERANCE = 1e-6


class CacheError(SceneInputError):
    """A morphing cache that cannot be used; ``reason`` is 'missing', 'stale' or 'corrupt'."""

    def __init__(self, object_name: str, reason: str, problem: str):
        self.reason = reason
        super().__init__(object_name, problem)


@functools.lru_cache(maxsize=1)
def engine_fingerprint() -> str:
    """SHA-256 of every engine module (``addon/*.py``): a cache baked by other engine code is
    stale. Conservative: a change anywhere in the engine asks for a new bake."""
    digest = hashlib.sha256()
    for path in sorted(Path(__file__).resolve().parent.glob("*.py")):
        digest.update(path.name.encode() + b"\0" + path.read_bytes())
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


def same_geometry(local_reflector: Reflector, vertices: np.ndarray, normals: np.ndarray) -> bool:
    """The stored geometry (in the rigid frame) matches this reflector's to the tolerance."""
    lo, hi = local_reflector.bounds
    size = max(float(np.max(hi - lo)), 1e-12)
    return (vertices.shape == local_reflector.vertices.shape and normals.shape == local_reflector.normals.shape
            and float(np.max(np.abs(vertices - local_reflector.vertices), initial=0.0)) <= GEOMETRY_TOLERANCE * size
            and float(np.max(np.abs(normals - local_reflector.normals), initial=0.0)) <= GEOMETRY_TOLERANCE)


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)[:60] or "reflector"


def grid_directory(cache_dir, reflector_name: str, key: str) -> Path:
    return Path(cache_dir) / f"{_safe(reflector_name)}-{key[:16]}"


def _siblings(cache_dir, reflector_name: str) -> list[Path]:
    """Finished cache folders of this reflector (any key)."""
    root = Path(cache_dir)
    if not root.is_dir():
        return []
    pattern = re.compile(re.escape(_safe(reflector_name)) + r"-[0-9a-f]{16}$")
    return [p for p in root.iterdir() if p.is_dir() and pattern.match(p.name)]


def node_file(directory: Path, node: int) -> Path:
    return Path(directory) / f"node_{node:05d}.npz"


def write_node(directory: Path, node: int, arrays: dict) -> None:
    np.savez_compressed(node_file(directory, node), **arrays)


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


def write_manifest(directory: Path, key: str, local_reflector: Reflector, grid: TetrahedralGrid,
                   settings: MorphSettings, node_status: np.ndarray, node_seconds: np.ndarray) -> None:
    lo, hi = local_reflector.bounds
    reflector_name, reflector_size = local_reflector.name, float(np.max(hi - lo))
    np.savez(Path(directory) / MANIFEST, key=np.array(key), engine=np.array(ENGINE_VERSION),
             vertices=local_reflector.vertices, normals=local_reflector.normals,
             name=np.array(reflector_name), lo=grid.lo, hi=grid.hi, shape=np.array(grid.shape),
             settings=np.array(repr(settings.as_tuple())), margin=np.array(settings.margin),
             face_resolution=np.array(settings.face_resolution), downsample=np.array(settings.downsample),
             accuracy_px=np.array(settings.accuracy_px), overlap_cells=np.array(settings.overlap_cells),
             extension=np.array(settings.extension), node_status=node_status,
             reflector_size=np.array(reflector_size), node_seconds=node_seconds)


def _read(path: Path, object_name: str):
    """All arrays of an .npz, or a CacheError saying the file is unreadable."""
    try:
        with np.load(path, allow_pickle=False) as data:
            return {k: data[k] for k in data.files}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as error:
        raise CacheError(object_name, "corrupt", f"the morphing cache file {path.name} is unreadable "
                         f"({type(error).__name__}: {error}); clear it and bake again") from None


class _LazyNodes:
    """Node cameras read from their files on first use; the last few kept."""

    def __init__(self, directory: Path, object_name: str):
        self.directory, self.object_name = directory, object_name
        self._cache: OrderedDict = OrderedDict()

    def __getitem__(self, node: int) -> NodeCamera:
        node = int(node)
        if node in self._cache:
            self._cache.move_to_end(node)
            return self._cache[node]
        data = _read(node_file(self.directory, node), self.object_name)
        try:
            camera = node_from_arrays(data)
        except (KeyError, ValueError, IndexError) as error:
            raise CacheError(self.object_name, "corrupt", f"the morphing cache file of node {node} is incomplete "
                             f"({type(error).__name__}: {error}); clear it and bake again") from None
        self._cache[node] = camera
        while len(self._cache) > NODES_IN_MEMORY:
            self._cache.popitem(last=False)
        return camera


def load_grid(cache_dir, local_reflector: Reflector, key: str, reflector_index: int = 0) -> MorphingGrid:
    """The baked grid of this reflector (in its rigid frame) for this key; CacheError
    (missing / stale / corrupt) else."""
    reflector_name = local_reflector.name
    directory = grid_directory(cache_dir, reflector_name, key)
    if not (directory / MANIFEST).is_file():
        if _siblings(cache_dir, reflector_name):
            raise CacheError(reflector_name, "stale", "the morphing cache was baked for other geometry or "
                             "settings; bake again (runtime mode until then)")
        raise CacheError(reflector_name, "missing", "no morphing cache yet; bake it (runtime mode until then)")
    manifest = _read(directory / MANIFEST, reflector_name)
    try:
        stored_key = str(manifest["key"])
        shape = tuple(int(n) for n in manifest["shape"])
        settings = MorphSettings(grid=shape, margin=float(manifest["margin"]),
                                 face_resolution=int(manifest["face_resolution"]),
                                 downsample=int(manifest["downsample"]), accuracy_px=float(manifest["accuracy_px"]),
                                 overlap_cells=int(manifest["overlap_cells"]), extension=float(manifest["extension"]))
        grid = TetrahedralGrid(np.asarray(manifest["lo"], float), np.asarray(manifest["hi"], float), shape)
        status = np.asarray(manifest["node_status"], dtype=np.int8)
        size = float(manifest["reflector_size"])
        geometry = same_geometry(local_reflector, np.asarray(manifest["vertices"], float),
                                 np.asarray(manifest["normals"], float))
    except (KeyError, ValueError, TypeError, SceneInputError) as error:
        raise CacheError(reflector_name, "corrupt", f"the morphing cache manifest is incomplete ({error}); "
                         "clear it and bake again") from None
    if stored_key != key or str(manifest.get("engine", "")) != ENGINE_VERSION or not geometry:
        raise CacheError(reflector_name, "stale", "the morphing cache was baked for other geometry or settings; "
                         "bake again (runtime mode until then)")
    if status.shape != (grid.n_nodes,):
        raise CacheError(reflector_name, "corrupt", "the morphing cache manifest has the wrong number of nodes; "
                         "clear it and bake again")
    absent = [n for n in np.flatnonzero(status == NODE_OK) if not node_file(directory, int(n)).is_file()]
    if absent:
        raise CacheError(reflector_name, "corrupt", f"the morphing cache lacks {len(absent)} node files "
                         f"(first: node {absent[0]}); clear it and bake again")
    return MorphingGrid(reflector_name, reflector_index, grid, settings, status,
                        _LazyNodes(directory, reflector_name), size)


def cache_state(cache_dir, local_reflector: Reflector, key: str) -> str:
    """'ready', 'stale' or 'missing' from the manifest alone (no node file is read)."""
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
        folders = _siblings(cache_dir, reflector_name) + [
            p for p in root.iterdir() if p.is_dir() and p.name.startswith(_safe(reflector_name) + "-")
            and ".partial-" in p.name]
    for folder in folders:
        shutil.rmtree(folder, ignore_errors=True)
    return len(folders)


def partial_directory(cache_dir, reflector_name: str, key: str) -> Path:
    """A fresh folder a bake writes into before it replaces the finished one."""
    final = grid_directory(cache_dir, reflector_name, key)
    partial = final.with_name(f"{final.name}.partial-{os.getpid()}-{os.urandom(4).hex()}")
    partial.mkdir(parents=True)
    return partial


def commit_directory(partial: Path, cache_dir, reflector_name: str, key: str) -> Path:
    """Swap the finished bake in and remove this reflector's stale grids."""
    final = grid_directory(cache_dir, reflector_name, key)
    for old in _siblings(cache_dir, reflector_name):
        if old != final:
            shutil.rmtree(old, ignore_errors=True)
    if final.exists():
        retired = final.with_name(f"{final.name}.partial-old-{os.urandom(4).hex()}")
        os.replace(final, retired)
        os.replace(partial, final)
        shutil.rmtree(retired, ignore_errors=True)
    else:
        os.replace(partial, final)
    return final
