# SPDX-License-Identifier: GPL-3.0-or-later
"""Morphing grids' node projections on the GPU.

In reflection-morphing mode (Popescu, Sacks, Mei 2006, section VI) a reflector's
reflections come from the panoramic sample-based cameras baked at the nodes of a
tetrahedral grid around it: the four nodes of the tetrahedron holding the eye project
each vertex, and their first reflector points are blended (:mod:`...engine.methods.morphing`).
:class:`GPUFaceImages` runs the nodes' projections, the expensive part, on the GPU with
the GLSL twin of ``SampleBasedCamera.project``; the live view and Render Image project
their nodes with it once per node and blend on the GPU every frame
(:mod:`.morph_pass`).

The earlier path, the blend in numpy handed to the renderer as a projection source, is
kept outside the zip as the benchmarks' reference (``tools/numpy_morph_source.py``).
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np

from . import sbc_gpu

#: Face cameras kept packed in GPU textures (a tetrahedron uses four nodes of six faces).
PACKED_FACES = 48


class GPUFaceImages:
    """A node's cube-face cameras projecting on the GPU (``MorphingGrid.face_images``).

    Each face SBC is packed into textures once (:class:`.sbc_gpu.SBCTextures`, the
    last :data:`PACKED_FACES` kept) and projects with :func:`.sbc_gpu.project_points`;
    the first reflector point is the face pixel's view ray at the projected depth, as
    ``SampleBasedCamera.project`` gives it. Needs the GPU: call from the main thread.
    """

    def __init__(self, capacity: int = PACKED_FACES):
        self.capacity = int(capacity)
        self._packed: OrderedDict = OrderedDict()  # id(sbc) -> (sbc, textures)
        self.packs = 0

    def __call__(self, sbc, points) -> np.ndarray:
        entry = self._packed.pop(id(sbc), None)
        if entry is None or entry[0] is not sbc:
            entry = (sbc, sbc_gpu.SBCTextures(sbc))
            self.packs += 1
            while len(self._packed) >= self.capacity:
                self._packed.popitem(last=False)
        self._packed[id(sbc)] = entry
        result = sbc_gpu.project_points(entry[1], points)
        images = np.full(result.pixels.shape[:2] + (3,), np.nan)
        if result.valid.any():
            origins, directions = sbc.ray_map.view.pixel_rays(result.pixels[result.valid])
            images[result.valid] = origins + result.first_depth[result.valid][:, None] * directions
        return images
