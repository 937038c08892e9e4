# SPDX-License-Identifier: GPL-3.0-or-later
"""Each pixel's own path through convex glass, on the GPU every frame: what the refracted
meshes of the refraction search are tested against, and where glass shows black.

The refraction search (``refraction_draw.py``) answers per vertex; a refracted triangle
is then filled between its corners' images, and through a strong lens two corners may be
answered in different images of the glass (either side of a focus, where the image turns
round): the triangle spans the lens. A compute stage (``glsl/glass_rays.glsl``) follows
each pixel of each searched glass through it, from the surface the pre-pass saw, on the
glass's cube map (``glsl/glass_path.glsl``, the search's own path), and keeps the entry,
the exit and the ray that leaves. The refracted meshes' fragment stage casts that ray at
each fragment's triangle and keeps the fragment where it hits, or passes near enough to
stand in (``glsl/reflection_mesh_frag.glsl``, REFRACTION_TEST), as the mirrors' fragments
are held to the law of reflection; the next search starts from the pixels whose rays
pass each vertex nearest (``glsl/refraction_search.glsl``). Where the
path must reflect totally inside a glass that does not reflect (a Refraction BSDF),
Cycles shows black, and so does the frame (``settled_draw.py``); glass that
reflects (a Glass BSDF) reflects the path inside (up to ``PIXEL_INSIDE_REFLECTIONS``
times), and it leaves where it next can.
"""

from __future__ import annotations

import gpu
import numpy as np

from ...engine.glass import refraction_search as search_module
from ..draw_shaders import shading_source
from ..gpu_data import read_texture
from ..screen_space import camera_position
from ..shader_cache import cached_shader
from ..shader_sources import glsl_source
from .settled_draw import draw_settled

#: Invocations per work group of the per-pixel stage (8 x 8 pixels).
LOCAL_SIZE = 8
#: Total reflections inside glass that reflects (a Glass BSDF) each pixel's path follows
#: at most (the search's follow ``refraction_search.INSIDE_REFLECTIONS``): one path per
#: pixel, where each more costs one exit search at the pixels that reflect again. A box
#: seen from above reflects a quarter of its pixels' paths twice; Render Image follows
#: ``paths.MAX_INTERFACES`` interfaces.
PIXEL_INSIDE_REFLECTIONS = 4
#: (attribute of :class:`GlassRays`, the shader's image) of each per-pixel texture, in
#: binding order (``glsl/glass_rays.glsl`` says what each holds).
PATHS = (("exits", "exit_rays"), ("leaving", "leaving_rays"), ("entries", "entry_rays"))


@cached_shader
def rays_shader():
    """The per-pixel compute shader, built on first use (100 bytes of push constants)."""
    info = gpu.types.GPUShaderCreateInfo()
    info.push_constant('MAT4', "inverse_view_projection")
    info.push_constant('VEC4', "camera")
    info.push_constant('VEC2', "view_size")
    info.push_constant('FLOAT', "eta")
    info.push_constant('FLOAT', "glass_id")
    info.push_constant('INT', "self_map")
    info.push_constant('INT', "reflects")
    for slot, name in enumerate(("reflector_maps", "map_params", "prepass_labels")):
        info.sampler(slot, 'FLOAT_2D', name)
    for slot, (_, name) in enumerate(PATHS):
        info.image(slot, 'RGBA32F', 'FLOAT_2D', name, qualifiers={'WRITE'})
    info.local_group_size(LOCAL_SIZE, LOCAL_SIZE)
    prelude = shading_source() + glsl_source("cube_map.glsl") + glsl_source("glass_path.glsl")
    defines = {**search_module.search_defines(), "INSIDE_REFLECTIONS": PIXEL_INSIDE_REFLECTIONS}
    info.compute_source(glsl_source("glass_rays.glsl", defines, prelude))
    return gpu.shader.create_from_info(info)


class GlassRays:
    """The per-pixel paths of one renderer's searched glass: RGBA32F textures of the
    view's size (:attr:`exits`: exit point and status; :attr:`leaving`: the leaving ray,
    and the glass's bounding radius, negative where dark; :attr:`entries`: the entry's
    direction from the glass's centre, and the glass's id), made again when the size
    changes."""

    def __init__(self):
        self.exits = None
        self.leaving = None
        self.entries = None
        self._size = None

    def trace(self, frame, methods, atlas, shift) -> None:
        """The paths of ``frame`` (``frame_pass.Frame``, its pre-pass drawn) through each
        glass of ``methods`` (``refraction_search.RefractedGlass``, the ``k``-th the
        ``k``-th map of ``atlas``): reflected inside where they must and the glass
        reflects, else dark there."""
        view, targets = frame.view, frame.targets
        size = (targets.width, targets.height)
        if self._size != size:
            for attribute, _ in PATHS:
                setattr(self, attribute, gpu.types.GPUTexture(size, format='RGBA32F'))
            self._size = size
        for attribute, _ in PATHS:
            getattr(self, attribute).clear(format='FLOAT', value=(0.0, 0.0, 0.0, 0.0))
        shader = rays_shader()
        shader.bind()
        shader.uniform_float("inverse_view_projection", frame.world_to_clip.inverted())
        shader.uniform_float("camera", camera_position(view, shift))
        shader.uniform_float("view_size", (float(size[0]), float(size[1])))
        shader.uniform_sampler("reflector_maps", atlas.texture)
        shader.uniform_sampler("map_params", atlas.params)
        shader.uniform_sampler("prepass_labels", targets.prepass_labels)
        for attribute, name in PATHS:
            shader.image(name, getattr(self, attribute))
        groups = (-(-size[0] // LOCAL_SIZE), -(-size[1] // LOCAL_SIZE), 1)
        for k, method in enumerate(methods):
            shader.uniform_float("eta", float(method.ior))
            shader.uniform_float("glass_id", float(method.index + 1))
            shader.uniform_int("self_map", k)
            shader.uniform_int("reflects", int(bool(method.reflects)))
            gpu.compute.dispatch(shader, *groups)

    @property
    def textures(self) -> tuple:
        """(exits, leaving): what the refracted meshes' ray cast reads."""
        return self.exits, self.leaving

    def draw_settled(self) -> None:
        """Into the bound reflection target, before the refracted meshes: black where the
        last paths marked it dark."""
        if self.leaving is not None:
            draw_settled(dark_rays=self.leaving)

    def read(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The last paths read back, rows bottom up: (H, W, 3) exit points (relative to
        the shift), (H, W) int statuses, (H, W, 3) leaving rays, (H, W) dark marks."""
        width, height = self._size
        exits = read_texture(self.exits, width, height).reshape(height, width, 4)
        leaving = read_texture(self.leaving, width, height).reshape(height, width, 4)
        return exits[..., :3], np.rint(exits[..., 3]).astype(int), leaving[..., :3], leaving[..., 3] < 0.0
