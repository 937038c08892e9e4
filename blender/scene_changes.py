# SPDX-License-Identifier: GPL-3.0-or-later
"""How settings and bakes tell the live view that the scene changed, without importing it.

Property update callbacks (``properties.py``) and the morphing bake (``morph_bake.py``)
call :func:`notify`; the live view (``live_handlers.py``) connects its listener when the
extension is registered and disconnects it on unregister. So neither of them imports
the live view, and the live view's imports of them make no circle.
"""

from __future__ import annotations

_listeners: list = []


def connect(listener) -> None:
    """Call ``listener(context, reflectors=..., meshes=...)`` on every change (once)."""
    if listener not in _listeners:
        _listeners.append(listener)


def disconnect(listener) -> None:
    if listener in _listeners:
        _listeners.remove(listener)


def notify(context, reflectors: bool = False, meshes: bool = False) -> None:
    """The scene of ``context`` changed: ``reflectors``, the set of reflectors or a method
    setting (the live view re-bakes); ``meshes``, a reflector's appearance (a new
    renderer only)."""
    for listener in list(_listeners):
        listener(context, reflectors=reflectors, meshes=meshes)
