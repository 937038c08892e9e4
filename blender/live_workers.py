# SPDX-License-Identifier: GPL-3.0-or-later
"""The live view's background threads (``live.py``): one builds the sample-based cameras
of changed views and their reflected triangles (and makes big reflectors ready for ray
tracing), one traces the pixels a landed camera cannot place, one prefetches morphing
nodes around the eye. All are bpy-free numpy work, and all run nicer than Blender, so
that the drawing they share the cores with keeps its pace.
"""

from __future__ import annotations

import collections
import os
import sys
import threading
from concurrent.futures import ThreadPoolExecutor

from ..engine.geometry.raytrace import ReflectorSet
from ..drawing.methods.camera_source import CameraSource
from .frame_pipeline import CameraJob

#: How much nicer than Blender the threads that build cameras and prefetch morphing
#: nodes run (Linux, where the nice value is per thread): they yield the cores to the
#: drawing, which on a software GL driver runs on the same cores, instead of sharing
#: them equally (a redraw during a build: 2.6x -> 2.2x a plain draw on 2 cores).
BACKGROUND_NICENESS = 10

#: The running threads by name (each made on first use).
_executors: dict = {}
#: What finished jobs were called with (their function, closures and arguments), kept
#: for the main thread to let go of (:func:`release_finished`).
_finished: collections.deque = collections.deque()
_finished_lock = threading.Lock()


class _Job:
    """A submitted call that, once run, hands its function and arguments to
    :data:`_finished` instead of dropping them on the worker thread.

    A job's closure or arguments may hold the last reference to GPU objects (a replaced
    renderer's frame targets and batches, a grid's textures): freed on a worker, which
    has no GPU context, Blender only queues their GL names as orphans, and nothing in the
    live view activates a context that deletes them, so each one's storage stayed in
    Mesa for the rest of the session (the soak's growth, docs/benchmarks/soak.md)."""

    __slots__ = ("call",)

    def __init__(self, fn, args, kwargs):
        self.call = (fn, args, kwargs)

    def __call__(self):
        call, self.call = self.call, None
        fn, args, kwargs = call
        try:
            return fn(*args, **kwargs)
        finally:
            fn = args = kwargs = None
            with _finished_lock:  # this thread lets go while the queue still holds them
                _finished.append(call)
                call = None


class _Executor(ThreadPoolExecutor):
    """A thread pool whose jobs' callables and arguments die on the main thread: the
    live view submits from there only, and each submission first lets go of what the
    finished jobs were called with (:func:`release_finished`)."""

    def submit(self, fn, /, *args, **kwargs):
        release_finished()
        job = _Job(fn, args, kwargs)
        future = super().submit(job)
        # Cancelled (on the main thread, which runs this then), it is never run: let go here.
        future.add_done_callback(lambda done: setattr(job, "call", None) if done.cancelled() else None)
        return future


def release_finished() -> None:
    """Drop what finished jobs were called with, on the calling (main) thread: the GPU
    objects only they still held are freed with a GPU context (see :class:`_Job`)."""
    with _finished_lock:
        released = list(_finished)
        _finished.clear()
    del released  # here, outside the lock


def build_camera(job: CameraJob, maker):
    """The view's ray map and BSP trees (``frame_pipeline.CameraJob``), then the
    reflected triangles of the renderer's meshes (``maker``, a
    ``CameraTriangleMaker``) projected with numpy (``camera_source.CameraSource``): the
    camera's landing then costs the main thread no projection pass, only the upload
    (``CameraPass.adopt``). Returns both."""
    sbc = job.build()
    return sbc, maker.triangles(CameraSource(sbc), sbc.ray_map.view, sbc, job.first_order_left_out)


def prepare_reflectors(reflectors, meshes):
    """The reflectors ready for ray tracing: their BVH (``ReflectorSet``), sealed against
    the diffuse ``meshes`` (``seal_empty_interiors``). Seconds for a million triangles:
    the live view runs it here for big reflectors (``live.BACKGROUND_TRIANGLES``)."""
    reflector_set = ReflectorSet(list(reflectors))
    reflector_set.seal_empty_interiors(meshes)
    return reflector_set


def _lower_priority() -> None:
    """A background thread's initializer: :data:`BACKGROUND_NICENESS` nicer, for this
    thread and the threads it starts (Linux only: elsewhere it would be the process's)."""
    if sys.platform.startswith("linux"):
        thread = threading.get_native_id()
        try:
            os.setpriority(os.PRIO_PROCESS, thread, min(19, os.getpriority(os.PRIO_PROCESS, thread)
                                                        + BACKGROUND_NICENESS))
        except OSError:
            pass  # a sandbox that forbids it: the thread runs at Blender's priority


def _executor(name: str) -> ThreadPoolExecutor:
    if name not in _executors:
        _executors[name] = _Executor(1, name, initializer=_lower_priority)
    return _executors[name]


def builder() -> ThreadPoolExecutor:
    """The camera builder's thread (made on first use)."""
    return _executor("curved_reflections")


def prefetcher() -> ThreadPoolExecutor:
    """The thread that projects morphing nodes around the eye ahead of time (numpy, no
    GPU; made on first use)."""
    return _executor("curved_reflections_prefetch")


def tracer() -> ThreadPoolExecutor:
    """The thread that ray traces the pixels of a landed camera's unreliable cells
    (``traced_pixels.trace_doubtful``; made on first use): beside the camera builder, so
    that a view change's next camera never queues behind it."""
    return _executor("curved_reflections_trace")


def running() -> bool:
    """Whether any of the threads exists."""
    return bool(_executors)


def shutdown() -> None:
    """Stop the threads, dropping the work not started."""
    for executor in _executors.values():
        executor.shutdown(wait=False, cancel_futures=True)
    _executors.clear()
    release_finished()
