# SPDX-License-Identifier: GPL-3.0-or-later
"""Fixtures for the Blender layer: an empty scene, and the package registered in-process."""

import pytest


@pytest.fixture
def empty_scene():
    """The factory start-up file with nothing in it; returns its scene."""
    import bpy

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    return bpy.context.scene


@pytest.fixture
def registered():
    """The package registered for one test, and unregistered after it."""
    import curved_reflections

    curved_reflections.register()
    yield curved_reflections
    curved_reflections.unregister()
