/* SPDX-License-Identifier: GPL-3.0-or-later */
/* Reflected meshes of the iterative search, vertex stage (drawing/methods/iterative_draw.py),
 * every frame after iterative_search.glsl.
 *
 * Roger & Holzschuch 2006, section 3.2 step 3: each vertex is placed where the current
 * view sees its reflection point P (`search_result`, texel `vertex_index`, this frame's
 * search), with the depth of SBC paper V-A for a first-order reflection, z / D for its
 * distance z from P along the reflected ray (section 3.3.6 writes the same distance: the
 * nearer reflected point wins). A vertex without an answer (not converged, facing away,
 * hidden, inside the mirror) or behind the view gets `valid_interp` 0: the fragment
 * stage discards every fragment of a triangle with such a corner (its interpolated
 * validity is below 1 everywhere but at the valid corners), so an unanswered vertex is
 * never drawn at a wrong place. It goes to the centre of its cell of a coarse grid
 * (UNANSWERED_CELLS across the view, from its last search sample): its triangles
 * without an answered corner collapse there and are dropped before rasterisation, and
 * one with an answered corner reaches no farther than a cell. A flipped image
 * (beyond the caustic, FLIPPED_CODE) gets -1: a triangle joining it to a direct image
 * spans a fold of the mirror, its interpolated validity is below 1 in magnitude inside,
 * and it is discarded as well. Shading data as
 * reflection_mesh_vert.glsl: the true eye vector from the vertex toward P, and the
 * distance. `mirror_point_interp`, P, lets the fragment stage drop a reflection whose
 * reflector point the mirror hides, or whose ray does not reflect toward it.
 * `snap_grid` (the view's cells across and up, 0: none): the live view places each
 * vertex at the centre of its cell of a grid a few pixels apart (pixel centres for a
 * one-pixel grid; reflected_meshes.SNAP_SHARE): a triangle within one cell collapses to
 * a point and is dropped before rasterisation, and neighbours sharing a vertex still
 * meet. */

/* An answer texel's code: found (FOUND_CODE modulo 16), flipped (FLIPPED_CODE), placed
 * without an answer (PLACED_CODE). */
bool is_found(float code)
{
  return int(code) % 16 == FOUND_CODE;
}

bool is_flipped(float code)
{
  return (int(code) / FLIPPED_CODE) % 2 == 1;
}

#ifdef IMAGES
/* A folded mirror's answers hold IMAGES slots, one below another (iterative_search.glsl's
 * search_images), and the meshes are drawn as triangle corners, a slot at a time: the
 * first corner's answer in `slot`, and each other corner's answer of the same parity
 * (flipped or not) nearest to it. The corners of a small triangle seen in one image lie
 * next to each other on the mirror, and its images elsewhere lie farther; where a
 * corner's nearest answer is another image all the same (its own is missing), the
 * fragment stage's law of reflection (reflected_meshes.FOLDED_REFLECTION_COSINE) drops
 * the triangle's fragments. */
vec4 matched_answer(ivec2 texel, int result_width, out ivec2 chosen)
{
  int rows = textureSize(search_result, 0).y / IMAGES;
  ivec2 anchor_texel = ivec2(anchor_index % result_width, anchor_index / result_width);
  chosen = anchor_texel + ivec2(0, slot * rows);
  vec4 anchor = texelFetch(search_result, chosen, 0);
  if (vertex_index == anchor_index) {
    return anchor;
  }
  if (!is_found(anchor.w)) {
#ifdef EXIT_POINTS
    /* Through glass each corner where its own search put it (an answer in this slot, or
     * placed, PLACED_CODE): the fragment stage's ray cast keeps what the pixels' rays hit. */
    chosen = texel + ivec2(0, slot * rows);
    return texelFetch(search_result, chosen, 0);
#else
    return anchor;  /* collapsed with the anchor: no area, dropped before set-up */
#endif
  }
  /* Without an answer of its own: unanswered, or placed (glass, PLACED_CODE) in its first slot. */
  chosen = texel;
  vec4 nearest = texelFetch(search_result, texel, 0);
  if (is_found(nearest.w)) {
    nearest.w = 0.0;
  }
  float best = 1e30;
  bool anchor_flipped = is_flipped(anchor.w);
  for (int k = 0; k < IMAGES; k++) {
    vec4 candidate = texelFetch(search_result, texel + ivec2(0, k * rows), 0);
    /* An image of the other parity lies across a fold from the anchor's: it counts as
     * farther than any of the same parity (beside a fold, a neighbour's two images lie
     * on both sides of the anchor's, the wrong one as near as the right one). */
    bool other_parity = is_flipped(candidate.w) != anchor_flipped;
    float apart = length(candidate.xyz - anchor.xyz) + (other_parity ? 1e20 : 0.0);
#ifdef EXIT_POINTS
    /* Through glass the anchor's own slot first: images keep their order (of entry
     * angle) from vertex to vertex, and beside a caustic the nearest may be another. */
    apart *= k == slot ? 1.0 : 1e10;
#endif
    if (is_found(candidate.w) && apart < best) {
      best = apart;
      nearest = candidate;
      chosen = texel + ivec2(0, k * rows);
    }
  }
  return nearest;
}
#endif

void main()
{
  int result_width = textureSize(vertex_positions, 0).x;
  ivec2 texel = ivec2(vertex_index % result_width, vertex_index / result_width);
  /* The texel of the answer taken (its slot's, for the exit point through glass). */
  ivec2 chosen = texel;
#ifdef IMAGES
  vec4 found = matched_answer(texel, result_width, chosen);
#else
  vec4 found = texelFetch(search_result, texel, 0);
#endif
  vec3 vertex = texelFetch(vertex_positions, texel, 0).xyz;
  vec3 p = found.xyz;
  vec4 clip = view_projection * vec4(p, 1.0);
  bool valid = is_found(found.w) && clip.w > 0.0;
  bool flipped = is_flipped(found.w);
  bool placed = false;
  vec3 to_mirror = p - vertex;
#ifdef EXIT_POINTS
  /* Seen through glass (refraction_search.glsl): along the ray leaving it at the exit
   * point; two vertices on one pixel share the path inside, so the distance from the exit
   * orders them as the distance from P would. */
  to_mirror = texelFetch(exit_points, chosen, 0).xyz - vertex;
  mesh_point_interp = vertex;
  mesh_interp = int(texelFetch(vertex_positions, texel, 0).w);
  barycentric_interp = vec3(corner == 0, corner == 1, corner == 2);
  placed = !valid && int(found.w) >= PLACED_CODE && clip.w > 0.0;
#endif
  float distance = length(to_mirror);
  color_interp = color;
  normal_interp = normal_lit.xyz;
  lit_interp = normal_lit.w;
  uv_interp = uv;
  eye_interp = to_mirror / max(distance, 1e-30);
  distance_interp = distance;
  mirror_point_interp = p;
  first_order_interp = 1.0;
  reflector_interp = reflector_id;
  valid_interp = valid ? (flipped ? -1.0 : 1.0) : 0.0;
  float depth = clamp(distance * inverse_diameter, 0.0, 1.0) * order_range;
  vec2 ndc = clip.xy / clip.w;
  if (!valid && !placed) {
    ndc = (floor(ndc * (0.5 * UNANSWERED_CELLS)) + 0.5) / (0.5 * UNANSWERED_CELLS);
  }
  else if (snap_grid.x > 0.0) {
    ndc = snapped(ndc, snap_grid);
  }
  gl_Position = clip.w > 0.0 ? vec4(ndc, depth * 2.0 - 1.0, 1.0) : vec4(0.0, 0.0, 1.0, 1.0);
}
