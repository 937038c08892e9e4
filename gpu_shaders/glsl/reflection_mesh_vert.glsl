/* SPDX-License-Identifier: GPL-3.0-or-later */
/* Reflected-mesh pass, vertex stage (gpu_shaders/reflection_draw.py).
 *
 * SBC paper (Popescu, Sacks, Mei 2006), section V-B: a reflected triangle is drawn when
 * all three vertices project and dropped otherwise. Triangles are drawn un-indexed;
 * every vertex carries the indices of its triangle's three corners (`corners`) and
 * which of them it is (`corner`). It reads the three projections written by the
 * vertex projection pass (texel (pixel.x, pixel.y, depth, valid) per mesh vertex and
 * sheet layer) and, when the triangle cannot be drawn, collapses onto a point outside
 * the clip volume: all three vertices of a triangle read the same texels and decide
 * alike, so the triangle vanishes whole (no stretched triangle toward an unprojected
 * vertex).
 *
 * Seams between sheets: where the rays of one reflection history cross in space, the
 * engine splits them into sheets (addon/sbc.py), each projecting only near its own
 * rays, so a triangle across the seam has corners that project in different sheets.
 * Drawing sheet `own_layer`, a corner without a projection in this sheet takes its
 * projection in another sheet of the same history (layers 0 .. n_layers - 1), the one
 * nearest in the image to the triangle's first corner that does project here, and only
 * within `stitch_px` of it: a point can have two images in two sheets (a mirror showing
 * it twice), and a corner must not be joined to its other image across the mirror. A
 * triangle is drawn when at least one corner projects in this sheet and every corner
 * projects in some sheet of the history.
 *
 * The position is the projected pixel in the desired view's NDC, with w = 1 and the
 * order-and-distance depth of reflection_project_vert.glsl (SBC V-A). The vertex keeps
 * its mesh's colour, normal and texture coordinates and gets its eye vector and
 * reflected distance from the projection (SBC V-C; shaded in reflection_mesh_frag.glsl).
 *
 * Mixed triangles (one or two corners projected, none stitched) are not drawn here but
 * subdivided by reflection_mixed_vert.glsl. */

vec4 fetch_projected(int layer, int index)
{
  int texel = layer * layer_size + index;
  return texelFetch(projected_vertices, ivec2(texel % projected_size.x, texel / projected_size.x), 0);
}

vec4 fetch_eye(int layer, int index)
{
  int texel = layer * layer_size + index;
  return texelFetch(projected_eyes, ivec2(texel % projected_size.x, texel / projected_size.x), 0);
}

/* The corner's projection from another layer nearest to `anchor`, within stitch_px;
 * `from_layer` the layer it came from. */
bool stitched(int index, vec2 anchor, out vec4 result, inout int from_layer)
{
  float best = stitch_px * stitch_px;
  bool found = false;
  result = vec4(0.0);
  for (int layer = 0; layer < n_layers; layer++) {
    if (layer == own_layer) {
      continue;
    }
    vec4 other = fetch_projected(layer, index);
    vec2 offset = other.xy - anchor;
    float distance2 = dot(offset, offset);
    if (other.w > 0.5 && distance2 <= best) {
      best = distance2;
      result = other;
      from_layer = layer;
      found = true;
    }
  }
  return found;
}

void main()
{
  color_interp = color;
  normal_interp = normal_lit.xyz;
  lit_interp = normal_lit.w;
  uv_interp = uv;
  int layer[3] = int[3](own_layer, own_layer, own_layer);
  vec4 p[3];
  p[0] = fetch_projected(own_layer, corners.x);
  p[1] = fetch_projected(own_layer, corners.y);
  p[2] = fetch_projected(own_layer, corners.z);
  bvec3 own = bvec3(p[0].w > 0.5, p[1].w > 0.5, p[2].w > 0.5);
  bool drawn = any(own);
  if (drawn && !all(own)) {
    vec2 anchor = own.x ? p[0].xy : (own.y ? p[1].xy : p[2].xy);
    drawn = (own.x || stitched(corners.x, anchor, p[0], layer[0])) &&
            (own.y || stitched(corners.y, anchor, p[1], layer[1])) &&
            (own.z || stitched(corners.z, anchor, p[2], layer[2]));
  }
  if (!drawn) {
    gl_Position = vec4(2.0, 2.0, 2.0, 1.0);
    return;
  }
  vec4 mine = p[corner];
  vec4 eye = fetch_eye(layer[corner], corner == 0 ? corners.x : (corner == 1 ? corners.y : corners.z));
  eye_interp = eye.xyz;
  distance_interp = eye.w;
  gl_Position = vec4(mine.xy / view_size * 2.0 - 1.0, mine.z * 2.0 - 1.0, 1.0);
}
