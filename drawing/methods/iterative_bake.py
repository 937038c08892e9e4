# SPDX-License-Identifier: GPL-3.0-or-later
"""A reflector's cube map (``engine/methods/iterative/reflector_map.py``) baked on the GPU.

The CPU bake casts one ray from the centre O through every texel of the padded
cube-map atlas. Here each of the six faces is a perspective view from O along its
major axis, the reflector's triangles rasterised into it: the camera's image plane at
distance 1 spans [-(1 + 2/S), 1 + 2/S] in the face's (u, v) with S + 2 pixels a side, so
pixel (i, j) of face f is exactly texel (i, j): its centre lies on the texel's ray, and
the six faces sit one above another in one (S + 2) x 6 (S + 2) float target, in the
atlas's own layout (row f (S + 2) + j, column i; the target's rows read back bottom to
top, as the atlas's rows count).

Each fragment computes the texel's ray d from its pixel (as ``texel_directions``), its
distance r where d meets the triangle's plane (the plane comes flat per triangle: the
triangles are drawn un-indexed) and the perspective-correctly interpolated vertex normal,
turned as the CPU tracer turns it (outward where the triangle's geometric normal faces
away from O). The fragment depth is r / far (linear, in a 32-bit float depth buffer):

1. depth test LESS, depth cleared to 1: the first crossing, (r, n) into the map's
   target and |cos| between the ray and the geometric normal into a second target
   (``min_cosine``);
2. depth test GREATER, depth cleared to 0: the last crossing; a texel whose last
   crossing lies beyond its first (by more than :data:`CROSSING_TOLERANCE` of the
   reflector's size) meets the surface twice: ``crossings``.

Colour is cleared to 0, so r = 0 marks a hole, as in the CPU bake. ``crossings`` counts
texels with any later crossing (the CPU bake counts rays that meet the surface again
outside the first hit's one-ring), so the two agree on zero and non-zero, not in value.
Coverage along a silhouette follows the rasteriser's rules, so a few texels whose ray
grazes the outline may differ from the CPU bake's.

The shader is built on first use and cached, never at import.
"""

from __future__ import annotations


import gpu
import numpy as np

from ...engine.geometry.closed_surfaces import is_convex
from ...engine.methods.iterative.reflector_map import MapBake, ReflectorMap
from ...engine.geometry.vectors import cross
from ..gpu_data import read_texture, vertex_buffer
from ..shader_cache import cached_shader

#: A texel crosses the surface again where its last crossing lies farther than its first
#: by more than this share of the reflector's size (bounding-box diagonal).
CROSSING_TOLERANCE = 1e-4
#: Near clipping plane of the face cameras, as a share of the reflector's size: surfaces
#: closer to O than this are not seen (the CPU tracer's limit is 1e-9 of the scene).
NEAR_FRACTION = 1e-7
#: Below this |cos| between ray and triangle plane, r comes from the interpolated
#: position instead of the plane (ill-conditioned at grazing rays).
GRAZING_COSINE = 1e-4

_VERTEX = """
/* The face camera at O looking along +/- axis: clip (u w / k, v w / k, ., w) for the
 * distance w = sign p[axis] along the axis, k = 1 + 2 / S; the near plane at w = near. */
void main()
{
  vec3 relative = position - offset;
  vec3 q = axis == 0 ? relative.yzx : (axis == 1 ? relative.zxy : relative.xyz);
  float w = axis_sign * q.z;
  gl_Position = vec4(q.x * inverse_extent, q.y * inverse_extent, w - 2.0 * near, w);
  position_interp = relative;
  normal_interp = normal;
  plane_interp = vec4(plane.xyz, plane.w - dot(plane.xyz, offset));
}
"""

_FRAGMENT = """
void main()
{
  /* The texel's ray, exactly as texel_directions: pixel centre i + 0.5 has
   * u = (i - 0.5) 2 / S - 1; the faces are stacked S + 2 rows apart. */
  vec2 texel = gl_FragCoord.xy - vec2(0.0, float(face * (face_size + 2)));
  vec2 uv = (texel - 1.0) * (2.0 / float(face_size)) - 1.0;
  vec3 q = vec3(uv, axis_sign);
  vec3 d = normalize(axis == 0 ? q.zxy : (axis == 1 ? q.yzx : q.xyz));
  /* Distance to the triangle's plane along the ray (the CPU tracer's t). */
  float cosine = dot(plane_interp.xyz, d);
  float r = abs(cosine) > grazing ? plane_interp.w / cosine : length(position_interp);
  if (!(r > 0.0)) {
    r = length(position_interp);
  }
  /* The tracer turns normals toward O by the geometric normal; the map stores them outward. */
  vec3 n = normalize(normal_interp);
  n = cosine > 0.0 ? n : -n;
  map_out = vec4(r, n);
  cosine_out = vec4(abs(cosine), 0.0, 0.0, 1.0);
  gl_FragDepth = clamp(r * inverse_far, 0.0, 1.0);
}
"""


@cached_shader
def _bake_shader():
    interface = gpu.types.GPUStageInterfaceInfo("curved_reflections_map_bake_interface")
    interface.smooth('VEC3', "position_interp")
    interface.smooth('VEC3', "normal_interp")
    interface.flat('VEC4', "plane_interp")
    info = gpu.types.GPUShaderCreateInfo()
    info.push_constant('INT', "axis")
    info.push_constant('INT', "face")
    info.push_constant('INT', "face_size")
    info.push_constant('FLOAT', "axis_sign")
    info.push_constant('FLOAT', "inverse_extent")
    info.push_constant('FLOAT', "near")
    info.push_constant('FLOAT', "inverse_far")
    info.push_constant('FLOAT', "grazing")
    info.push_constant('VEC3', "offset")
    info.vertex_in(0, 'VEC3', "position")
    info.vertex_in(1, 'VEC3', "normal")
    info.vertex_in(2, 'VEC4', "plane")
    info.vertex_out(interface)
    info.fragment_out(0, 'VEC4', "map_out")
    info.fragment_out(1, 'VEC4', "cosine_out")
    info.depth_write('ANY')
    info.vertex_source(_VERTEX)
    info.fragment_source(_FRAGMENT)
    return gpu.shader.create_from_info(info)


def _mesh_arrays(reflector):
    """(vertices, triangles, normals) of a Reflector, or of a ReflectorSet's reflectors together."""
    if hasattr(reflector, "reflectors"):  # a ReflectorSet
        return reflector.vertices, reflector.triangles, reflector.normals
    return (np.asarray(reflector.vertices, np.float64), np.asarray(reflector.triangles, np.int64),
            np.asarray(reflector.normals, np.float64))


def _face_normals(vertices, triangles) -> np.ndarray:
    corners = vertices[triangles]
    face = cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    return face / np.maximum(np.linalg.norm(face, axis=1), 1e-300)[:, None]


def _triangle_batch(vertices, triangles, normals, origin, face_normals):
    """An un-indexed TRIS batch: positions relative to ``origin``, vertex normals, and
    each triangle's plane (geometric normal, offset from ``origin``) on its three corners."""
    corners = triangles.reshape(-1)
    relative = vertices[corners] - origin
    offsets = np.einsum("tk,tk->t", face_normals, vertices[triangles[:, 0]] - origin)
    plane = np.repeat(np.c_[face_normals, offsets], 3, axis=0)
    buffer = vertex_buffer({
        "position": (relative.astype(np.float32), 'F32', 'FLOAT'),
        "normal": (normals[corners].astype(np.float32), 'F32', 'FLOAT'),
        "plane": (plane.astype(np.float32), 'F32', 'FLOAT'),
    })
    return gpu.types.GPUBatch(type='TRIS', buf=buffer)


def _draw_faces(framebuffer, shader, batch, uniforms, depth_test: str, clear_depth: float) -> None:
    """Clear the atlas target and draw the six face cameras into their rows; the
    viewport, depth and blend state are restored afterwards."""
    size, near, inverse_far, offset = uniforms
    side = size + 2
    saved = (gpu.state.viewport_get(), gpu.state.depth_test_get(), gpu.state.depth_mask_get(),
             gpu.state.blend_get())
    with framebuffer.bind():
        try:
            gpu.state.viewport_set(0, 0, side, 6 * side)
            framebuffer.clear(color=(0.0, 0.0, 0.0, 0.0), depth=clear_depth)
            gpu.state.depth_test_set(depth_test)
            gpu.state.depth_mask_set(True)
            gpu.state.face_culling_set('NONE')  # mirrors are two-sided
            gpu.state.blend_set('NONE')
            gpu.state.scissor_test_set(True)
            shader.bind()
            shader.uniform_int("face_size", size)
            shader.uniform_float("inverse_extent", 1.0 / (1.0 + 2.0 / size))
            shader.uniform_float("near", near)
            shader.uniform_float("inverse_far", inverse_far)
            shader.uniform_float("grazing", GRAZING_COSINE)
            shader.uniform_float("offset", offset)
            for face in range(6):
                gpu.state.viewport_set(0, face * side, side, side)
                gpu.state.scissor_set(0, face * side, side, side)
                shader.uniform_int("axis", face // 2)
                shader.uniform_int("face", face)
                shader.uniform_float("axis_sign", -1.0 if face % 2 else 1.0)
                batch.draw(shader)
        finally:
            gpu.state.scissor_test_set(False)
            gpu.state.viewport_set(*saved[0])
            gpu.state.depth_test_set(saved[1])
            gpu.state.depth_mask_set(saved[2])
            gpu.state.blend_set(saved[3])


class GPUMapBaker:
    """One reflector's triangles on the GPU, relative to its bounding box's centre, for
    maps around any number of centres (a candidate centre, a piece's) with one upload:
    each bake moves the face cameras by a push constant (the centre's offset from the
    box's, small beside the reflector, so float32 keeps the positions as relative
    ones would)."""

    def __init__(self, reflector):
        self.vertices, self.triangles, normals = _mesh_arrays(reflector)
        lo, hi = self.vertices.min(axis=0), self.vertices.max(axis=0)
        self.origin = 0.5 * (lo + hi)
        self.scale = float(max(np.linalg.norm(hi - lo), 1e-12))
        self.batch = _triangle_batch(self.vertices, self.triangles, normals, self.origin,
                                     _face_normals(self.vertices, self.triangles))
        self._convex = None

    def _is_convex(self, centre) -> bool:
        """``is_convex`` around the first centre baked (every centre baked lies inside the
        body, where the answer is the same; it sorts every edge, too slow per map)."""
        if self._convex is None:
            self._convex = is_convex(self.vertices, self.triangles, centre)
        return self._convex

    def bake(self, centre, face_size: int) -> MapBake:
        """The ``MapBake`` of ``bake_reflector_map(ReflectorSet([reflector]), centre, face_size)``,
        rasterised (the GPU must be ready: ``blender.gpu_init.ensure_gpu``)."""
        size = int(face_size)
        side = size + 2
        centre = np.asarray(centre, dtype=np.float64)
        offsets = self.vertices - centre
        far = 2.0 * float(np.sqrt(np.max(np.einsum("vk,vk->v", offsets, offsets)))) + self.scale
        shader = _bake_shader()
        map_target = gpu.types.GPUTexture((side, 6 * side), format='RGBA32F')
        cosine_target = gpu.types.GPUTexture((side, 6 * side), format='RGBA32F')
        depth_target = gpu.types.GPUTexture((side, 6 * side), format='DEPTH_COMPONENT32F')
        framebuffer = gpu.types.GPUFrameBuffer(depth_slot=depth_target, color_slots=(map_target, cosine_target))
        try:
            uniforms = (size, NEAR_FRACTION * self.scale, 1.0 / far, tuple(float(c) for c in centre - self.origin))
            _draw_faces(framebuffer, shader, self.batch, uniforms, 'LESS', 1.0)
            texels = read_texture(map_target, side, 6 * side).copy()
            cosine = read_texture(cosine_target, side, 6 * side)[..., 0].copy()
            _draw_faces(framebuffer, shader, self.batch, uniforms, 'GREATER', 0.0)
            last = read_texture(map_target, side, 6 * side)[..., 0].copy()
        finally:
            # No explicit free for textures and framebuffers: dropping the references releases them.
            del framebuffer, map_target, cosine_target, depth_target

        radius = texels[..., 0]
        hit = radius > 0
        again = hit & (last.astype(np.float64) - radius > CROSSING_TOLERANCE * self.scale)
        reflector_map = ReflectorMap(
            centre=centre, face_size=size, texels=texels,
            convex=self._is_convex(centre),
            min_radius=float(radius[hit].min()) if hit.any() else 0.0,
            max_radius=float(radius[hit].max()) if hit.any() else 0.0,
        )
        return MapBake(reflector_map, int(again.sum()), float(cosine[hit].min()) if hit.any() else 0.0,
                       float(hit.mean()), np.where(hit, cosine, 0.0).astype(np.float32))


def bake_reflector_map_gpu(reflector, centre, face_size: int) -> MapBake:
    """The ``MapBake`` of ``bake_reflector_map(ReflectorSet([reflector]), centre, face_size)``,
    rasterised on the GPU (which must be ready: ``blender.gpu_init.ensure_gpu``); for
    several centres of one reflector, one :class:`GPUMapBaker`."""
    return GPUMapBaker(reflector).bake(centre, face_size)
