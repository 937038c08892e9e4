# SPDX-License-Identifier: GPL-3.0-or-later
"""The float targets one frame is drawn into (``reflection_draw.py``): the pre-pass's
colours, labels, normals and depth, the reflections' colours and depth, and the
composite's output, made once per frame size and reused from frame to frame."""

from __future__ import annotations

import gpu
import numpy as np


class FrameTargets:
    """Float textures and framebuffers of one frame size (reusable from frame to frame)."""

    def __init__(self, width: int, height: int):
        self.width, self.height = int(width), int(height)
        size = (self.width, self.height)
        self.prepass_colors = gpu.types.GPUTexture(size, format='RGBA32F')
        self.prepass_labels = gpu.types.GPUTexture(size, format='RGBA32F')
        #: The smooth normal of the surface each pixel shows (the mirrors' for the
        #: reflected meshes' law-of-reflection test; float32: a traced mirror pixel is
        #: reflected about it, ``methods/traced_pass.py``).
        self.prepass_normals = gpu.types.GPUTexture(size, format='RGBA32F')
        self.prepass_depth = gpu.types.GPUTexture(size, format='DEPTH_COMPONENT32F')
        self.prepass = gpu.types.GPUFrameBuffer(depth_slot=self.prepass_depth,
                                                color_slots=(self.prepass_colors, self.prepass_labels,
                                                             self.prepass_normals))
        self.reflection_colors = gpu.types.GPUTexture(size, format='RGBA32F')
        self.reflection_depth = gpu.types.GPUTexture(size, format='DEPTH_COMPONENT32F')
        self.reflection = gpu.types.GPUFrameBuffer(depth_slot=self.reflection_depth,
                                                   color_slots=(self.reflection_colors,))
        zero = np.zeros(4, np.float32)
        self.no_trace = gpu.types.GPUTexture((1, 1), format='RGBA32F', data=gpu.types.Buffer('FLOAT', 4, zero))
        self.traced = None  # RGBA32F of the traced band of the last frame, or None
        #: RGBA32F of what the reflector pixels show beneath their drawn images, where a
        #: pass made it this frame (glass's traced reflections), else None: their colours.
        self.beneath = None
        #: (x, y, width, height): the pixels the last frame cleared and drew (an overlay's
        #: scissor); None: all of them. The rest hold an older frame's values.
        self.box = None
        self._output = None

    def fits(self, width: int, height: int) -> bool:
        return (self.width, self.height) == (int(width), int(height))

    @property
    def output(self):
        """(texture, framebuffer) that :meth:`ReflectionRenderer.render` composites into."""
        if self._output is None:
            texture = gpu.types.GPUTexture((self.width, self.height), format='RGBA32F')
            self._output = (texture, gpu.types.GPUFrameBuffer(color_slots=(texture,)))
        return self._output

    def outside_box(self) -> np.ndarray:
        """(height, width) bool: the pixels the last frame left alone (:attr:`box`)."""
        outside = np.zeros((self.height, self.width), dtype=bool)
        if self.box is not None:
            x, y, width, height = self.box
            outside[:] = True
            outside[y:y + height, x:x + width] = False
        return outside
