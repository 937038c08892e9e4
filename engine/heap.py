# SPDX-License-Identifier: GPL-3.0-or-later
"""Handing freed memory back to the system between the stages of a frame.

numpy allocates its arrays with the C library's ``malloc``. glibc serves arrays up to
32 MB (once larger ones have come and gone) from its heap, and a freed one stays in the
process's resident memory, between the blocks that live on, until it is reused or the
heap is trimmed. A frame of a million-triangle mirror makes and frees hundreds of
megabytes of them stage by stage (the capture's weld, the ray-tracing set's blocks,
the renderer's arrays, the camera's ray map), so its resident peak held the garbage
of every earlier stage besides the live arrays, and varied by 150 MB from run to run
with where the heap happened to place them (bench_cliffs' subdivided ball, six frames:
290 to 480 MB over Blender's own frame; trimmed after each stage, 250 to 300 MB).
:func:`release_freed_memory` asks glibc to return its free pages (``malloc_trim``):
a few milliseconds, and nothing where the C library is not glibc (macOS, Windows,
musl), whose allocators return large blocks themselves.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools


@functools.cache
def _malloc_trim():
    """glibc's ``malloc_trim``, or None where the C library has none."""
    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim
    except (OSError, AttributeError, TypeError):
        return None


def release_freed_memory() -> bool:
    """Return the C heap's free pages to the system (glibc's ``malloc_trim(0)``);
    whether it ran. Call it after a stage that freed large arrays."""
    trim = _malloc_trim()
    if trim is None:
        return False
    trim(0)
    return True
