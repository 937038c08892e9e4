# SPDX-License-Identifier: GPL-3.0-or-later
"""Glass ray traced per pixel on the GPU, every frame: any glass solid or sheet.

Each pixel the pre-pass saw glass on follows its eye ray through the glass's own
triangles (``scene_tables.py``: one bounding volume hierarchy over the diffuse meshes,
the mirrors and the glass, ``glsl/scene_colors.glsl``): Snell's law at each interface off
the smooth normal, total internal reflection past the critical angle, mirrors reflecting
to the scene's Max Order, what the glass reflects where the ray meets it and back inside
where it leaves, mixed by the exact Fresnel reflectance (``glsl/glass_trace.glsl``): the
picture Render Image's CPU trace gives (``blender/glass_layer.py``), convex or not, one
glass seen through another, whatever the number of images a point has through the glass.
The cost follows the glass's pixels, not the scene's vertices. Scenes whose image
textures do not fit a trace's atlas (``image_atlas.py``) are drawn by the refraction
search instead (``refraction_draw.py``).

What is uploaded once per renderer: the scene's tables; per frame, one dispatch over the
glass's box on screen and one full-screen draw (``settled_draw.py``).
"""

from __future__ import annotations

import functools

import gpu
import numpy as np

from ..frame_pass import Frame, FramePass, PassInputs
from ..gpu_data import data_texture, read_texture
from ..screen_space import box_corners, box_on_screen, camera_position, pixel_box
from ..shader_cache import cached_shader
from ..shader_sources import glsl_source
from . import scene_tables
from .scene_tables import SceneTables, TracedScene
from .settled_draw import draw_settled

#: Invocations per work group (8 x 8 pixels).
LOCAL_SIZE = 8
#: The eye's ray is followed from this share of the pre-pass's depth before the glass it
#: saw: the point from float32 depth lies within about 1e-6 of its distance of the surface.
LEAD = 1e-3


@cached_shader
def trace_shader():
    """The per-pixel compute shader, built on first use (116 bytes of push constants: the
    rectangle's origin alone, an IVEC2 declared last, keeps Blender's count, which pads
    vectors, within the 128 Vulkan guarantees)."""
    info = gpu.types.GPUShaderCreateInfo()
    info.push_constant('MAT4', "inverse_view_projection")
    info.push_constant('VEC4', "camera")
    info.sampler(0, 'FLOAT_2D', "prepass_labels")
    info.sampler(1, 'FLOAT_2D', "eye_medium")
    scene_tables.declare(info, 2)
    info.push_constant('IVEC2', "rect_origin")
    info.image(0, 'RGBA32F', 'FLOAT_2D', "traced_colors", qualifiers={'WRITE'})
    info.image(1, 'RGBA32F', 'FLOAT_2D', "front_colors", qualifiers={'WRITE'})
    info.local_group_size(LOCAL_SIZE, LOCAL_SIZE)
    info.compute_source(glsl_source("glass_trace.glsl", {"LEAD": f"{LEAD:.9e}"}, scene_tables.prelude()))
    return gpu.shader.create_from_info(info)


class GlassTracePass(FramePass):
    """The trace's GPU side for one renderer whose reflectors are ``glasses``
    (``engine.glass.Glass`` each, the k-th the renderer's reflector k): its ``diffuse``
    meshes as given (what the rays meet; those named in ``scene.mirrors`` reflect) and
    the glass, as :class:`.scene_tables.SceneTables` takes them."""

    name = "glass trace"

    @classmethod
    def factory(cls, glasses, scene: TracedScene = TracedScene()):
        """The pass's factory (``frame_pass.FramePass.factory``)."""
        return functools.partial(cls.of_inputs, tuple(glasses), scene=scene)

    @classmethod
    def of_inputs(cls, glasses: tuple, inputs: PassInputs, scene: TracedScene = TracedScene()) -> "GlassTracePass":
        return cls(inputs.geometry, inputs.meshes, glasses, inputs.diffuse, scene)

    def __init__(self, geometry, meshes, glasses, diffuse, scene: TracedScene = TracedScene()):
        self.geometry = geometry
        self.meshes = meshes
        self.glasses = tuple(glasses)
        self.tables = SceneTables(diffuse, geometry, scene, glasses=self.glasses)
        #: RGBA32F of the view's size: the last frame's glass pixels (``glsl/glass_trace.glsl``).
        self.colors = None
        #: The same colours, the composite's beneath the glass (``FrameTargets.beneath``);
        #: alpha 2 where the path met glass inside glass, the world colour off the glass.
        self.front_colors = None
        self._size = None
        self._corners = None
        #: The glass the eye is inside (its index; -1: air), which the caller sets per view.
        self.eye_glass = -1
        self._eye_textures = {}

    @property
    def reflector_indices(self) -> list:
        return list(range(len(self.glasses)))

    def update(self, frame: Frame) -> None:
        """Trace every glass pixel of ``frame``."""
        view, targets = frame.view, frame.targets
        size = (targets.width, targets.height)
        if self._size != size:
            self.colors = gpu.types.GPUTexture(size, format='RGBA32F')
            self.front_colors = gpu.types.GPUTexture(size, format='RGBA32F')
            self._size = size
        self.colors.clear(format='FLOAT', value=(0.0, 0.0, 0.0, 0.0))
        self.front_colors.clear(format='FLOAT', value=self.tables.world)
        frame.targets.beneath = self.front_colors
        if self._corners is None:
            points = np.concatenate([glass.surface.vertices for glass in self.glasses]) - self.geometry.shift
            self._corners = box_corners(points)
        x, y, width, height = pixel_box(box_on_screen(self._corners, view, self.geometry.shift, *size), *size, 0)
        if width <= 0 or height <= 0:
            return
        shader = trace_shader()
        shader.bind()
        self.tables.bind(shader)
        shader.uniform_float("inverse_view_projection", frame.world_to_clip.inverted())
        shader.uniform_float("camera", camera_position(view, self.geometry.shift))
        shader.uniform_int("rect_origin", (x, y))
        shader.uniform_sampler("prepass_labels", targets.prepass_labels)
        shader.uniform_sampler("eye_medium", self._eye_medium())
        shader.image("traced_colors", self.colors)
        shader.image("front_colors", self.front_colors)
        gpu.compute.dispatch(shader, -(-width // LOCAL_SIZE), -(-height // LOCAL_SIZE), 1)

    def _eye_medium(self):
        """A texel of (index, index of refraction) of the medium the eye is in (made once
        per glass)."""
        if self.eye_glass not in self._eye_textures:
            ior = self.glasses[self.eye_glass].ior if self.eye_glass >= 0 else 1.0
            self._eye_textures[self.eye_glass] = data_texture(np.array([[self.eye_glass, ior]]))
        return self._eye_textures[self.eye_glass]

    def nested(self, labels: np.ndarray) -> tuple:
        """The names of the glass whose pixels' paths met glass inside other glass in the
        last frame (``labels``: its pre-pass labels, read back: (H, W, 4))."""
        if self.front_colors is None:
            return ()
        front = read_texture(self.front_colors, *self._size)
        ids = np.unique(np.rint(labels[..., 0][front[..., 3] > 1.5]).astype(int)) - 1
        return tuple(self.glasses[k].name for k in ids if 0 <= k < len(self.glasses))

    def claims(self) -> frozenset:
        return frozenset(self.reflector_indices)

    @property
    def every_order_reflectors(self) -> frozenset:
        return frozenset(self.reflector_indices)

    def answers(self) -> list:
        return []

    def draw(self, frame: Frame) -> None:
        """The traced pixels, at depth 0 (``settled_draw.py``)."""
        if self.colors is not None:
            draw_settled(self.colors)

    def statistics(self) -> list:
        return [f"Glass traced on the GPU: {', '.join(glass.name for glass in self.glasses)} (every pixel, through "
                f"every interface, to Max Order {self.tables.scene.max_order})"]
