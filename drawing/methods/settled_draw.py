# SPDX-License-Identifier: GPL-3.0-or-later
"""Pixels whose reflection is settled per pixel, drawn before any reflected mesh.

A trace on the GPU (``glass_trace.py`` through glass, ``traced_pass.py`` off mirrors)
knows each of its pixels' colour exactly; glass that does not reflect shows black where
it must reflect totally (``glass_rays.py``). One full-screen triangle writes those
pixels into the bound reflection target at depth 0, which no reflected mesh drawn after
it passes, and discards the rest.
"""

from __future__ import annotations

import gpu
import numpy as np

from ..gpu_data import vertex_buffer
from ..shader_cache import cached_shader

#: The alpha of a traced pixel whose ray meets nothing: the composite shows the world there.
MISSED = 0.25


@cached_shader
def settled_shader():
    """Black where ``dark_rays`` w is negative, the traced colour where ``traced_colors``
    alpha is above 0.5, nothing drawn (the world shows) where it is :data:`MISSED`, each
    at depth 0; elsewhere discarded. Built on first use."""
    info = gpu.types.GPUShaderCreateInfo()
    info.sampler(0, 'FLOAT_2D', "dark_rays")
    info.sampler(1, 'FLOAT_2D', "traced_colors")
    info.vertex_in(0, 'VEC2', "position")
    info.fragment_out(0, 'VEC4', "color_out")
    info.depth_write('ANY')
    info.vertex_source("void main()\n{\n  gl_Position = vec4(position, 0.0, 1.0);\n}\n")
    # Alpha 1: a drawn reflection at distance 0, which the composite does not fade; a
    # traced one keeps its alpha, 1 + its distance.
    info.fragment_source(
        "void main()\n{\n  ivec2 pixel = ivec2(gl_FragCoord.xy);\n"
        "  vec4 traced = texelFetch(traced_colors, min(pixel, textureSize(traced_colors, 0) - 1), 0);\n"
        "  if (texelFetch(dark_rays, min(pixel, textureSize(dark_rays, 0) - 1), 0).w < 0.0) {\n"
        "    color_out = vec4(0.0, 0.0, 0.0, 1.0);\n  }\n"
        "  else if (traced.a > 0.5) {\n    color_out = traced;\n  }\n"
        "  else if (traced.a > 0.0) {\n    color_out = vec4(0.0);\n  }\n"
        "  else {\n    discard;\n  }\n  gl_FragDepth = 0.0;\n}\n")
    return gpu.shader.create_from_info(info)


@cached_shader  # a GPU object, released with the shaders
def _screen():
    corners = np.array([[-1.0, -1.0], [3.0, -1.0], [-1.0, 3.0]], np.float32)
    return gpu.types.GPUBatch(type='TRIS', buf=vertex_buffer({"position": (corners, 'F32', 'FLOAT')}))


@cached_shader  # a GPU object, released with the shaders
def _nothing():
    """A 1 x 1 texture of zeros: no pixel dark, none traced."""
    texture = gpu.types.GPUTexture((1, 1), format='RGBA32F')
    texture.clear(format='FLOAT', value=(0.0, 0.0, 0.0, 0.0))
    return texture


def draw_settled(traced=None, dark_rays=None) -> None:
    """Into the bound reflection target (depth test on, as the passes draw): the colours of
    ``traced`` (RGBA32F of the view's size; None: none) where traced, and black where the
    w of ``dark_rays`` (RGBA32F of the view's size; None: none) is negative."""
    shader = settled_shader()
    shader.bind()
    shader.uniform_sampler("dark_rays", _nothing() if dark_rays is None else dark_rays)
    shader.uniform_sampler("traced_colors", _nothing() if traced is None else traced)
    gpu.state.depth_test_set('ALWAYS')
    _screen().draw(shader)
    gpu.state.depth_test_set('LESS')
