# SPDX-License-Identifier: GPL-3.0-or-later
"""numpy arrays onto the GPU and back: vertex buffers, float data textures, their
read-back, and the draw state a pass restores.

Every pass of the renderer and of the per-frame methods moves its data through these:
per-vertex attributes as ``GPUVertBuf`` s, tables (cameras, maps, answers) as RGBA32F
textures with one texel per entry in rows of a fixed width.
"""

from __future__ import annotations

import contextlib

import gpu
import numpy as np

from .methods import sbc_pack


def vertex_buffer(attributes: dict):
    """A GPUVertBuf from {name: (array, comp_type, fetch_mode)}."""
    vertex_format = gpu.types.GPUVertFormat()
    count = None
    for name, (array, comp_type, fetch_mode) in attributes.items():
        width = 1 if array.ndim == 1 else array.shape[1]
        vertex_format.attr_add(id=name, comp_type=comp_type, len=width, fetch_mode=fetch_mode)
        count = len(array)
    buffer = gpu.types.GPUVertBuf(vertex_format, count)
    for name, (array, _, _) in attributes.items():
        buffer.attr_fill(name, np.ascontiguousarray(array))
    return buffer


def data_texture(values: np.ndarray, width: int | None = None):
    """An RGBA32F texture of ``values`` (N, <= 4) one texel each, rows of ``width``
    texels (default: up to the packer's texture width), or of an (H, W, 4) image."""
    values = np.asarray(values, dtype=np.float32)
    if values.ndim == 3:
        height, width = values.shape[:2]
        texels = values.reshape(-1, 4)
    else:
        texels = np.zeros((max(1, len(values)), 4), np.float32)
        texels[:len(values), :values.shape[1]] = values
        width = width or max(1, min(len(texels), sbc_pack.TEXTURE_WIDTH))
        height = -(-len(texels) // width)
        texels = np.concatenate([texels, np.zeros((width * height - len(texels), 4), np.float32)])
    data = gpu.types.Buffer('FLOAT', texels.size, np.ascontiguousarray(texels).reshape(-1))
    return gpu.types.GPUTexture((width, height), format='RGBA32F', data=data)


def read_texture(texture, width: int, height: int) -> np.ndarray:
    """(H, W, 4) float32 of an RGBA32F texture, rows bottom to top."""
    data = texture.read()
    data.dimensions = width * height * 4
    return np.asarray(data, dtype=np.float32).reshape(height, width, 4)


def read_depth(framebuffer, width: int, height: int) -> np.ndarray:
    """(H, W) float32 window depths of a framebuffer's depth attachment, rows bottom to
    top. Through ``GPUFrameBuffer.read_depth``: a depth texture's own ``read()`` returned
    its texels in another order on llvmpipe (none of row-major, flipped or transposed
    matched the depths of exactly traced points)."""
    with framebuffer.bind():
        data = framebuffer.read_depth(0, 0, width, height)
    data.dimensions = width * height
    return np.asarray(data, dtype=np.float32).reshape(height, width)


@contextlib.contextmanager
def saved_state():
    """Restore viewport, depth test, depth writes and blending (a draw handler's state)."""
    saved = (gpu.state.viewport_get(), gpu.state.depth_test_get(), gpu.state.depth_mask_get(),
             gpu.state.blend_get())
    try:
        yield
    finally:
        gpu.state.viewport_set(*saved[0])
        gpu.state.depth_test_set(saved[1])
        gpu.state.depth_mask_set(saved[2])
        gpu.state.blend_set(saved[3])


def points_batch(positions: np.ndarray):
    """A POINTS batch of (N, 3) float32 positions (the projection pass's input)."""
    return gpu.types.GPUBatch(type='POINTS', buf=vertex_buffer({"position": (positions, 'F32', 'FLOAT')}))
