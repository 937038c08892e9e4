/* SPDX-License-Identifier: GPL-3.0-or-later */
/* Reflected meshes of the iterative search, vertex stage (gpu_shaders/iterative_draw.py),
 * every frame after iterative_search.glsl.
 *
 * Roger & Holzschuch 2006, section 3.2 step 3: each vertex is placed where the current
 * view sees its reflection point P (`search_result`, this frame's search), with the
 * depth of SBC paper V-A for a first-order reflection, z / D for its distance z from P
 * along the reflected ray (section 3.3.6 writes the same distance: the nearer reflected
 * point wins). The triangles are drawn unindexed and each vertex knows its triangle's
 * three corners (`corners.xyz`, `corners.w` being its own): where any corner has no
 * answer (not converged, facing away, hidden) or lies behind the view, all three
 * collapse to one point and the triangle draws nothing, so an unanswered vertex is
 * never drawn at a wrong place. Shading data as reflection_mesh_vert.glsl: the true eye
 * vector from the vertex toward P, and the distance. The fragment stage is
 * reflection_mesh_frag.glsl. */

bool corner_found(int index, out vec3 p, out vec4 clip)
{
  vec4 found = texelFetch(search_result, ivec2(index % result_width, index / result_width), 0);
  p = found.xyz;
  clip = view_projection * vec4(p, 1.0);
  return int(found.w) % 16 == FOUND_CODE && clip.w > 0.0;
}

void main()
{
  vec3 p0, p1, p2;
  vec4 c0, c1, c2;
  bool found0 = corner_found(corners.x, p0, c0);
  bool found1 = corner_found(corners.y, p1, c1);
  bool found2 = corner_found(corners.z, p2, c2);
  if (!(found0 && found1 && found2)) {
    gl_Position = vec4(2.0, 2.0, 2.0, 1.0);
    return;
  }
  int index = corners.w == 0 ? corners.x : (corners.w == 1 ? corners.y : corners.z);
  vec3 p = corners.w == 0 ? p0 : (corners.w == 1 ? p1 : p2);
  vec4 clip = corners.w == 0 ? c0 : (corners.w == 1 ? c1 : c2);
  vec3 vertex = texelFetch(vertex_positions, ivec2(index % result_width, index / result_width), 0).xyz;
  vec3 to_mirror = p - vertex;
  float distance = length(to_mirror);
  color_interp = color;
  normal_interp = normal_lit.xyz;
  lit_interp = normal_lit.w;
  uv_interp = uv;
  eye_interp = to_mirror / max(distance, 1e-30);
  distance_interp = distance;
  reflector_interp = reflector_id;
  float depth = clamp(distance * inverse_diameter, 0.0, 1.0) * order_range;
  gl_Position = vec4(clip.xy / clip.w, depth * 2.0 - 1.0, 1.0);
}
