/* SPDX-License-Identifier: GPL-3.0-or-later */
/* Reflected-mesh pass, fragment stage (reflection_mesh_vert.glsl).
 *
 * A reflection is kept only on pixels where the pre-pass saw its sheet's first
 * reflector (id = history[0] + 1, per vertex in `reflector_interp`): that confines it to the visible footprint of the
 * reflector, and real objects in front of the mirror stay in front, their pre-pass id
 * being 0 (Roger & Holzschuch 2006, section 3.3.6, with an id texture for the stencil).
 * Hidden-surface removal between reflected points is the depth test on the depth
 * written by the vertex stage (SBC paper section V-A, cases 2 and 3).
 *
 * Colour: the mesh's own (vertex colour times its image texture, if any) lit with the
 * true eye vector (SBC V-C, reflection_shading.glsl). Alpha is 1 + the distance from the
 * mirror along the reflected ray: > 0.5 marks a drawn reflection, and the composite
 * fades it with that distance (SBC V-D). */

void main()
{
#ifdef SEARCHED
  /* Iterative search (iterative_mesh_vert.glsl): a triangle with an unanswered corner, or
   * joining a flipped image (-1) to a direct one (1). */
  if (!(abs(valid_interp) >= VALID_THRESHOLD)) {  /* NaN too */
    discard;
  }
#endif
  vec4 label = texelFetch(prepass_labels, ivec2(gl_FragCoord.xy), 0);
  if (abs(label.x - reflector_interp) > 0.5) {
    discard;
  }
#ifdef HIDDEN_TEST
  /* A reflector point farther from the eye than the mirror surface the pre-pass saw at
   * this pixel is hidden by the mirror itself (a bump, a handle before the body): the
   * per-frame methods answer a vertex without tracing the eye's ray, so the image of a
   * point reflected behind the front surface would be drawn on it. Where the live view
   * snapped the vertices (`snap_grid`), a fragment lies up to 0.7 of a cell from where its
   * point projects, and beside a silhouette the mirror's depth changes by much of its size
   * within that: the surface is then read at the four pixels around the point's own
   * projection too, the farthest of them of this mirror (a ball's front is convex seen
   * from the eye: none of them nearer than the surface at the point). */
  float surface_depth = label.w;
  if (snap_grid.x > 0.0) {
    vec4 clip = view_projection * vec4(mirror_point_interp, 1.0);
    ivec2 size = textureSize(prepass_labels, 0);
    ivec2 corner = ivec2(floor((clip.xy / clip.w * 0.5 + 0.5) * vec2(size) - 0.5));
    for (int i = 0; i < 4; i++) {
      vec4 around = texelFetch(prepass_labels, clamp(corner + ivec2(i & 1, i >> 1), ivec2(0), size - 1), 0);
      if (abs(around.x - reflector_interp) <= 0.5) {
        surface_depth = max(surface_depth, around.w);
      }
    }
  }
  if (eye_depth(mirror_point_interp, camera) > surface_depth + hidden_tolerance) {
    discard;
  }
#endif
  /* The law of reflection at this pixel (first order): the eye's ray, reflected about the
   * normal of the mirror the pre-pass saw here, must leave toward the fragment's own
   * point of the mesh. A triangle whose corners were answered in different sheets of the
   * reflection (two images of a non-convex mirror in one answer slot, across a fold or a
   * crease) stretches over pixels whose reflected rays point elsewhere: dropped there,
   * instead of a wedge of colour. The per-frame passes compile it out for a mirror with
   * one sheet (LAW_TEST, reflected_meshes.fragment_tests). */
#if !defined(SEARCHED) || defined(LAW_TEST)
  if (first_order_interp > 0.5) {
    vec3 mirror_normal = texelFetch(prepass_normals, ivec2(gl_FragCoord.xy), 0).xyz;
    vec3 incoming = camera.w > 0.5 ? mirror_point_interp - camera.xyz : -camera.xyz;
    vec3 outgoing = reflect(normalize(incoming), normalize(mirror_normal));
    if (dot(outgoing, -normalize(eye_interp)) < reflection_cosine) {
      discard;
    }
  }
#endif
  vec4 albedo = color_interp;
  if (use_image != 0) {
    albedo *= texture(image, uv_interp);
  }
  color_out = vec4(shade(albedo.rgb, lit_interp, normal_interp, eye_interp), 1.0 + max(distance_interp, 0.0));
}
