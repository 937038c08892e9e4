# SPDX-License-Identifier: GPL-3.0-or-later
"""Baking a morphing grid on every core, in ranges a render farm can split, with
progress and cancellation.

SBC paper VI builds the grid's SBCs as a preprocess. Each node's panoramic camera is
independent numpy work, which threads would serialise on the GIL between numpy calls,
so nodes are built in worker *processes* (``multiprocessing``, ``fork`` context). Each
worker writes the node it built into the grid's cache folder itself, atomically
(compression happens on every core, and no camera is pickled to the parent); the parent
reports progress after each node and checks the cancel flag between nodes. Workers run
numpy's BLAS on one thread each (``blas_threads``): the cores are the workers'.

A bake may be given a range of nodes (``nodes``): several processes, on one machine or
on many sharing the cache folder (a render farm's array job), then bake one grid
together. A node whose file is already there (whole, and of this grid's key) is not
baked again, so a bake that was cancelled, or whose machine died, resumes where it
stopped, and a damaged node file is replaced. The result does not depend on how the
nodes were split: a node's camera depends on its position alone. When a bake finds
every node of the grid present, it removes the reflector's grids of other keys.

Inside Blender the extension is the package ``bl_ext.<repo>.curved_reflections``. A
forked worker inherits the parent's modules, so the worker function (this module's
``_bake_node``) resolves by that name without re-importing anything. A ``spawn`` worker
would start a fresh interpreter (Blender's own binary, as ``sys.executable``) that must
import ``bl_ext.<repo>...`` before it can unpickle the function: it cannot, since the
extension repositories are set up by Blender's startup, not by Python's import path. So
where ``fork`` is not offered (Windows) the bake runs in the calling process, one node
after another, with the same progress and cancellation.
"""

from __future__ import annotations

import math
import multiprocessing
import sys
import time
from dataclasses import dataclass

import numpy as np

from . import bake_cache
from .blas_threads import limit_blas_threads
from ..methods.morphing.morph_grid import NODE_OK, MorphSettings, bake_reflector, reflector_in_frame, rigid_frame
from ..scene import Reflector

try:
    import resource  # Unix only: peak memory is reported as NaN elsewhere
except ImportError:  # pragma: no cover - Windows
    resource = None

#: Work shared with forked workers (set before the pool starts, inherited by fork).
_WORK: dict = {}


@dataclass(frozen=True)
class BakeResult:
    """What a bake did; ``directory`` is the grid's folder once every node is baked
    (by this bake or others), else None (cancelled, or other ranges still to bake)."""

    cancelled: bool
    key: str  # the grid's key (topology, settings, engine: ``bake_cache.cache_key``)
    shape: str  # the shape it was baked for (``bake_cache.shape_key`` of its first bake)
    directory: object
    n_nodes: int  # nodes of the grid
    n_built: int  # nodes this bake built
    n_skipped: int  # nodes of its range already baked
    n_baked: int  # nodes of the grid in its folder after this bake (all of them once ``directory`` is set)
    seconds: float
    node_seconds: np.ndarray  # (N,) worker wall time per node (0 for nodes not built)
    node_cpu_seconds: np.ndarray  # (N,) worker CPU time per node
    nbytes: int  # bytes of the built cameras (arrays), all nodes
    processes: int
    peak_rss_mb: float  # largest resident set of the parent or of any worker
    replaced: bool  # a grid of this reflector was baked before, for another shape or other settings


def default_processes() -> int:
    return max(1, multiprocessing.cpu_count())


def _bake_node(node: int):
    """Worker: build one node and write its cache file; only its status and sizes cross the pipe.

    Writing in the worker keeps the parent idle: compressing every node's arrays in the
    parent (and pickling them to it) would take a core's worth of time away from the workers.
    """
    work = _WORK
    kind = bake_cache.GRID_KINDS[work["settings"].kind]
    camera = kind.build(work["reflector_set"], work["positions"][node], work["bounds"], work["settings"])
    arrays = kind.to_arrays(camera) if camera.status == NODE_OK else None
    bake_cache.write_node(work["directory"], node, work["node_key"], arrays)
    return node, (camera.seconds, camera.cpu_seconds), camera.nbytes


def _peak_rss_mb() -> float:
    if resource is None:
        return math.nan
    scale = 1.0 if sys.platform == "darwin" else 1024.0  # ru_maxrss: bytes on macOS, KiB on Linux
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * scale
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * scale
    return max(own, children) / 2**20


def parse_node_range(text: str, n_nodes: int) -> range:
    """``"first-last"`` (inclusive), ``"first-"``, ``"node"`` or ``""`` (every node) as a
    range of the grid's ``n_nodes`` nodes; a clear ValueError otherwise."""
    text = text.strip()
    if not text:
        return range(n_nodes)
    first, dash, last = text.partition("-")
    try:
        start = int(first)
        stop = (int(last) + 1 if last.strip() else n_nodes) if dash else start + 1
    except ValueError:
        raise ValueError(f"node range {text!r}: write first-last (e.g. 0-99), first- or one node") from None
    if not 0 <= start < stop <= n_nodes:
        raise ValueError(f"node range {text!r}: the grid has nodes 0 to {n_nodes - 1}")
    return range(start, stop)


def bake_grid(reflector: Reflector, matrix, settings: MorphSettings, cache_dir, processes: int | None = None,
              progress=None, cancel=None, reflector_index: int = 0, nodes: range | None = None) -> BakeResult:
    """Bake the morphing grid of one world-space reflector whose object matrix is ``matrix``:
    the nodes of ``nodes`` (default: all) that are not baked yet.

    ``progress(done, total)`` is called after every node of the range (already baked
    ones count at once); ``cancel`` is anything with ``is_set()`` (a
    ``threading.Event``), checked between nodes: the nodes built so far stay, and the
    next bake goes on from there. ``processes`` defaults to every core; 1 builds in this
    process.
    """
    start = time.perf_counter()
    frame = rigid_frame(matrix)
    local = reflector_in_frame(reflector, frame)
    key = bake_cache.cache_key(local, settings)
    reflector_set, grid, bounds = bake_reflector(local, settings)
    positions = grid.node_positions()
    total = grid.n_nodes
    nodes = range(total) if nodes is None else nodes
    found = bake_cache.find_grid(cache_dir, local, key)
    replaced = found is None and bool(bake_cache.grid_folders(cache_dir, reflector.name))
    directory, shape = found or (None, bake_cache.shape_key(local))
    directory = directory or bake_cache.grid_directory(cache_dir, reflector.name, key, shape)
    node_key = bake_cache.node_key(key, shape)
    directory.mkdir(parents=True, exist_ok=True)
    bake_cache.remove_abandoned(directory)
    if found is None:
        bake_cache.write_manifest(directory, key, shape, local, grid, settings)
    todo = [n for n in nodes if not bake_cache.node_is_baked(directory, n, node_key)]
    # Nearest the reflector first: there it fills most of the cube faces and a node costs
    # the most, and a worker left alone with one of those at the end would keep the bake waiting.
    centre, _ = reflector_set.bounding_sphere
    todo.sort(key=lambda n: float(np.linalg.norm(positions[n] - centre)))
    skipped = len(nodes) - len(todo)
    processes = default_processes() if processes is None else max(1, int(processes))
    if "fork" not in multiprocessing.get_all_start_methods():
        processes = 1
    node_seconds, node_cpu = np.zeros(total), np.zeros(total)
    nbytes, done, cancelled = 0, skipped, False
    if progress is not None and skipped:
        progress(done, len(nodes))
    _WORK.update(reflector_set=reflector_set, positions=positions, bounds=bounds, settings=settings,
                 directory=directory, node_key=node_key)
    try:
        if processes == 1 or len(todo) <= 1:
            results = map(_bake_node, todo)
            pool = None
        else:
            pool = multiprocessing.get_context("fork").Pool(min(processes, len(todo)), initializer=limit_blas_threads)
            results = pool.imap_unordered(_bake_node, todo, chunksize=1)
        try:
            for node, seconds, size in results:
                node_seconds[node], node_cpu[node] = seconds
                nbytes += size
                done += 1
                if progress is not None:
                    progress(done, len(nodes))
                if cancel is not None and cancel.is_set() and done < len(nodes):
                    cancelled = True
                    break
        finally:
            if pool is not None:
                pool.terminate()
                pool.join()
    finally:
        _WORK.clear()
    baked = int(bake_cache.baked_nodes(directory, total)[0].sum())
    complete = not cancelled and baked == total
    if complete:
        bake_cache.remove_stale(cache_dir, reflector.name, directory)
    return BakeResult(cancelled, key, shape, directory if complete else None, total, done - skipped, skipped, baked,
                      time.perf_counter() - start, node_seconds, node_cpu, nbytes, processes, _peak_rss_mb(),
                      replaced)


def load_for(reflector: Reflector, matrix, settings: MorphSettings, cache_dir, reflector_index: int = 0,
             polish: bool = False):
    """The baked grid matching this reflector's current geometry and settings (CacheError
    else); ``polish``: its nodes' grazing and extended images are polished on the mirror."""
    local = reflector_in_frame(reflector, rigid_frame(matrix))
    return bake_cache.load_grid(cache_dir, local, bake_cache.cache_key(local, settings), reflector_index, polish)


def adopt_renamed(reflector: Reflector, matrix, settings: MorphSettings, cache_dir, names_in_use):
    """``bake_cache.adopt_grid`` for a world-space reflector: the grid of a mirror that
    was renamed, moved to its new name (None where there is none to adopt)."""
    local = reflector_in_frame(reflector, rigid_frame(matrix))
    return bake_cache.adopt_grid(cache_dir, local, bake_cache.cache_key(local, settings), names_in_use)
