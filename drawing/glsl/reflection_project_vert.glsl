/* SPDX-License-Identifier: GPL-3.0-or-later */
/* Vertex projection pass (drawing/reflection_draw.py): each vertex of the
 * (pre-subdivided) diffuse meshes is projected once per sheet with the sample-based
 * camera (SBC paper, Popescu, Sacks, Mei 2006, section V-A) and its result written to
 * texel layer_offset + gl_VertexID of two float targets, so the triangle pass can read
 * the projections of all three corners of a triangle without projecting any vertex
 * three times. The sheets of one reflection history go to consecutive layers of the
 * targets (layer_offset = layer * vertex count), so that triangles can be stitched
 * across the seams between sheets (reflection_mesh_vert.glsl).
 *
 * Target 0 = (pixel.x, pixel.y, depth, leaf kind): the desired-view pixel of the reflection,
 * and the depth that orders reflections (SBC V-A visibility cases 2 and 3): the offset
 * (k - 1 + z / D) g along the desired view ray, with k the reflection order, z the
 * distance from the last reflector point along the reflected ray (the point nearer the
 * mirror wins within a sheet), D an upper bound of z (the scene's diameter) and
 * g = 1 / (k_max + 1) the depth range per order (lower orders in front); the leaf kind is
 * 0 where the vertex does not project, 1 (camera leaf) or 2 (ray-list leaf) where it does:
 * the CPU polishes ray-list answers on the true rays (SampleBasedCamera.polish_answers).
 * Target 1 = (e, z): e the eye vector of lighting (SBC V-C), from the vertex to its
 * first reflector point (exact for first-order reflections; for higher orders the first
 * point stands in for the last), and z again, for distance attenuation (SBC V-D). */

void main()
{
  vec2 pixel;
  float first_depth, ray_distance;
  int leaf_kind;
  bool valid = sbc_project(position, group, pixel, first_depth, ray_distance, leaf_kind);
  float z = clamp(ray_distance * inverse_diameter, 0.0, 1.0);
  float depth = (float(order - 1) + z) * order_range;
  projected = valid ? vec4(pixel, depth, float(leaf_kind)) : vec4(0.0);
  vec3 eye = view_ray_point(inverse_view_projection, view_size, pixel, first_depth) - position;
  projected_eye = valid ? vec4(eye, ray_distance) : vec4(0.0);
  int index = layer_offset + gl_VertexID;
  vec2 texel = vec2(float(index % target_size.x), float(index / target_size.x)) + 0.5;
  gl_Position = vec4(texel / vec2(target_size) * 2.0 - 1.0, 0.0, 1.0);
  gl_PointSize = 1.0;
}
