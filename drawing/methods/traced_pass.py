# SPDX-License-Identifier: GPL-3.0-or-later
"""Mirrors ray traced per pixel on the GPU, every frame: the method that is right on any
mirror, folded or not star-shaped, with no bake.

The projection methods place each diffuse vertex where it appears (the sample-based
camera, the iterative search, the grids, perturbation), and a mirror that folds its
reflections (a point seen two or three times in it) or is not star-shaped (a torus, a
teapot) is where they miss images or need seconds per view. Here each pixel the pre-pass
saw a traced mirror on is met with the mirror's own triangles (the exact point and its
smooth normal), its eye ray reflected there and met with the scene
(``scene_tables.py``: a bounding volume hierarchy over the diffuse meshes, the mirrors
and the glass, ``glsl/mirror_trace.glsl``), reflecting off mirrors to the scene's Max
Order and refracting through glass (its own reflection left out, drawn where the eye
meets the glass by ``glass_trace.py``):
the exact answer the band trace of Render Image gives (``engine/geometry/band_trace.py``)
for every pixel, every image, every order. The cost follows the pixels, not the
geometry's vertices: a tree descent or two per mirror pixel.

What is uploaded once per renderer: the scene's tables; per frame, one dispatch over the
traced mirrors' box on screen and one full-screen draw (``settled_draw.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import gpu
import numpy as np

from ..frame_pass import Frame, FramePass, PassInputs
from ..gpu_data import data_texture
from ..screen_space import box_corners, box_on_screen, camera_position, pixel_box
from ..shader_cache import cached_shader
from ..shader_sources import glsl_source
from . import scene_tables
from .scene_tables import SceneTables, TracedScene
from .settled_draw import MISSED, draw_settled

#: Invocations per work group (8 x 8 pixels).
LOCAL_SIZE = 8
#: A reflected ray meets triangles from this share of the scene's diameter on: the point
#: it leaves, from the pre-pass's depth, lies within float32's error of its mirror (about
#: 1e-6 of its distance), which this clears.
REFLECTED_START_SHARE = 1e-5


@dataclass(frozen=True)
class TracedMirror:
    """A reflector the trace draws: its index among the scene's reflectors, and its name."""

    index: int
    name: str


@cached_shader
def trace_shader():
    """The per-pixel compute shader, built on first use (108 bytes of push constants)."""
    info = gpu.types.GPUShaderCreateInfo()
    info.push_constant('MAT4', "inverse_view_projection")
    info.push_constant('VEC4', "camera")
    info.push_constant('IVEC4', "rect")
    for slot, name in enumerate(("prepass_labels", "prepass_normals", "traced_reflectors")):
        info.sampler(slot, 'FLOAT_2D', name)
    scene_tables.declare(info, 3, world=False)
    info.image(0, 'RGBA32F', 'FLOAT_2D', "traced_colors", qualifiers={'WRITE'})
    info.local_group_size(LOCAL_SIZE, LOCAL_SIZE)
    defines = {"MISSED": f"{MISSED:.9e}"}
    info.compute_source(glsl_source("mirror_trace.glsl", defines, scene_tables.prelude(world=False)))
    return gpu.shader.create_from_info(info)


class TracedPass(FramePass):
    """The trace's GPU side for one renderer: its reflected geometry, every reflector of
    the scene (the rays reflect off each of them), its ``diffuse`` meshes as given (what
    the rays meet) and the reflectors it draws (``methods``, :class:`TracedMirror` each)."""

    name = "traced"

    @classmethod
    def of_inputs(cls, methods: tuple, inputs: PassInputs) -> "TracedPass":
        return cls(inputs.geometry, methods, inputs.meshes, inputs.reflectors, inputs.diffuse,
                   inputs.settings.max_order, inputs.glasses)

    def __init__(self, geometry, methods, meshes, reflectors, diffuse, max_order: int = 1, glasses=()):
        self.geometry = geometry
        self.methods = list(methods)
        self.meshes = meshes
        self.reflectors = tuple(reflectors)
        self.max_order = int(max_order)
        self.tables = SceneTables(diffuse, geometry, TracedScene(max_order=self.max_order), surfaces=self.reflectors,
                                  glasses=glasses)
        #: RGBA32F of the view's size: the last frame's traced pixels (``glsl/mirror_trace.glsl``).
        self.colors = None
        self._size = None
        self._drawn = frozenset()
        self._boxes = {}
        self._flag_textures = {}

    def update(self, frame: Frame) -> None:
        """Trace the pixels of the pass's reflectors that no earlier pass claimed."""
        self._drawn = frozenset(m.index for m in self.methods) - frame.claimed
        if not self._drawn:
            return
        view, targets = frame.view, frame.targets
        size = (targets.width, targets.height)
        if self._size != size:
            self.colors = gpu.types.GPUTexture(size, format='RGBA32F')
            self._size = size
        self.colors.clear(format='FLOAT', value=(0.0, 0.0, 0.0, 0.0))
        x, y, width, height = pixel_box(box_on_screen(self._box(self._drawn), view, self.geometry.shift, *size),
                                        *size, 0)
        if width <= 0 or height <= 0:
            return
        shader = trace_shader()
        shader.bind()
        # A mirror hit is one bounce: the scene's tables follow the rest of Max Order.
        self.tables.bind(shader, bounces=self.max_order - 1, world=False,
                         start_share=REFLECTED_START_SHARE)
        shader.uniform_float("inverse_view_projection", frame.world_to_clip.inverted())
        shader.uniform_float("camera", camera_position(view, self.geometry.shift))
        shader.uniform_int("rect", (x, y, x + width, y + height))
        shader.uniform_sampler("prepass_labels", targets.prepass_labels)
        shader.uniform_sampler("prepass_normals", targets.prepass_normals)
        shader.uniform_sampler("traced_reflectors", self._flags(self._drawn))
        shader.image("traced_colors", self.colors)
        gpu.compute.dispatch(shader, -(-width // LOCAL_SIZE), -(-height // LOCAL_SIZE), 1)

    def _box(self, indices: frozenset) -> np.ndarray:
        """(8, 4) corners of the bounding box of the reflectors ``indices``, relative to the shift."""
        key = tuple(sorted(indices))
        if key not in self._boxes:
            points = np.concatenate([self.reflectors[k].vertices for k in key]) - self.geometry.shift
            self._boxes[key] = box_corners(points)
        return self._boxes[key]

    def _flags(self, indices: frozenset):
        """A texture of one texel per reflector: 1 where the pass traces it (made once per set)."""
        if indices not in self._flag_textures:
            flags = np.zeros((max(1, len(self.reflectors)), 1), np.float32)
            flags[list(indices), 0] = 1.0
            self._flag_textures[indices] = data_texture(flags, 1 << scene_tables.TABLE_ROW_BITS)
        return self._flag_textures[indices]

    def claims(self) -> frozenset:
        return self._drawn

    @property
    def every_order_reflectors(self) -> frozenset:
        return frozenset(m.index for m in self.methods)

    def answers(self) -> list:
        return []

    def draw(self, frame: Frame) -> None:
        """The traced pixels, at depth 0 (``settled_draw.py``)."""
        if self._drawn and self.colors is not None:
            draw_settled(self.colors)

    def statistics(self) -> list:
        if not self.methods:
            return []
        return [f"Traced on the GPU: {', '.join(m.name for m in self.methods)} (every pixel, every image, "
                f"to Max Order {self.max_order})"]
