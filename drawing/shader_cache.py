# SPDX-License-Identifier: GPL-3.0-or-later
"""The GPU shaders this extension builds, kept for reuse and released before Blender goes.

A shader is built on first use (never at import or register time) and kept by
:func:`cached_shader`. A shader object freed after Blender has torn its GPU context
down crashes the process: Blender run as a Python module (a headless render, a farm
script) reaches that teardown when the interpreter exits, and a module-level cache is
freed after it. So the first shader built registers :func:`release_shaders` with
``atexit`` (which runs before the interpreter clears modules); the extension's
``unregister`` releases them too.
"""

from __future__ import annotations

import atexit
import functools

_caches: list = []
_exit_hook = False


def cached_shader(build):
    """``build`` (a function returning a ``GPUShader`` for its arguments) cached per
    arguments, its shaders released by :func:`release_shaders`."""
    cached = functools.cache(build)

    @functools.wraps(build)
    def shader(*args, **kwargs):
        global _exit_hook
        if not _exit_hook:
            atexit.register(release_shaders)
            _exit_hook = True
        return cached(*args, **kwargs)

    _caches.append(cached)
    return shader


def release_shaders() -> None:
    """Drop every shader built (the next draw builds them again)."""
    for cache in _caches:
        cache.cache_clear()
