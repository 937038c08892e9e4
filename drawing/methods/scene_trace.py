# SPDX-License-Identifier: GPL-3.0-or-later
"""What each glass pixel sees, ray traced on the GPU every frame.

Each pixel's own path through convex glass is followed on the GPU
(:class:`.glass_rays.GlassRays`): where it leaves the glass, and along which ray. The ray
is then met with the scene's triangles through a bounding volume hierarchy
(``glsl/scene_bvh.glsl``, the tree of ``engine/geometry/bvh.py`` packed into two
textures) and the hit lit as a refracted vertex is (``glsl/glass_trace.glsl``), with what
glass that reflects reflects back inside as the path leaves: the picture Render Image
traces on the CPU, per pixel and exact, whatever the number of images a point has
through the glass or of reflections inside it. The refraction search's
meshes (``refraction_draw.py``) are drawn where a pixel is left to them: its path was
not followed out, or it meets a mesh with an image texture.

What is uploaded once per renderer: the tree over the reflected meshes' triangles (as
subdivided for drawing), their vertices' colours and normals; per frame, one dispatch
per glass over its box on screen.
"""

from __future__ import annotations

from dataclasses import dataclass

import gpu
import numpy as np

from ...engine.geometry.bvh import build_bvh
from ...engine.methods.iterative.search import FOUND
from ..draw_shaders import shading_source
from ..gpu_data import data_texture
from ..shader_cache import cached_shader
from ..shader_sources import glsl_source

#: Triangles per leaf of the tree: the slab tests of a deeper tree cost more than the
#: triangle tests of a fuller leaf.
LEAF_SIZE = 4
#: Invocations per work group (8 x 8 pixels).
LOCAL_SIZE = 8
#: A leaving ray meets triangles from this share of the scene's diameter on (the glass it
#: leaves is no triangle of the scene, but an object may touch it).
START_SHARE = 1e-7
#: A slot's image index for a mirror's triangle (``glsl/scene_bvh.glsl``; -1: no image).
MIRROR_CODE = -2


@dataclass(frozen=True)
class TracedScene:
    """What the trace shows besides the meshes' colours: the ``world`` colour (linear RGB)
    where a ray meets nothing, which meshes are ``mirrors`` (by name: a ray reflects off
    them) and how many mirror reflections a ray follows (the scene's Max Order)."""

    world: tuple = (0.0, 0.0, 0.0)
    mirrors: frozenset = frozenset()
    max_order: int = 1


@cached_shader
def trace_shader():
    """The per-pixel compute shader, built on first use (44 bytes of push constants)."""
    info = gpu.types.GPUShaderCreateInfo()
    info.push_constant('IVEC4', "rect")
    info.push_constant('VEC4', "world")
    info.push_constant('FLOAT', "t_min")
    info.push_constant('INT', "leaf_first")
    info.push_constant('INT', "max_order")
    names = ("exit_rays", "leaving_rays", "back_exits", "back_leaving_rays", "front_points", "front_rays",
             "bvh_boxes", "bvh_slots", "scene_vertices", "vertex_colors", "vertex_normals")
    for slot, name in enumerate(names):
        info.sampler(slot, 'FLOAT_2D', name)
    info.image(0, 'RGBA32F', 'FLOAT_2D', "traced_colors", qualifiers={'WRITE'})
    info.image(1, 'RGBA32F', 'FLOAT_2D', "front_colors", qualifiers={'WRITE'})
    info.local_group_size(LOCAL_SIZE, LOCAL_SIZE)
    prelude = shading_source() + glsl_source("scene_bvh.glsl")
    defines = {"LEAF_SIZE": LEAF_SIZE, "FOUND": FOUND, "MIRROR_CODE": f"{MIRROR_CODE:.1f}"}
    info.compute_source(glsl_source("glass_trace.glsl", defines, prelude))
    return gpu.shader.create_from_info(info)


def bvh_tables(vertices: np.ndarray, triangles: np.ndarray, codes: np.ndarray) -> tuple:
    """((2 n, 4) node texels, (slots, 4) slot texels, first leaf's node index) of the tree
    over ``triangles`` (``glsl/scene_bvh.glsl`` says what they hold); ``codes`` (T,) each
    triangle's image index, -1 for none (:func:`triangle_codes`)."""
    bvh = build_bvh(vertices, triangles, leaf_size=LEAF_SIZE)
    leaf_first = 1 << bvh.depth
    boxes = np.zeros((4 * leaf_first, 4), np.float32)
    for level, rows in enumerate(bvh.box_rows):  # one slice per level, not per node
        nodes = (1 << level) + np.arange(1 << level)
        boxes[2 * nodes, :3] = np.nan_to_num(rows[:3].T)
        boxes[2 * nodes, 3] = ~np.isnan(rows[0])
        boxes[2 * nodes + 1, :3] = np.nan_to_num(rows[3:].T)
    slots = np.full((len(bvh.order), 4), -1.0, np.float32)
    filled = bvh.order >= 0
    slots[filled, :3] = triangles[bvh.order[filled]]
    slots[filled, 3] = codes[bvh.order[filled]]
    return boxes, slots, leaf_first


def triangle_codes(geometry, mirrors=frozenset()) -> np.ndarray:
    """(T,) each reflected triangle's image index (-1: none) from ``geometry``'s ranges of
    triangles sorted by image, :data:`MIRROR_CODE` for the meshes named in ``mirrors``."""
    codes = np.full(len(geometry.triangles), -1, np.int64)
    for image, first, count in geometry.ranges:  # one slice per image
        codes[first:first + count] = image
    mirror_meshes = np.flatnonzero(np.isin(np.asarray(geometry.mesh_names, dtype=object), list(mirrors)))
    if len(mirror_meshes) and len(codes):
        codes[np.isin(geometry.vertex_mesh[np.asarray(geometry.triangles)[:, 0]], mirror_meshes)] = MIRROR_CODE
    return codes


class SceneTrace:
    """The scene's triangles of one renderer's geometry on the GPU as a tree, and each
    frame's traced glass pixels (:attr:`colors`, RGBA32F of the view's size), ``scene``
    (:class:`TracedScene`) saying what else the rays show."""

    def __init__(self, geometry, meshes, scene: TracedScene = TracedScene()):
        self.geometry = geometry
        self.meshes = meshes
        self.scene = scene
        self.world = tuple(float(c) for c in scene.world)[:3] + (1.0,)
        self.colors = None
        #: What glass that reflects reflects where each pixel sees it (RGBA32F of the
        #: view's size, the world colour elsewhere): the composite's colours beneath the
        #: refraction (``FrameTargets.beneath``).
        self.front_colors = None
        self._tables = None
        self._size = None

    def _ensure(self) -> None:
        if self._tables is not None:
            return
        g = self.geometry
        boxes, slots, leaf_first = bvh_tables(g.vertices - g.shift, np.asarray(g.triangles),
                                              triangle_codes(g, self.scene.mirrors))
        self._tables = (data_texture(boxes), data_texture(slots), data_texture(g.colors, self.meshes.width),
                        data_texture(np.c_[g.normals, g.lit], self.meshes.width), leaf_first)

    def trace(self, rays, rects, size) -> None:
        """The traced colours of the glass pixels of ``rays`` (:class:`.glass_rays.GlassRays`,
        this frame's) within each (x0, y0, x1, y1) of ``rects``, in a view of ``size``."""
        if self._size != size:
            self.colors = gpu.types.GPUTexture(size, format='RGBA32F')
            self.front_colors = gpu.types.GPUTexture(size, format='RGBA32F')
            self._size = size
        self.colors.clear(format='FLOAT', value=(0.0, 0.0, 0.0, 0.0))
        self.front_colors.clear(format='FLOAT', value=self.world)
        if not len(self.geometry.triangles):
            return
        self._ensure()
        boxes, slots, colors, normals, leaf_first = self._tables
        shader = trace_shader()
        shader.bind()
        shader.uniform_float("t_min", START_SHARE * self.geometry.diameter)
        shader.uniform_int("leaf_first", leaf_first)
        shader.uniform_int("max_order", int(self.scene.max_order))
        shader.uniform_float("world", self.world)
        for name, texture in (("exit_rays", rays.exits), ("leaving_rays", rays.leaving),
                              ("back_exits", rays.back_exits), ("back_leaving_rays", rays.back_leaving),
                              ("front_points", rays.front_points), ("front_rays", rays.front_rays),
                              ("bvh_boxes", boxes),
                              ("bvh_slots", slots), ("scene_vertices", self.meshes.positions),
                              ("vertex_colors", colors), ("vertex_normals", normals)):
            shader.uniform_sampler(name, texture)
        shader.image("traced_colors", self.colors)
        shader.image("front_colors", self.front_colors)
        for x0, y0, x1, y1 in rects:
            if x1 > x0 and y1 > y0:
                shader.uniform_int("rect", (x0, y0, x1, y1))
                gpu.compute.dispatch(shader, -(-(x1 - x0) // LOCAL_SIZE), -(-(y1 - y0) // LOCAL_SIZE), 1)
