# SPDX-License-Identifier: GPL-3.0-or-later
"""Polish Node Images on the GPU: ``glsl/image_polish.glsl``, the float32 twin of
``engine/methods/morphing/image_polish.polish_images`` (``MorphingGrid.image_polish``).

In numpy the polish costs more than the node's projection itself (a BVH descent per
image to find its triangle, then Newton in float64), too much for an animation's
frames. Here one dispatch answers every image of a node (milliseconds): the shader
walks from a grid cell's triangle across the mirror's edges instead of descending a
BVH, so it needs two flat tables of the mirror (``ReflectorSet.triangle_grid``,
``ReflectorSet.edge_neighbours``), uploaded once per mirror
(docs/benchmarks/morphing.md). Triangle indices travel as float32, exact below 2**24
triangles.
"""

from __future__ import annotations

from collections import OrderedDict

import gpu
import numpy as np

from ...engine.methods.morphing.image_polish import FRAME_POLISH_ROUNDS
from ...engine.reference import exact
from ..gpu_data import data_texture, read_texture
from ..shader_sources import glsl_source
from ..shader_cache import cached_shader

#: Invocations per work group (along x).
LOCAL_SIZE = 64
#: Mirrors whose tables stay on the GPU.
MIRRORS_KEPT = 4
#: Result texels per row.
WORK_WIDTH = 1024
#: Triangles tried per image, as ``image_polish.POLISH_ROUNDS``: the one under the image,
#: then the one under Newton's root while it lies outside the triangle it was found in.
ROUNDS = 4
#: Newton iterations per triangle (the numpy twin's ``POLISH_ITERATIONS``; float32
#: converges no further after these).
ITERATIONS = 10
#: Edges crossed, at most, from a grid cell's triangle to the one under a point (a
#: cell's triangle lies up to ``triangle_grid.MAX_DILATION`` cells off, a cell a few
#: edges long on a dense mirror).
LOCATE_STEPS = 64
#: Central differences of the residual, in barycentric units (float32: 1e-7 would round away).
DIFFERENCE_STEP = 1e-3
#: A step is at most half a triangle, as in ``exact.newton_in_triangles``.
MAX_STEP = 0.5
#: A point lies in a triangle where no barycentric weight is below minus this.
INSIDE_TOLERANCE = 1e-4
#: Converged: a step shorter than this (barycentric units) ...
STEP_TOLERANCE = 1e-6
#: ... and, to be kept, a residual (unit vectors' difference) below this: about 1e-4 of
#: a radian, 1e-4 of the mirror's curvature radius along the surface.
RESIDUAL_TOLERANCE = 1e-4


def polish_defines() -> dict:
    return {"ROUNDS": ROUNDS, "ITERATIONS": ITERATIONS, "LOCATE_STEPS": LOCATE_STEPS,
            "DIFFERENCE_STEP": f"{DIFFERENCE_STEP:.9e}", "MAX_STEP": f"{MAX_STEP:.9e}",
            "STEP_TOLERANCE": f"{STEP_TOLERANCE:.9e}", "RESIDUAL_TOLERANCE": f"{RESIDUAL_TOLERANCE:.9e}",
            "INSIDE_TOLERANCE": f"{INSIDE_TOLERANCE:.9e}", "BACKTRACK_HALVINGS": exact.BACKTRACK_HALVINGS,
            "ABANDON_DISTANCE": f"{exact.ABANDON_DISTANCE:.9e}", "ABANDON_AFTER": exact.ABANDON_AFTER}


@cached_shader
def polish_shader(frame_answers: bool = False):
    """The compute shader of the polish, built on first use: of a list of (point, image)
    rows into a result texture, or with ``frame_answers`` of a frame's answer texture in
    place (``FRAME_ANSWERS``: each vertex's blended answer, up to FRAME_POLISH_ROUNDS
    triangles from it)."""
    width, rows, result, access = (("positions_width", "vertex_positions", "answers", {'READ', 'WRITE'})
                                   if frame_answers else ("work_width", "work", "result", {'WRITE'}))
    info = gpu.types.GPUShaderCreateInfo()
    for name in ("n_rows", width, "mirror_width", "cells_width"):
        info.push_constant('INT', name)
    for slot, name in enumerate((rows, "mirror", "cells", "params")):
        info.sampler(slot, 'FLOAT_2D', name)
    info.image(0, 'RGBA32F', 'FLOAT_2D', result, qualifiers=access)
    info.local_group_size(LOCAL_SIZE, 1)
    defines = polish_defines()
    if frame_answers:
        defines.update(ROUNDS=FRAME_POLISH_ROUNDS, FRAME_ANSWERS=1)
    info.compute_source(glsl_source("image_polish.glsl", defines))
    return gpu.shader.create_from_info(info)


def polish_answers(tables: tuple, eye, to_mirror: np.ndarray, meshes, answers) -> None:
    """Polish a frame's answer textures ``answers`` (one per image slot; ``meshes``: the
    renderer's ``ReflectedMeshes``, whose vertices they answer) in place on the mirror of
    ``tables`` (:meth:`GPUImagePolish.tables`), seen from ``eye``; ``to_mirror`` (4, 4)
    maps the renderer's coordinates to the mirror's (``eye`` is in them). An answer not
    placed is dropped."""
    centre, grid_rows = tables[2:]
    to_table = np.eye(4)
    to_table[:3, 3] = -centre
    to_table = to_table @ to_mirror
    params = data_texture(np.array([[*(np.asarray(eye, dtype=np.float64) - centre), 0.0], *grid_rows,
                                    *to_table[:3], *np.linalg.inv(to_table)[:3]]))
    for texture in answers:
        _dispatch_polish(tables, params, meshes.n_vertices, meshes.width, meshes.positions, texture,
                         meshes.work_groups(LOCAL_SIZE), frame_answers=True)


def _dispatch_polish(tables: tuple, params, n_rows: int, width: int, rows, result, groups: tuple,
                     frame_answers: bool = False) -> None:
    """One dispatch of :func:`polish_shader` over ``n_rows`` rows ``width`` to a texel
    row of ``rows`` (the work rows, or the vertices' positions), into ``result``."""
    mirror_texture, cells_texture = tables[:2]
    shader = polish_shader(frame_answers)
    shader.bind()
    shader.uniform_int("n_rows", n_rows)
    shader.uniform_int("positions_width" if frame_answers else "work_width", width)
    shader.uniform_int("mirror_width", mirror_texture.width)
    shader.uniform_int("cells_width", cells_texture.width)
    shader.uniform_sampler("vertex_positions" if frame_answers else "work", rows)
    shader.uniform_sampler("mirror", mirror_texture)
    shader.uniform_sampler("cells", cells_texture)
    shader.uniform_sampler("params", params)
    shader.image("answers" if frame_answers else "result", result)
    gpu.compute.dispatch(shader, *groups)


def mirror_texels(mirror, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T * 6, 4) the shader's ``mirror`` table, relative to ``centre`` (corners with the
    neighbours across the opposite edges, corner normals, the first with the triangle's
    ``closed_sides``), and the grid's cells four to a texel ((C / 4, 4), -1 where empty)."""
    texels = np.zeros((len(mirror.triangles), 6, 4), np.float32)
    texels[:, :3, :3] = mirror.vertices[mirror.triangles] - centre
    texels[:, :3, 3] = mirror.edge_neighbours
    texels[:, 3:, :3] = mirror.normals[mirror.triangles]
    texels[:, 3, 3] = mirror.closed_sides
    cells = mirror.triangle_grid.cells.reshape(-1).astype(np.float32)
    cells = np.concatenate([cells, np.full(-len(cells) % 4, -1.0, np.float32)]).reshape(-1, 4)
    return texels.reshape(-1, 4), cells


def mirror_centre(mirror) -> np.ndarray:
    """The centre of the mirror's box: the shader's positions are relative to it (float32)."""
    lo, hi = mirror.vertices.min(axis=0), mirror.vertices.max(axis=0)
    return 0.5 * (lo + hi)


class GPUImagePolish:
    """``image_polish.polish_images`` on the GPU, for a grid's ``image_polish``: a
    mirror's tables are uploaded on first use and kept (the last ``capacity`` mirrors:
    one per reflector in a grid mode). Needs the GPU: call from the main thread."""

    def __init__(self, capacity: int = MIRRORS_KEPT):
        self.capacity = int(capacity)
        self._tables_of: OrderedDict = OrderedDict()  # id(mirror) -> (mirror, textures)
        self.dispatches = 0

    def __call__(self, mirror, eye, points, images) -> np.ndarray:
        """(P, K, 3) as ``polish_images(mirror, eye, points, images)``."""
        rows, slots = np.nonzero(np.isfinite(images[..., 0]))
        polished = np.full(images.shape, np.nan)
        if len(rows) == 0:
            return polished
        tables = self.tables(mirror)
        centre = tables[2]
        found = self._dispatch(tables, np.asarray(eye, dtype=np.float64) - centre,
                               points[rows] - centre, images[rows, slots] - centre)
        placed = found[:, 3] > 0.5
        polished[rows[placed], slots[placed]] = found[placed, :3].astype(np.float64) + centre
        return polished

    def tables(self, mirror) -> tuple:
        """(mirror texture, cells texture, centre, the grid's two rows of ``params``) of
        a mirror, made and uploaded on first use; the last ``capacity`` mirrors kept."""
        entry = self._tables_of.pop(id(mirror), None)
        if entry is None or entry[0] is not mirror:
            centre = mirror_centre(mirror)
            texels, cells = mirror_texels(mirror, centre)
            grid = mirror.triangle_grid
            grid_rows = [[*(grid.origin - centre), grid.cell], [*grid.shape, 0.0]]
            entry = (mirror, (data_texture(texels), data_texture(cells), centre, grid_rows))
            while len(self._tables_of) >= self.capacity:
                self._tables_of.popitem(last=False)
        self._tables_of[id(mirror)] = entry
        return entry[1]

    def _dispatch(self, tables: tuple, eye, points, images) -> np.ndarray:
        """(R, 4) float32: (reflection point, 1) of each row, else zeros; positions
        relative to the centre in ``tables`` (:meth:`tables`)."""
        params = data_texture(np.array([[*eye, 0.0], *tables[3]]))
        n_rows = len(points)
        width = min(WORK_WIDTH, n_rows)
        height = -(-n_rows // width)
        work = np.zeros((height * width, 2, 4), np.float32)
        work[:n_rows, 0, :3], work[:n_rows, 1, :3] = points, images
        work_texture = data_texture(work.reshape(height, 2 * width, 4))
        result = gpu.types.GPUTexture((width, height), format='RGBA32F')
        _dispatch_polish(tables, params, n_rows, width, work_texture, result, (-(-width // LOCAL_SIZE), height, 1))
        self.dispatches += 1
        return read_texture(result, width, height).reshape(-1, 4)[:n_rows]

