# SPDX-License-Identifier: GPL-3.0-or-later
"""What each glass pixel sees, ray traced on the GPU every frame.

Each pixel's own path through convex glass is followed on the GPU
(:class:`.glass_rays.GlassRays`): where it leaves the glass, and along which ray. The ray
is then met with the scene (``scene_tables.py``: its triangles under a bounding volume
hierarchy) and the hit lit as a refracted vertex is (``glsl/glass_trace.glsl``), with what
glass that reflects reflects back inside as the path leaves, and what it reflects where
the pixel sees it: the picture Render Image traces on the CPU, per pixel, whatever the
number of images a point has through the glass or of reflections inside it. The
refraction search's meshes (``refraction_draw.py``) are drawn where a pixel is left to
them: its path was not followed out, or it meets a mesh with an image texture past the
first ``scene_tables.MAX_IMAGES``.

What is uploaded once per renderer: the scene's tables; per frame, one dispatch per glass
over its box on screen.
"""

from __future__ import annotations

import gpu

from ...engine.methods.iterative.search import FOUND
from ..shader_cache import cached_shader
from ..shader_sources import glsl_source
from . import glass_rays, scene_tables
from .scene_tables import SceneTables, TracedScene

#: Invocations per work group (8 x 8 pixels).
LOCAL_SIZE = 8
#: The per-pixel paths' textures the trace reads (``glass_rays.PATHS``: their
#: ``GlassRays`` attribute and name), in binding order.
PATHS = tuple(path for path in glass_rays.PATHS if path[0] != "entries")


@cached_shader
def trace_shader():
    """The per-pixel compute shader, built on first use (40 bytes of push constants)."""
    info = gpu.types.GPUShaderCreateInfo()
    info.push_constant('IVEC4', "rect")
    for slot, (_, name) in enumerate(PATHS):
        info.sampler(slot, 'FLOAT_2D', name)
    scene_tables.declare(info, len(PATHS))
    info.image(0, 'RGBA32F', 'FLOAT_2D', "traced_colors", qualifiers={'WRITE'})
    info.image(1, 'RGBA32F', 'FLOAT_2D', "front_colors", qualifiers={'WRITE'})
    info.local_group_size(LOCAL_SIZE, LOCAL_SIZE)
    info.compute_source(glsl_source("glass_trace.glsl", {"FOUND": FOUND}, scene_tables.prelude()))
    return gpu.shader.create_from_info(info)


class SceneTrace:
    """Each frame's traced glass pixels of one renderer (:attr:`colors`, RGBA32F of the
    view's size): its diffuse ``meshes`` as given and its ``geometry``, as
    :class:`.scene_tables.SceneTables` takes them, ``scene`` saying what else the rays show."""

    def __init__(self, meshes, geometry, scene: TracedScene = TracedScene()):
        self.tables = SceneTables(meshes, geometry, scene)
        self.colors = None
        #: What glass that reflects reflects where each pixel sees it (RGBA32F of the
        #: view's size, the world colour elsewhere): the composite's colours beneath the
        #: refraction (``FrameTargets.beneath``).
        self.front_colors = None
        self._size = None

    def trace(self, rays, rects, size, images) -> None:
        """The traced colours of the glass pixels of ``rays`` (:class:`.glass_rays.GlassRays`,
        this frame's) within each (x0, y0, x1, y1) of ``rects``, in a view of ``size``;
        ``images(k)``: the frame's image textures."""
        if self._size != size:
            self.colors = gpu.types.GPUTexture(size, format='RGBA32F')
            self.front_colors = gpu.types.GPUTexture(size, format='RGBA32F')
            self._size = size
        self.colors.clear(format='FLOAT', value=(0.0, 0.0, 0.0, 0.0))
        self.front_colors.clear(format='FLOAT', value=self.tables.world)
        if self.tables.empty:
            return
        shader = trace_shader()
        shader.bind()
        self.tables.bind(shader, images)
        for attribute, name in PATHS:
            shader.uniform_sampler(name, getattr(rays, attribute))
        shader.image("traced_colors", self.colors)
        shader.image("front_colors", self.front_colors)
        for x0, y0, x1, y1 in rects:
            if x1 > x0 and y1 > y0:
                shader.uniform_int("rect", (x0, y0, x1, y1))
                gpu.compute.dispatch(shader, -(-(x1 - x0) // LOCAL_SIZE), -(-(y1 - y0) // LOCAL_SIZE), 1)
