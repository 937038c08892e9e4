# SPDX-License-Identifier: GPL-3.0-or-later
"""What the panel shows of one scene, kept per scene for the session.

The last method plan's choices, the live view's accuracy checks and the methods Auto
passed over after them, and the morphing grids' bake progress and per-reflector lines:
one :class:`SceneStatus` per scene, keyed by the scene's ``session_uid``, so that
renaming a scene keeps its status and an object of the same name in another scene
never writes over it. Dropped when a file is loaded and on unregister.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class SceneStatus:
    """One scene's status (see the module docstring)."""

    #: ``method_plan.MethodChoice`` of each reflector in the last plan.
    choices: list = field(default_factory=list)
    #: {reflector: ``accuracy.Measured``}: the live view's last checks.
    measured: dict = field(default_factory=dict)
    #: {reflector: ``picture_check.PictureCheck``}: the last checks of a chosen mode's
    #: picture against the trace (Render Image's, the resting live view's).
    pictures: dict = field(default_factory=dict)
    #: {reflector: {method: what was measured}}: methods passed over (until Refresh).
    outside_accuracy: dict = field(default_factory=dict)
    #: The morphing bake in progress or last done: running, done, total, reflector, message.
    bake: dict = field(default_factory=dict)
    #: {reflector: its grid's last load, bake, clear or draw outcome}.
    grid_lines: dict = field(default_factory=dict)


_stores: dict[int, SceneStatus] = {}


def status_of(scene) -> SceneStatus:
    """``scene``'s status (made empty on first use)."""
    return _stores.setdefault(scene.session_uid, SceneStatus())


def forget_all() -> None:
    """Drop every scene's status (another file is loaded, or unregister)."""
    _stores.clear()
