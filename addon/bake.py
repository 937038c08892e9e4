# SPDX-License-Identifier: GPL-3.0-or-later
"""Baking a morphing grid on every core, with progress and cancellation.

SBC paper VI builds the grid's SBCs as a preprocess. Each node's panoramic camera is
independent numpy work, which threads would serialise on the GIL between numpy calls,
so nodes are built in worker *processes* (``multiprocessing``, ``fork`` context). Each
worker writes the node it built to the partial cache folder itself (compression happens
on every core, and no camera is pickled to the parent); the parent reports progress
after each node and checks the cancel flag between nodes: a cancelled (or failed) bake
stops the workers and removes its partial folder, so the previous cache stays exactly
as it was.

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
import shutil
import sys
import time
from dataclasses import dataclass

import numpy as np

from . import bake_cache
from .morphing import NODE_OK, MorphSettings, bake_reflector, build_node, reflector_in_frame, rigid_frame
from .scene import Reflector

try:
    import resource  # Unix only: peak memory is reported as NaN elsewhere
except ImportError:  # pragma: no cover - Windows
    resource = None

#: Work shared with forked workers (set before the pool starts, inherited by fork).
_WORK: dict = {}


@dataclass(frozen=True)
class BakeResult:
    """What a bake did; ``directory`` is None when it was cancelled."""

    cancelled: bool
    key: str
    directory: object
    n_nodes: int
    n_built: int
    seconds: float
    node_seconds: np.ndarray  # (N,) worker wall time per node (0 for nodes not built)
    node_cpu_seconds: np.ndarray  # (N,) worker CPU time per node
    nbytes: int  # bytes of the built cameras (arrays), all nodes
    processes: int
    peak_rss_mb: float  # largest resident set of the parent or of any worker


def default_processes() -> int:
    return max(1, multiprocessing.cpu_count())


def _bake_node(node: int):
    """Worker: build one node and write its cache file; only its status and sizes cross the pipe.

    Writing in the worker keeps the parent idle: compressing every node's arrays in the
    parent (and pickling them to it) took a core's worth of time away from the workers.
    """
    work = _WORK
    camera = build_node(work["reflector_set"], work["positions"][node], work["bounds"], work["settings"])
    if camera.status == NODE_OK:
        bake_cache.write_node(work["partial"], node, bake_cache.node_arrays(camera))
    return node, camera.status, (camera.seconds, camera.cpu_seconds), camera.nbytes


def _peak_rss_mb() -> float:
    if resource is None:
        return math.nan
    scale = 1.0 if sys.platform == "darwin" else 1024.0  # ru_maxrss: bytes on macOS, KiB on Linux
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * scale
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * scale
    return max(own, children) / 2**20


def bake_grid(reflector: Reflector, matrix, settings: MorphSettings, cache_dir, processes: int | None = None,
              progress=None, cancel=None, reflector_index: int = 0) -> BakeResult:
    """Bake the morphing grid of one world-space reflector whose object matrix is ``matrix``.

    ``progress(done, total)`` is called after every node; ``cancel`` is anything with
    ``is_set()`` (a ``threading.Event``), checked between nodes. ``processes`` defaults
    to every core; 1 builds in this process.
    """
    start = time.perf_counter()
    frame = rigid_frame(matrix)
    local = reflector_in_frame(reflector, frame)
    key = bake_cache.cache_key(local, settings)
    reflector_set, grid, bounds = bake_reflector(local, settings)
    positions = grid.node_positions()
    total = grid.n_nodes
    processes = default_processes() if processes is None else max(1, int(processes))
    if "fork" not in multiprocessing.get_all_start_methods():
        processes = 1
    partial = bake_cache.partial_directory(cache_dir, reflector.name, key)
    status = np.zeros(total, dtype=np.int8)
    node_seconds, node_cpu = np.zeros(total), np.zeros(total)
    nbytes, done, cancelled = 0, 0, False
    _WORK.update(reflector_set=reflector_set, positions=positions, bounds=bounds, settings=settings, partial=partial)
    try:
        if processes == 1:
            results = map(_bake_node, range(total))
            pool = None
        else:
            pool = multiprocessing.get_context("fork").Pool(processes)
            results = pool.imap_unordered(_bake_node, range(total), chunksize=1)
        try:
            for node, node_status, seconds, size in results:
                status[node], (node_seconds[node], node_cpu[node]) = node_status, seconds
                nbytes += size
                done += 1
                if progress is not None:
                    progress(done, total)
                if cancel is not None and cancel.is_set() and done < total:
                    cancelled = True
                    break
        finally:
            if pool is not None:
                pool.terminate()
                pool.join()
        if cancelled:
            shutil.rmtree(partial, ignore_errors=True)
            return BakeResult(True, key, None, total, done, time.perf_counter() - start, node_seconds, node_cpu, nbytes,
                              processes, _peak_rss_mb())
        bake_cache.write_manifest(partial, key, local, grid, settings, status, node_seconds)
        directory = bake_cache.commit_directory(partial, cache_dir, reflector.name, key)
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        raise
    finally:
        _WORK.clear()
    return BakeResult(False, key, directory, total, done, time.perf_counter() - start, node_seconds, node_cpu, nbytes,
                      processes, _peak_rss_mb())


def load_for(reflector: Reflector, matrix, settings: MorphSettings, cache_dir, reflector_index: int = 0):
    """The baked grid matching this reflector's current geometry and settings (CacheError else)."""
    local = reflector_in_frame(reflector, rigid_frame(matrix))
    return bake_cache.load_grid(cache_dir, local, bake_cache.cache_key(local, settings), reflector_index)
