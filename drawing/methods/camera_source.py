# SPDX-License-Identifier: GPL-3.0-or-later
"""A sample-based camera as a projection source that projects on the CPU.

``CameraTriangleMaker.triangles`` projects the renderer's vertices with a source and
decides the reflected triangles from what it gives (SBC paper, Popescu, Sacks, Mei
2006, sections V-A and V-B). With the camera's GPU textures (``sbc_gpu.SBCTextures``)
that needs the GPU, so the main thread; with :class:`CameraSource` it is numpy only
(``SampleBasedCamera.project``, whose GLSL twin the GPU pass runs: the same answers,
docs/benchmarks/projection_rate.md), so the live view's worker thread makes a landing
camera's reflected triangles right after building it, and the main thread only puts
them on the GPU (``CameraPass.adopt``).
"""

from __future__ import annotations

import numpy as np

from .reflected_depth import reflected_depth


class CameraSource:
    """``sbc`` (a ``SampleBasedCamera``) projecting with numpy, as the GPU pass writes
    its targets (``glsl/reflection_project_vert.glsl``)."""

    #: Projects in numpy: no point batch, ``positions`` themselves.
    on_gpu = False
    #: Mixed triangles use the renderer's sub-grids.
    sheet_subdivisions = None

    def __init__(self, sbc):
        self.sbc = sbc
        self.groups = sbc.groups
        self.downsample = sbc.ray_map.downsample
        self.view = sbc.ray_map.view

    def project(self, maker, positions, batch, draws: list, n_texels: int, setup: dict, static: bool = False,
                camera=None):
        """Per (group, order, texel offset, first, count) of ``draws``, points first ..
        first + count - 1 of ``positions`` into texels offset + index: (pixel, depth,
        leaf kind) and (eye vector, reflected distance), 0 where a point does not
        project; ``batch`` is not used. Each point is projected once, in every group
        (the camera culls groups by their cones), and polished on the true rays where
        ``maker.polish`` asks, as the GPU pass's read-back is (``camera`` is its own)."""
        points = np.zeros((n_texels, 4), np.float32)
        eyes = np.zeros((n_texels, 4), np.float32)
        if not draws:
            return points, eyes
        positions = np.asarray(positions, np.float64)
        wanted = np.zeros(len(positions), bool)
        for _, _, _, first, count in draws:
            wanted[first:first + count] = True
        rows = np.flatnonzero(wanted)
        result = self.sbc.project(positions[rows], polish=maker.polish)
        for group, order, offset, first, count in draws:
            at = np.arange(np.searchsorted(rows, first), np.searchsorted(rows, first + count))
            at = at[result.valid[group, at]]
            vertex = rows[at]
            texels = offset + vertex
            distance = result.ray_distance[group, at]
            points[texels] = np.c_[result.pixels[group, at], reflected_depth(order, distance, setup),
                                   result.leaf_kind[group, at]]
            eyes[texels] = np.c_[result.reflector_points[group, at] - positions[vertex], distance]
        return points, eyes
