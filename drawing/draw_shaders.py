# SPDX-License-Identifier: GPL-3.0-or-later
"""The renderer's shaders (``reflection_draw.py``): pre-pass, vertex projection with a
sample-based camera, reflected meshes and composite, each built from ``glsl/`` on first
use and cached (never at import or register time).

Push constants stay far below the 128 bytes Vulkan guarantees
(:data:`PUSH_CONSTANT_BYTES`); the cameras travel in textures (``sbc_gpu.SBCTextures``).
"""

from __future__ import annotations


import gpu

from ..engine.geometry import band_trace
from .methods import sbc_gpu
from .shader_sources import glsl_source
from .shader_cache import cached_shader

#: Bytes of push constants per shader (Vulkan guarantees 128): the pre-pass's matrix is
#: the largest; everything bigger (the cameras, the pre-pass images) is in textures.
PUSH_CONSTANT_BYTES = {
    "prepass": 64 + 16 + 4,  # mat4 view_projection; vec4 camera; int use_image
    # mat4 inverse_view_projection; vec2 view_size; int group, order, layer_offset; ivec2 target_size;
    # float inverse_diameter, order_range
    "project": 64 + 8 + 4 + 4 + 4 + 8 + 4 + 4,
    # mat4 view_projection; vec4 camera; vec2 view_size, snap_grid; int use_camera_pixel, use_image;
    # float order_range, reflection_cosine
    "reflected": 64 + 16 + 8 + 8 + 4 + 4 + 4 + 4,
    # vec4 world_color, rect; int reflectors_only, fill_radius; ivec2 origin; vec2 depth_bias
    "composite": 16 + 16 + 4 + 4 + 8 + 8,
}
_COMPOSITE_VERTEX = """
/* A unit square drawn over `rect` (normalised device coordinates: x0, y0, x1, y1). */
void main()
{
  gl_Position = vec4(mix(rect.xy, rect.zw, position), 0.0, 1.0);
}
"""



def shader(name: str):
    """The renderer's shader ``name`` (prepass, project, reflected, composite), built on
    first use and cached."""
    return _BUILDERS[name]()


def shading_source() -> str:
    """``glsl/reflection_shading.glsl`` behind its ``#define``."""
    return f"#define SHADE_AMBIENT {band_trace.SHADE_AMBIENT:.9e}\n" + glsl_source("reflection_shading.glsl")


@cached_shader
def _build_prepass():
    interface = gpu.types.GPUStageInterfaceInfo("curved_reflections_prepass_interface")
    interface.smooth('VEC4', "color_interp")
    interface.flat('VEC4', "label_interp")
    interface.smooth('VEC3', "normal_interp")
    interface.flat('FLOAT', "lit_interp")
    interface.smooth('VEC2', "uv_interp")
    interface.smooth('VEC3', "position_interp")
    info = gpu.types.GPUShaderCreateInfo()
    info.push_constant('MAT4', "view_projection")
    info.push_constant('VEC4', "camera")
    info.push_constant('INT', "use_image")
    info.sampler(0, 'FLOAT_2D', "image")
    info.vertex_in(0, 'VEC3', "position")
    info.vertex_in(1, 'VEC4', "color")
    info.vertex_in(2, 'VEC4', "label")
    info.vertex_in(3, 'VEC4', "normal_lit")
    info.vertex_in(4, 'VEC2', "uv")
    info.vertex_out(interface)
    info.fragment_out(0, 'VEC4', "color_out")
    info.fragment_out(1, 'VEC4', "label_out")
    info.fragment_out(2, 'VEC4', "normal_out")
    info.vertex_source(glsl_source("reflection_prepass_vert.glsl"))
    info.fragment_source(shading_source() + glsl_source("reflection_prepass_frag.glsl"))
    return gpu.shader.create_from_info(info)


@cached_shader
def _build_project():
    interface = gpu.types.GPUStageInterfaceInfo("curved_reflections_project_interface")
    interface.flat('VEC4', "projected")
    interface.flat('VEC4', "projected_eye")
    info = gpu.types.GPUShaderCreateInfo()
    info.push_constant('MAT4', "inverse_view_projection")
    info.push_constant('VEC2', "view_size")
    info.push_constant('INT', "group")
    info.push_constant('INT', "order")
    info.push_constant('INT', "layer_offset")
    info.push_constant('IVEC2', "target_size")
    info.push_constant('FLOAT', "inverse_diameter")
    info.push_constant('FLOAT', "order_range")
    sbc_gpu.declare_samplers(info)
    info.vertex_in(0, 'VEC3', "position")
    info.vertex_out(interface)
    info.fragment_out(0, 'VEC4', "projected_out")
    info.fragment_out(1, 'VEC4', "eye_out")
    info.vertex_source(sbc_gpu.library_source() + shading_source() + glsl_source("reflection_project_vert.glsl"))
    info.fragment_source(glsl_source("reflection_project_frag.glsl"))
    return gpu.shader.create_from_info(info)


def reflected_interface(name: str, searched: bool = False, refracted: bool = False):
    """The varyings of a reflected-mesh vertex stage, read by ``glsl/reflection_mesh_frag.glsl``;
    ``searched`` adds the per-frame passes' interpolated validity, ``refracted`` the point
    of the mesh (relative to the shift), its barycentric coordinates in its triangle and
    the index of its mesh, for the refraction test."""
    interface = gpu.types.GPUStageInterfaceInfo(name)
    interface.smooth('VEC4', "color_interp")
    interface.smooth('VEC3', "normal_interp")
    interface.smooth('VEC3', "eye_interp")
    interface.smooth('VEC2', "uv_interp")
    interface.smooth('FLOAT', "distance_interp")
    interface.flat('FLOAT', "lit_interp")
    interface.flat('FLOAT', "reflector_interp")
    interface.smooth('VEC3', "mirror_point_interp")
    interface.flat('FLOAT', "first_order_interp")
    if searched:
        interface.smooth('FLOAT', "valid_interp")
    if refracted:
        interface.smooth('VEC3', "mesh_point_interp")
        interface.smooth('VEC3', "barycentric_interp")
        interface.flat('INT', "mesh_interp")
    return interface


def reflected_fragment_source(defines: str = "") -> str:
    """``glsl/reflection_mesh_frag.glsl`` behind ``defines`` and the shading functions."""
    return defines + shading_source() + glsl_source("reflection_mesh_frag.glsl")


@cached_shader
def _build_reflected():
    interface = reflected_interface("curved_reflections_reflected_interface")
    info = gpu.types.GPUShaderCreateInfo()
    info.push_constant('MAT4', "view_projection")
    info.push_constant('VEC4', "camera")
    info.push_constant('VEC2', "view_size")
    info.push_constant('VEC2', "snap_grid")
    info.push_constant('INT', "use_camera_pixel")
    info.push_constant('INT', "use_image")
    info.push_constant('FLOAT', "order_range")
    info.push_constant('FLOAT', "reflection_cosine")
    info.sampler(0, 'FLOAT_2D', "prepass_labels")
    info.sampler(1, 'FLOAT_2D', "image")
    info.sampler(2, 'FLOAT_2D', "prepass_normals")
    info.vertex_in(0, 'VEC4', "world_depth")
    info.vertex_in(1, 'VEC4', "pixel_reflector")
    info.vertex_in(2, 'VEC4', "eye_distance")
    info.vertex_in(3, 'VEC4', "color")
    info.vertex_in(4, 'VEC4', "normal_lit")
    info.vertex_in(5, 'VEC2', "uv")
    info.vertex_out(interface)
    info.fragment_out(0, 'VEC4', "color_out")
    info.vertex_source(shading_source() + glsl_source("reflection_mesh_vert.glsl"))
    info.fragment_source(reflected_fragment_source())
    return gpu.shader.create_from_info(info)


@cached_shader
def _build_composite():
    info = gpu.types.GPUShaderCreateInfo()
    info.push_constant('VEC4', "world_color")
    info.push_constant('VEC4', "rect")
    info.push_constant('INT', "reflectors_only")
    info.push_constant('INT', "fill_radius")
    info.push_constant('IVEC2', "origin")
    info.push_constant('VEC2', "depth_bias")
    info.sampler(0, 'FLOAT_2D', "prepass_colors")
    info.sampler(1, 'FLOAT_2D', "prepass_labels")
    info.sampler(2, 'FLOAT_2D', "reflection_colors")
    info.sampler(3, 'FLOAT_2D', "traced_colors")
    info.sampler(4, 'FLOAT_2D', "prepass_depth")
    info.sampler(5, 'FLOAT_2D', "prepass_normals")
    info.sampler(6, 'FLOAT_2D', "beneath_colors")
    info.vertex_in(0, 'VEC2', "position")
    info.fragment_out(0, 'VEC4', "color_out")
    info.depth_write('ANY')  # the pre-pass depth of each pixel, for the overlay's depth test
    info.vertex_source(_COMPOSITE_VERTEX)
    info.fragment_source(glsl_source("reflection_composite_frag.glsl"))
    return gpu.shader.create_from_info(info)


_BUILDERS = {"prepass": _build_prepass, "project": _build_project, "reflected": _build_reflected,
             "composite": _build_composite}

