# SPDX-License-Identifier: GPL-3.0-or-later
"""Make Blender's ``gpu`` module usable, also in background mode (``blender -b``, ``import bpy``).

In background mode every ``gpu`` drawing call raises ``SystemError: GPU functions for
drawing are not available in background mode`` until something has rendered. One tiny
Workbench render initialises the GPU backend (through EGL, e.g. on Mesa llvmpipe), after
which offscreen buffers, custom shaders and float textures all work. With a window the GPU is
always ready and nothing is rendered.

This module imports only ``bpy`` and ``gpu``, so the test harness can also load it by
file path in a child process (``tests/conftest.py`` probes there first: without OpenGL,
Blender aborts the whole process instead of raising).
"""

from __future__ import annotations

import bpy
import gpu

_NAME = "curved_reflections_gpu_init"


def gpu_ready() -> bool:
    """Whether ``gpu`` drawing calls work now (no side effects beyond a 4x4 offscreen)."""
    try:
        gpu.types.GPUOffScreen(4, 4).free()
    except SystemError:
        return False
    return True


def initialise_gpu() -> None:
    """One 4x4 Workbench render in a temporary scene, which starts the GPU backend.

    The scene, camera and their data are removed afterwards; the user's scenes and
    render settings are not touched.
    """
    scene = bpy.data.scenes.new(_NAME)
    camera_data = bpy.data.cameras.new(_NAME)
    camera = bpy.data.objects.new(_NAME, camera_data)
    try:
        scene.collection.objects.link(camera)
        scene.camera = camera
        scene.render.engine = 'BLENDER_WORKBENCH'
        scene.render.resolution_x = scene.render.resolution_y = 4
        scene.render.resolution_percentage = 100
        bpy.ops.render.render(scene=scene.name)
    finally:
        bpy.data.scenes.remove(scene)
        bpy.data.objects.remove(camera)
        bpy.data.cameras.remove(camera_data)


def ensure_gpu() -> None:
    """Initialise the GPU if drawing calls do not work yet; raise ``RuntimeError`` if it stays off."""
    if gpu_ready():
        return
    initialise_gpu()
    if not gpu_ready():
        raise RuntimeError("Blender's GPU module could not be initialised (no OpenGL 4.3 or Vulkan device)")
