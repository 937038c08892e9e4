# SPDX-License-Identifier: GPL-3.0-or-later
"""Sample-based camera projection on the GPU: the GLSL library and a point projector.

SBC paper (Popescu, Sacks, Mei 2006), section V-A: the reflected scene is rendered by
projecting every vertex with the sample-based camera *in the vertex shader*. This
module gives that projection to shaders:

- :func:`library_source` is ``glsl/sbc_projection.glsl`` (the GLSL twin of
  :meth:`engine.methods.sbc.sbc.SampleBasedCamera.project`) behind ``#define`` lines generated from
  the engine's own constants, so iteration counts and tolerances cannot drift apart;
- :func:`declare_samplers` adds its six samplers to a ``GPUShaderCreateInfo``;
- :class:`SBCTextures` packs one camera (:mod:`.sbc_pack`) into RGBA32F textures and
  binds them to a shader;
- :func:`project_points` projects points by drawing one point primitive per input
  point into a float target, one texel per point, and reads the texels back: the same
  answer as ``SampleBasedCamera.project``, used by the tests and benchmarks;
- :func:`polish_readback` polishes the renderer's projection pass's risky answers on
  the true rays, as the engine's numpy projection does.

Shaders are built on first use and cached, never at import or register time.

Float32 versus the engine's float64 (the only intended differences):

- Newton stops when a step moves (u, v) by less than :data:`STEP_TOLERANCE` instead of
  ``ray_patch.STEP_TOLERANCE`` (1e-9, below float32 resolution of chart coordinates);
  the engine tests this over a whole chunk of points, the shader per point, which
  changes nothing once a point has converged.
- A solve is accepted when its residual is below the engine's 1e-6 (|p| + 1) *or*
  below :data:`ROUNDING_TOLERANCE` (|p - origin| + |s|), four float32 roundings of the
  terms of t + s r - p. Converged float32 solves measure up to about one rounding, and
  about 2e-7 (|p| + 1), so the engine's test alone passes them in scenes of a few units;
  the floor keeps them passing where rays are long compared with |p| + 1 (large
  scenes seen near the world origin). Decisions can differ from the engine's only for
  solves whose float64 residual lies between the two tolerances (Newton not converged
  in its 8 iterations, a hair from the engine's threshold).
- Determinant and length guards are 1e-30 instead of 1e-300 (float32 range).
- Every other test (split planes, the segment's ends, cell bounds, the ranking of
  ray-list cells) keeps the engine's tolerance but is evaluated in float32, so a point
  within float32 rounding of such a boundary (about 1e-7 of the coordinates) can fall
  on the other side. Measured: 1 decision of 300,000 differed, a point 6e-7 beyond the
  engine's tolerance at its segment's head (tests/drawing/methods/test_sbc_gpu.py).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import gpu
import numpy as np

from ...engine.methods.sbc import ray_patch, sbc as sbc_module, sbc_cells
from ...engine.methods.sbc.bsp import CAMERA_LEAF, RAY_LIST_LEAF
from ..gpu_data import data_texture, points_batch
from ..shader_sources import glsl_source
from . import sbc_pack
from .reflected_depth import reflected_depth
from ..shader_cache import cached_shader

#: Newton's step tolerance on the GPU (chart coordinates span [-1, 1]; float32 resolves ~1e-7).
STEP_TOLERANCE = 1e-6
#: Residual tolerance factor (times |p| + 1), as ray_patch.project_patches and sbc._project_ray_lists.
RESIDUAL_TOLERANCE = 1e-6
#: Floor of the residual tolerance, times |p - origin| + |s|: four float32 roundings. Converged
#: float32 solves measure about one (the shader's Newton emulated in numpy float32, 34k solves).
ROUNDING_TOLERANCE = 4 * 2.0 ** -23
#: Margin (cells) around a camera leaf's member cells, as ray_patch.project_patches.
CELL_MARGIN = 0.5
#: Tolerance factor (times 1 + head distance) on the ray segment, as sbc._project_group.
DISTANCE_TOLERANCE = 1e-6

SAMPLERS = tuple(f"sbc_{name}" for name in sbc_pack.TEXTURE_NAMES)


def _float(value: float) -> str:
    return f"{float(value):.9e}"


def defines() -> dict:
    """The ``SBC_*`` constants of the GLSL library, from the engine and the packer."""
    return {
        "SBC_TEXTURE_WIDTH": str(sbc_pack.TEXTURE_WIDTH),
        "SBC_GROUP_TEXELS": str(sbc_pack.GROUP_TEXELS),
        "SBC_NODE_TEXELS": str(sbc_pack.NODE_TEXELS),
        "SBC_PATCH_TEXELS": str(sbc_pack.PATCH_TEXELS),
        "SBC_RAY_TEXELS": str(sbc_pack.RAY_TEXELS),
        "SBC_CAMERA_LEAF": str(CAMERA_LEAF),
        "SBC_RAY_LIST_LEAF": str(RAY_LIST_LEAF),
        "SBC_NEWTON_ITERATIONS": str(ray_patch.NEWTON_ITERATIONS),
        "SBC_CANDIDATE_CELLS": str(sbc_module.CANDIDATE_CELLS),
        "SBC_BAND_CANDIDATES": str(sbc_module.BAND_CANDIDATES),
        "SBC_SUBCELL_SAMPLES": str(sbc_cells.SUBCELL_SAMPLES),
        "SBC_FOLD_SAMPLES": str(sbc_cells.FOLD_SAMPLES),
        "SBC_FOLD_CANDIDATES": str(sbc_module.FOLD_CANDIDATES),
        "SBC_MAX_CANDIDATES": str(max(sbc_module.CANDIDATE_CELLS, sbc_module.BAND_CANDIDATES,
                                      sbc_module.FOLD_CANDIDATES)),
        "SBC_MISS_CELLS": _float(sbc_cells.MISS_CELLS),
        "SBC_STEP_TOLERANCE": _float(STEP_TOLERANCE),
        "SBC_RESIDUAL_TOLERANCE": _float(RESIDUAL_TOLERANCE),
        "SBC_ROUNDING_TOLERANCE": _float(ROUNDING_TOLERANCE),
        "SBC_CELL_TOLERANCE": _float(sbc_module.CELL_TOLERANCE),
        "SBC_CELL_MARGIN": _float(CELL_MARGIN),
        "SBC_DISTANCE_TOLERANCE": _float(DISTANCE_TOLERANCE),
    }


@functools.cache
def library_source() -> str:
    """GLSL defining ``bool sbc_project(vec3 p, int group, out vec2 pixel, out float
    first_depth, out float ray_distance, out int leaf_kind)``; insert it before the
    shader's ``main`` and declare the samplers with :func:`declare_samplers`."""
    return glsl_source("sbc_projection.glsl", defines())


def declare_samplers(info, first_slot: int = 0) -> int:
    """Declare the library's samplers on ``info`` from ``first_slot``; returns the next free slot."""
    for k, name in enumerate(SAMPLERS):
        info.sampler(first_slot + k, 'FLOAT_2D', name)
    return first_slot + len(SAMPLERS)


class SBCTextures:
    """One sample-based camera in GPU textures (needs an initialised GPU): a projection
    source (``sbc_triangles``' protocol) that projects on the GPU."""

    #: Projects on the GPU, a batch of the points at a time (``CameraTriangleMaker.project_pass``).
    on_gpu = True
    #: Mixed triangles use the renderer's sub-grids.
    sheet_subdivisions = None

    def __init__(self, sbc):
        self.packed = sbc_pack.pack_sample_based_camera(sbc)
        self.textures = {name: data_texture(image) for name, image in self.packed.texture_arrays().items()}
        self.groups = list(sbc.groups)
        self.view = sbc.ray_map.view

    @property
    def n_groups(self) -> int:
        return self.packed.n_groups

    @property
    def downsample(self) -> int:
        return self.packed.downsample

    def project(self, maker, positions, batch, draws: list, n_texels: int, setup: dict,
                static: bool = False, camera=None):
        """The GPU projection pass of ``draws`` (``CameraTriangleMaker.project_pass``) over
        ``positions`` (``batch``: their point batch, made here when None); with the
        ``camera`` these textures were packed from, risky answers are polished on the
        true rays where the renderer polishes (:func:`polish_readback`)."""
        if batch is None:
            batch = points_batch(np.asarray(positions, np.float32))
        points, eyes = maker.project_pass(self, batch, draws, n_texels, setup)
        if maker.polish and camera is not None and camera.true_rays is not None:
            polish_readback(camera, positions, draws, points, eyes, setup)
        return points, eyes

    def bind(self, shader) -> None:
        """Bind the textures to the library's samplers of a bound ``shader``."""
        for name, sampler in zip(sbc_pack.TEXTURE_NAMES, SAMPLERS):
            shader.uniform_sampler(sampler, self.textures[name])


_POINT_VERTEX = """
void main()
{
  vec2 pixel;
  float first_depth, ray_distance;
  int leaf_kind;
  sbc_project(position, group, pixel, first_depth, ray_distance, leaf_kind);
  projected = vec4(pixel, float(leaf_kind), first_depth);
  distance_out = ray_distance;
  /* Point i covers exactly texel (i % width, i / width) of the target. */
  vec2 texel = vec2(float(gl_VertexID % target_size.x), float(gl_VertexID / target_size.x)) + 0.5;
  gl_Position = vec4(texel / vec2(target_size) * 2.0 - 1.0, 0.0, 1.0);
  gl_PointSize = 1.0;
}
"""

_POINT_FRAGMENT = """
void main()
{
  projected_out = projected;
  distance_target = vec4(distance_out, 0.0, 0.0, 0.0);
}
"""


@cached_shader
def _point_shader():
    """Projects each vertex and writes its result to the texel of its index (built on first use)."""
    interface = gpu.types.GPUStageInterfaceInfo("curved_reflections_sbc_points_interface")
    interface.flat('VEC4', "projected")
    interface.flat('FLOAT', "distance_out")
    info = gpu.types.GPUShaderCreateInfo()
    info.push_constant('INT', "group")
    info.push_constant('IVEC2', "target_size")
    declare_samplers(info)
    info.vertex_in(0, 'VEC3', "position")
    info.vertex_out(interface)
    info.fragment_out(0, 'VEC4', "projected_out")
    info.fragment_out(1, 'VEC4', "distance_target")
    info.vertex_source(library_source() + _POINT_VERTEX)
    info.fragment_source(_POINT_FRAGMENT)
    return gpu.shader.create_from_info(info)


#: Bytes of push constants of the point projector: int group + ivec2 target size.
POINT_SHADER_PUSH_CONSTANT_BYTES = 4 + 8


@dataclass(frozen=True)
class GPUProjection:
    """Result of :func:`project_points` for P points and G groups (as ``engine.projection.Projection``)."""

    groups: list
    valid: np.ndarray  # (G, P) bool
    leaf_kind: np.ndarray  # (G, P) int8
    pixels: np.ndarray  # (G, P, 2), NaN where not valid
    first_depth: np.ndarray  # (G, P) distance along the pixel's view ray to the first reflector point
    ray_distance: np.ndarray  # (G, P)


def _read(texture, n: int) -> np.ndarray:
    data = texture.read()
    width, height = texture.width, texture.height
    data.dimensions = width * height * 4
    return np.asarray(data, dtype=np.float32).reshape(-1, 4)[:n]


def project_points(textures: SBCTextures, points) -> GPUProjection:
    """Project world points (P, 3) in every group on the GPU (float32 input)."""
    points = np.ascontiguousarray(points, dtype=np.float32)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must be a (P, 3) array, got shape {points.shape}")
    n_points, n_groups = len(points), textures.n_groups
    result = GPUProjection(
        groups=textures.groups, valid=np.zeros((n_groups, n_points), dtype=bool),
        leaf_kind=np.zeros((n_groups, n_points), dtype=np.int8),
        pixels=np.full((n_groups, n_points, 2), np.nan), first_depth=np.full((n_groups, n_points), np.nan),
        ray_distance=np.full((n_groups, n_points), np.nan),
    )
    if n_points == 0 or n_groups == 0:
        return result
    width = min(n_points, sbc_pack.TEXTURE_WIDTH)
    height = -(-n_points // width)
    # Non-finite points are left out, as SampleBasedCamera.project does.
    finite = np.isfinite(points).all(axis=1)
    vertex_format = gpu.types.GPUVertFormat()
    vertex_format.attr_add(id="position", comp_type='F32', len=3, fetch_mode='FLOAT')
    buffer = gpu.types.GPUVertBuf(vertex_format, n_points)
    buffer.attr_fill("position", np.where(finite[:, None], points, 0.0).astype(np.float32))
    batch = gpu.types.GPUBatch(type='POINTS', buf=buffer)
    shader = _point_shader()
    projected = gpu.types.GPUTexture((width, height), format='RGBA32F')
    distance = gpu.types.GPUTexture((width, height), format='RGBA32F')
    framebuffer = gpu.types.GPUFrameBuffer(color_slots=(projected, distance))
    blend, depth_test = gpu.state.blend_get(), gpu.state.depth_test_get()
    try:
        for g in range(n_groups):
            with framebuffer.bind():
                try:
                    gpu.state.viewport_set(0, 0, width, height)
                    framebuffer.clear(color=(0.0, 0.0, 0.0, 0.0))
                    gpu.state.blend_set('NONE')
                    gpu.state.depth_test_set('NONE')
                    gpu.state.program_point_size_set(True)
                    shader.bind()
                    shader.uniform_int("group", g)
                    shader.uniform_int("target_size", (width, height))
                    textures.bind(shader)
                    batch.draw(shader)
                finally:
                    gpu.state.program_point_size_set(False)
                    gpu.state.blend_set(blend)
                    gpu.state.depth_test_set(depth_test)
            out = _read(projected, n_points)
            ray_distance = _read(distance, n_points)[:, 0]
            kind = np.rint(out[:, 2]).astype(np.int8)
            valid = (kind > 0) & finite
            result.valid[g] = valid
            result.leaf_kind[g] = np.where(valid, kind, 0)
            result.pixels[g][valid] = out[valid, :2]
            result.first_depth[g][valid] = out[valid, 3]
            result.ray_distance[g][valid] = ray_distance[valid]
    finally:
        del framebuffer, projected, distance, batch, buffer
    return result


def polish_readback(camera, positions, draws: list, points: np.ndarray, eyes: np.ndarray, setup: dict) -> None:
    """Polish, in place, the GPU pass's first-order answers of ray-list leaves and fold
    cells on the true reflected rays, as the camera's numpy projection does
    (``SampleBasedCamera.polish_answers``; the GLSL twin interpolates only): new pixel,
    depth, eye vector and distance where polished, not projected where polishing fails."""
    for group, order, offset, first, count in draws:
        if len(camera.histories[group]) != 1:
            continue
        answered = np.flatnonzero(points[offset + first:offset + first + count, 3] > 0.5)
        if len(answered) == 0:
            continue
        texels = offset + first + answered
        position = np.asarray(positions[first + answered], dtype=np.float64)
        pixels, reflector_points, distance, ok = camera.polish_answers(
            group, points[texels, :2], position, np.rint(points[texels, 3]).astype(np.int8))
        points[texels[~ok]] = 0.0
        eyes[texels[~ok]] = 0.0
        polished = np.flatnonzero(ok & np.isfinite(distance))
        moved = texels[polished]
        points[moved, :3] = np.c_[pixels[polished], reflected_depth(order, distance[polished], setup)]
        eyes[moved] = np.c_[reflector_points[polished] - position[polished], distance[polished]]
