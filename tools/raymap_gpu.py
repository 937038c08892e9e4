# SPDX-License-Identifier: GPL-3.0-or-later
"""Ray maps on the GPU: first hits of the view rays found by rasterising the reflectors.

SBC paper (Popescu, Sacks, Mei 2006), section III-B: the first-order reflected rays of
a desired view are computed on the GPU by rendering the reflectors into floating-point
targets that hold, per pixel, the reflector point (world position) and its normal.
Here all reflectors are drawn as one mesh, with the depth test, into an offscreen
framebuffer of the ray map's size (desired view down-sampled by ``d``), so each
target pixel samples exactly the desired-view pixel centre d (k + 0.5):

- target 0, RGBA32F: world position (xyz) and the triangle index (w, -1 where empty);
- target 1, RGBA32F: the interpolated vertex normal, normalised per fragment (xyz).

The triangle index travels as a flat per-vertex attribute of an un-indexed copy of the
mesh (three vertices per triangle; float32 holds indices below 2^24 exactly), which
does not depend on ``gl_PrimitiveID`` being available in every Blender backend.

After read-back, numpy turns each sample into what the CPU tracer returns for the same
view ray (depth along the ray, normals turned toward the ray's origin) and hands it to
:func:`engine.methods.sbc.raymap.reflect_primary_hits`, so reflection, higher orders, heads and
grouping are shared with :func:`engine.methods.sbc.raymap.trace_ray_map`. By default the hit is
also refined in float64 on the triangle the rasteriser chose (the GPU decides
visibility, numpy the exact point), removing the error of sub-pixel vertex snapping;
see :func:`gpu_ray_map`.

Unlike the CPU tracer, the rasteriser clips at the view's far plane: reflector points
beyond it are not in the ray map (nor visible in the view).

The extension traces its ray maps on the CPU (``engine/methods/sbc/raymap.py``) and never
runs this producer; it is kept, with its tests (``tests/tools/test_raymap_gpu.py``), as
the paper's GPU route measured against the CPU tracer, not shipped.
"""

from __future__ import annotations

import functools

import gpu
import numpy as np
from mathutils import Matrix

from ..engine.methods.sbc.raymap import RayMap, reflect_primary_hits
from ..engine.geometry.raytrace import ReflectorSet
from ..engine.view import View


#: Clear value of the position target; w = -1 marks pixels that no reflector covers.
_EMPTY = (0.0, 0.0, 0.0, -1.0)

_VERTEX_SOURCE = """
void main()
{
  world_position = position;
  world_normal = normal;
  triangle_id = triangle;
  gl_Position = view_projection * vec4(position, 1.0);
}
"""

_FRAGMENT_SOURCE = """
void main()
{
  position_out = vec4(world_position, triangle_id);
  normal_out = vec4(world_normal / max(length(world_normal), 1e-30), 1.0);
}
"""


@functools.cache
def _first_hit_shader():
    """The shader writing position + triangle and normal into two float targets (built on first use)."""
    interface = gpu.types.GPUStageInterfaceInfo("curved_reflections_first_hit_interface")
    interface.smooth('VEC3', "world_position")
    interface.smooth('VEC3', "world_normal")
    interface.flat('FLOAT', "triangle_id")
    info = gpu.types.GPUShaderCreateInfo()
    info.push_constant('MAT4', "view_projection")
    info.vertex_in(0, 'VEC3', "position")
    info.vertex_in(1, 'VEC3', "normal")
    info.vertex_in(2, 'FLOAT', "triangle")
    info.vertex_out(interface)
    info.fragment_out(0, 'VEC4', "position_out")
    info.fragment_out(1, 'VEC4', "normal_out")
    info.vertex_source(_VERTEX_SOURCE)
    info.fragment_source(_FRAGMENT_SOURCE)
    return gpu.shader.create_from_info(info)


def target_projection(view: View, downsample: int) -> np.ndarray:
    """Projection for the (W // d) x (H // d) target whose pixel k samples desired pixel d (k + 0.5).

    NDC maps uniformly to pixels, so the same projection drawn into a W/d-wide target
    samples d (k + 0.5) when d divides W. Otherwise the clip-space x (and y) is scaled
    and shifted: with c = W // d and s = W / (d c), target NDC = s * desired NDC + s - 1
    puts desired pixel d (k + 0.5) at target pixel k + 0.5 (and drops the last W - d c
    desired pixels, which have no ray-map cell).
    """
    d = int(downsample)
    columns, rows = view.width // d, view.height // d
    sx, sy = view.width / (d * columns), view.height / (d * rows)
    crop = np.array([[sx, 0, 0, sx - 1], [0, sy, 0, sy - 1], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=np.float64)
    return crop @ view.projection_matrix


def _mesh_batch(reflector_set: ReflectorSet, shift: np.ndarray):
    """Un-indexed triangles (positions relative to ``shift``), normals and flat triangle ids."""
    corners = reflector_set.triangles.reshape(-1)
    n_triangles = len(reflector_set.triangles)
    if n_triangles >= 1 << 24:
        raise ValueError(f"{n_triangles} triangles: float32 triangle ids are exact below 2^24 only")
    vertex_format = gpu.types.GPUVertFormat()
    vertex_format.attr_add(id="position", comp_type='F32', len=3, fetch_mode='FLOAT')
    vertex_format.attr_add(id="normal", comp_type='F32', len=3, fetch_mode='FLOAT')
    vertex_format.attr_add(id="triangle", comp_type='F32', len=1, fetch_mode='FLOAT')
    buffer = gpu.types.GPUVertBuf(vertex_format, len(corners))
    buffer.attr_fill("position", np.ascontiguousarray(reflector_set.vertices[corners] - shift, dtype=np.float32))
    buffer.attr_fill("normal", np.ascontiguousarray(reflector_set.normals[corners], dtype=np.float32))
    buffer.attr_fill("triangle", np.repeat(np.arange(n_triangles, dtype=np.float32), 3))
    return gpu.types.GPUBatch(type='TRIS', buf=buffer)


def _read(texture, columns: int, rows: int) -> np.ndarray:
    data = texture.read()
    data.dimensions = rows * columns * 4
    return np.array(data, dtype=np.float64).reshape(rows * columns, 4)  # row-major from the bottom row


def rasterise_first_hits(reflector_set: ReflectorSet, view: View, downsample: int = 2):
    """Position, triangle index and unit interpolated normal at each ray-map cell.

    Returns ``(position (K, 3), triangle (K,), normal (K, 3))`` in the order of
    ``view.pixel_grid(downsample)``; triangle -1 (and NaN rows) where no reflector is seen.
    """
    d = int(downsample)
    if d < 1:
        raise ValueError(f"downsample must be >= 1, got {downsample}")
    columns, rows = view.width // d, view.height // d
    if columns < 1 or rows < 1:
        raise ValueError(f"a {view.width}x{view.height} view has no cell at downsample {d}")
    # Vertices go to the GPU relative to the reflectors' centre, in float32; the shift
    # is folded into the matrix in float64 and added back after read-back.
    shift = 0.5 * (reflector_set.vertices.min(axis=0) + reflector_set.vertices.max(axis=0))
    translate = np.eye(4)
    translate[:3, 3] = shift
    matrix = target_projection(view, d) @ view.view_matrix @ translate

    shader = _first_hit_shader()
    batch = _mesh_batch(reflector_set, shift)
    position_target = gpu.types.GPUTexture((columns, rows), format='RGBA32F')
    normal_target = gpu.types.GPUTexture((columns, rows), format='RGBA32F')
    depth_target = gpu.types.GPUTexture((columns, rows), format='DEPTH_COMPONENT32F')
    framebuffer = gpu.types.GPUFrameBuffer(depth_slot=depth_target, color_slots=(position_target, normal_target))
    depth_test, depth_mask = gpu.state.depth_test_get(), gpu.state.depth_mask_get()
    blend = gpu.state.blend_get()
    try:
        with framebuffer.bind():
            try:
                gpu.state.viewport_set(0, 0, columns, rows)
                framebuffer.clear(color=_EMPTY, depth=1.0)
                gpu.state.depth_test_set('LESS_EQUAL')
                gpu.state.depth_mask_set(True)
                gpu.state.face_culling_set('NONE')  # mirrors are two-sided
                gpu.state.blend_set('NONE')
                shader.bind()
                shader.uniform_float("view_projection", Matrix(matrix.tolist()))
                batch.draw(shader)
            finally:
                gpu.state.depth_test_set(depth_test)
                gpu.state.depth_mask_set(depth_mask)
                gpu.state.blend_set(blend)
        position = _read(position_target, columns, rows)
        normal = _read(normal_target, columns, rows)[:, :3]
    finally:
        # Python exposes no explicit free for textures and framebuffers: dropping the
        # last references releases them now rather than at some later collection.
        del framebuffer, position_target, normal_target, depth_target, batch

    triangle = np.where(position[:, 3] >= 0, np.rint(position[:, 3]), -1).astype(np.int64)
    hit = triangle >= 0
    points = np.full((len(triangle), 3), np.nan)
    points[hit] = position[hit, :3] + shift
    normals = np.full((len(triangle), 3), np.nan)
    normals[hit] = normal[hit] / np.maximum(np.linalg.norm(normal[hit], axis=1), 1e-300)[:, None]
    return points, triangle, normals


def refine_on_triangles(reflector_set: ReflectorSet, origins: np.ndarray, directions: np.ndarray,
                        triangle: np.ndarray):
    """Exact (float64) hits of rays on the triangles the rasteriser chose.

    Returns ``(depth (K,), normal (K, 3), inside (K,))``: the distance along each unit
    ray to its triangle (NaN where the ray misses it), the unit interpolated normal
    there, and whether the hit lies inside the triangle (the CPU tracer's own test,
    ``ReflectorSet.hit_triangles``) and is well defined.
    """
    depth, u, v, det = reflector_set.hit_triangles(origins, directions, triangle)
    e1, e2 = reflector_set.e1[triangle], reflector_set.e2[triangle]
    # Stricter than the tracer about rays nearly parallel to the plane: those are re-traced.
    inside = (np.abs(det) > 1e-12 * np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)) & (depth > 0)
    corners = reflector_set.triangles[triangle]
    normal = np.einsum("ij,ijk->ik", np.stack([1 - u - v, u, v], axis=1), reflector_set.normals[corners])
    length = np.linalg.norm(normal, axis=1)
    inside &= length > 1e-12
    return depth, normal / np.maximum(length, 1e-300)[:, None], inside


def gpu_ray_map(reflector_set: ReflectorSet, view: View, bounds, downsample: int = 2,
                max_order: int = 1, refine: bool = True) -> RayMap:
    """Ray map whose first hits come from the GPU; same result type as ``trace_ray_map``.

    The view rays are those of :meth:`View.pixel_rays` through the cell centres.

    ``refine=False`` uses the rasterised point and normal as the paper does: the depth
    is the projection (position - origin) . direction and the tail is rebuilt on the
    ray from it. Rasterisers snap vertices to a sub-pixel grid (commonly 1/256 pixel),
    so a sample lands up to about 1/512 pixel off its ray's surface point; on curved,
    obliquely seen mirrors that is a few 1e-5 of the scene in position and up to a few
    1e-4 in the reflected direction, and cells on silhouettes can differ.

    ``refine=True`` (the default) lets the GPU decide visibility only: each cell's hit
    is recomputed in float64 on the triangle the rasteriser chose, and the few cells
    whose ray falls outside that triangle (snapped across an edge or a silhouette, a
    tiny fraction) are re-traced on the CPU. The result then matches
    :func:`engine.methods.sbc.raymap.trace_ray_map` to rounding, except where depth-buffer precision
    picks a different surface than the exact nearest hit.

    As in :meth:`ReflectorSet.intersect`, the interpolated and the face normal are both
    turned toward the ray's origin. Everything after the first hit is shared with the
    CPU path (:func:`engine.methods.sbc.raymap.reflect_primary_hits`).
    """
    if max_order < 1:
        raise ValueError(f"max_order must be >= 1, got {max_order}")
    points, triangle, normals = rasterise_first_hits(reflector_set, view, downsample)
    origins, directions = view.pixel_rays(view.pixel_grid(downsample))
    hit = triangle >= 0
    rows = np.flatnonzero(hit)
    depth = np.full(len(triangle), np.inf)
    depth[rows] = np.einsum("ij,ij->i", points[rows] - origins[rows], directions[rows])
    face = np.full((len(triangle), 3), np.nan)
    face[rows] = reflector_set.face_normals[triangle[rows]]
    retrace = rows[:0]
    if refine:
        exact_depth, exact_normal, inside = refine_on_triangles(
            reflector_set, origins[rows], directions[rows], triangle[rows])
        depth[rows[inside]], normals[rows[inside]] = exact_depth[inside], exact_normal[inside]
        retrace = rows[~inside]
    flip = np.einsum("ij,ij->i", face[rows], directions[rows]) > 0
    face[rows] = np.where(flip[:, None], -face[rows], face[rows])
    normals[rows] = np.where(flip[:, None], -normals[rows], normals[rows])
    if len(retrace):
        traced = reflector_set.intersect(origins[retrace], directions[retrace])
        triangle[retrace], depth[retrace] = traced.triangle, traced.t
        normals[retrace], face[retrace] = traced.normal, traced.face_normal
        hit = triangle >= 0
    return reflect_primary_hits(reflector_set, view, bounds, downsample, max_order, hit, triangle, depth,
                                origins, directions, normals, face)
