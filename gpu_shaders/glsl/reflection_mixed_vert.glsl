/* SPDX-License-Identifier: GPL-3.0-or-later */
/* Mixed-triangle pass, vertex stage (gpu_shaders/reflection_draw.py).
 *
 * SBC paper (Popescu, Sacks, Mei 2006), section V-B: "a triangle is called mixed when one
 * or two vertices project. Discarding mixed triangles creates jagged reflection edges. We
 * solve this problem by subdividing mixed triangles". Each instance is one mixed
 * triangle of one sheet, found from the vertex projections (texels 2k, 2k + 1 of
 * `mixed_instances`: its corner indices and group, then its sheet's anchor pixel, the
 * projection of a corner that projects). The batch is a fixed triangular grid of
 * sub-vertices in barycentric coordinates; every sub-vertex interpolates the corners'
 * data (position, colour, normal, texture coordinates) and is projected on its own with
 * `sbc_project`, so the reflection's edge follows where projection stops, at the
 * sub-grid's resolution, instead of a corner-to-corner staircase. A sub-vertex that does
 * not project sits at the anchor with `valid_interp` 0, and the fragment stage discards
 * every fragment of a sub-triangle that has one (the interpolated validity is below 1).
 * Depth and eye vector as in reflection_project_vert.glsl. */

vec4 vertex_texel(sampler2D data, int index)
{
  int width = textureSize(data, 0).x;
  return texelFetch(data, ivec2(index % width, index / width), 0);
}

void main()
{
  int width = textureSize(mixed_instances, 0).x;
  int first = 2 * (gl_InstanceID + instance_offset);
  vec4 instance = texelFetch(mixed_instances, ivec2(first % width, first / width), 0);
  vec4 anchor = texelFetch(mixed_instances, ivec2((first + 1) % width, (first + 1) / width), 0);
  ivec3 c = ivec3(instance.xyz);
  vec3 w = vec3(barycentric, 1.0 - barycentric.x - barycentric.y);
  vec4 p0 = vertex_texel(vertex_positions, c.x), p1 = vertex_texel(vertex_positions, c.y),
       p2 = vertex_texel(vertex_positions, c.z);
  vec3 position = w.x * p0.xyz + w.y * p1.xyz + w.z * p2.xyz;
  color_interp = w.x * vertex_texel(vertex_colors, c.x) + w.y * vertex_texel(vertex_colors, c.y) +
                 w.z * vertex_texel(vertex_colors, c.z);
  vec4 n0 = vertex_texel(vertex_normals, c.x), n1 = vertex_texel(vertex_normals, c.y),
       n2 = vertex_texel(vertex_normals, c.z);
  normal_interp = w.x * n0.xyz + w.y * n1.xyz + w.z * n2.xyz;
  uv_interp = w.x * vec2(p0.w, n0.w) + w.y * vec2(p1.w, n1.w) + w.z * vec2(p2.w, n2.w);
  lit_interp = vertex_texel(vertex_colors, c.x).a; /* the vertex textures keep `lit` in alpha */
  color_interp.a = 1.0;

  vec2 pixel;
  float first_depth, ray_distance;
  int leaf_kind;
  bool valid = sbc_project(position, int(instance.w), pixel, first_depth, ray_distance, leaf_kind);
  valid_interp = valid ? 1.0 : 0.0;
  float z = clamp(ray_distance * inverse_diameter, 0.0, 1.0);
  float depth = (float(order - 1) + z) * order_range;
  eye_interp = view_ray_point(inverse_view_projection, view_size, pixel, first_depth) - position;
  distance_interp = ray_distance;
  vec2 xy = valid ? pixel : anchor.xy;
  gl_Position = vec4(xy / view_size * 2.0 - 1.0, (valid ? depth : 1.0) * 2.0 - 1.0, 1.0);
}
