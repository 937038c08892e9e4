# SPDX-License-Identifier: GPL-3.0-or-later
"""The morphing blend in numpy as a projection source of the reflection renderer.

In reflection-morphing mode (Popescu, Sacks, Mei 2006, section VI) the extension projects
each grid node's images on the GPU and blends them there every frame
(``drawing/methods/morph_pass.py``). :class:`MorphSource` is the earlier path, kept as
the numpy reference the benchmarks compare with (``tests/benchmarks/bench_view_change.py``)
and not shipped: it hands the blended points of one view to
``drawing.reflection_draw.ReflectionRenderer`` in the layout of its GPU projection pass
(``drawing/glsl/reflection_project_vert.glsl``), so the renderer draws them as it draws
a runtime camera's (whole and mixed triangles); the matching of images across nodes and the
blend run in numpy, and the renderer's own vertices are *static points* whose four node
images are kept while the eye stays in one tetrahedron.
"""

from __future__ import annotations

import numpy as np

from ..drawing.methods.morph_pass import SLOTS
from ..drawing.methods.reflected_depth import reflected_depth

#: Images of one point in one reflector drawn at most (sheets per grid), as on the GPU.
MAX_IMAGES = SLOTS
#: Largest sub-grid of a mixed triangle (SBC V-B) drawn from a grid: every sub-vertex is
#: morphed from scratch (node projections, matching, blend), tens of microseconds each in
#: numpy, where the GPU projects a runtime camera's for almost nothing. 8 keeps the
#: reflection's edge within an eighth of a triangle.
MIXED_SUBDIVISIONS = 8


class MorphSource:
    """First-order reflections of some reflectors from their baked grids, for one view.

    ``grids``: (``MorphingGrid``, the reflector's object matrix) pairs, each grid's
    ``reflector_index`` its index among the renderer's reflectors; ``view``: the
    perspective view inside every grid (``MorphingGrid.locate_view``). Each grid gives
    :data:`MAX_IMAGES` sheets of the history ``(reflector_index,)``; an image's sheet is
    its rank in the blend (``MorphProjection``), so one sheet is one image of a point.
    """

    #: Projects in numpy: no point batch, ``positions`` themselves.
    on_gpu = False

    def __init__(self, grids, view, max_images: int = MAX_IMAGES):
        self.grids = list(grids)
        self.view = view
        self.max_images = int(max_images)
        self.groups = [(grid.reflector_index,) for grid, _ in self.grids for _ in range(self.max_images)]
        self.downsample = 1  # a vertex's image is blended on its own, not read from a ray map
        self.sheet_subdivisions = [MIXED_SUBDIVISIONS] * len(self.groups)

    def project(self, maker, positions, batch, draws: list, n_texels: int, setup: dict, static: bool = False,
                camera=None):
        """(n_texels, 4) (pixel, depth, valid) and (eye vector, reflected distance) per
        drawn texel, as the renderer's GPU pass writes them; ``batch`` is not used."""
        points = np.zeros((n_texels, 4), np.float32)
        eyes = np.zeros((n_texels, 4), np.float32)
        positions = np.asarray(positions, np.float64)
        blended = {}
        for group, order, offset, first, count in draws:
            grid_index, image = divmod(int(group), self.max_images)
            key = (grid_index, int(first), int(count))
            if key not in blended:
                grid, matrix = self.grids[grid_index]
                static_key = (maker.vertices_token, key[1:]) if static else None
                blended[key] = grid.project(positions[first:first + count], self.view, matrix,
                                            static_key=static_key)
            result = blended[key]
            if image >= len(result.groups):
                continue
            valid = result.valid[image]
            rows = np.flatnonzero(valid)
            texels = offset + first + rows
            distance = result.ray_distance[image, rows]
            points[texels] = np.c_[result.pixels[image, rows], reflected_depth(order, distance, setup),
                                   np.ones(len(rows))]
            eyes[texels] = np.c_[result.reflector_points[image, rows] - positions[first + rows], distance]
        return points, eyes
