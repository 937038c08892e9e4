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
#ifdef REFRACTION_TEST
  /* Before any discard: screen derivatives need the whole 2 x 2 quad. */
  vec3 across_x = dFdx(mesh_point_interp);
  vec3 across_y = dFdy(mesh_point_interp);
  vec3 dFdx_barycentric = dFdx(barycentric_interp);
  vec3 dFdy_barycentric = dFdy(barycentric_interp);
  vec4 exit_ray = texelFetch(glass_exits, ivec2(gl_FragCoord.xy), 0);
#endif
#if defined(SEARCHED) && !defined(REFRACTION_TEST)
  /* Iterative search (iterative_mesh_vert.glsl): a triangle with an unanswered corner, or
   * joining a flipped image (-1) to a direct one (1). Through glass the ray cast below
   * decides. */
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
#ifdef REFRACTION_TEST
  /* Through glass, a ray cast: the pixel's own refracted path (glass_rays.glsl) must
   * exist, and its ray leaving the glass is met with the plane of the fragment's
   * triangle, spanned by the screen derivatives of the point of the mesh. The meeting
   * point's barycentric coordinates follow from theirs (both are affine across the drawn
   * triangle, wherever its corners were placed), so whether the ray hits the triangle is
   * exact: a hit, within OUTSIDE_PX of the drawn edges (a pixel whose ray meets the
   * neighbour a fraction of a pixel away). Where a strong lens magnifies a coarse
   * triangle its straight image strays from its true one, and the rays that hit it cross
   * its neighbours' images: a fragment of a triangle whose corners were all answered (in
   * images of one parity) stands in where its ray passes the fragment's point within
   * REFRACTION_REACH of the meshes' subdivision limit (engine/geometry/subdivision.py: a
   * share of the larger of the glass's radius and the point's distance from its centre,
   * here bounded by the distance from the exit plus the radius). A triangle drawn across
   * two images of a lens (either side of a focus) spans pixels whose rays pass it farther
   * off, and is dropped. A hit lies at the distance along its ray to the plane, a stand-in
   * at its own. */
  if (int(exit_ray.w) != PATH_FOUND) {
    discard;
  }
  vec4 leaving = texelFetch(glass_leaving, ivec2(gl_FragCoord.xy), 0);
  vec3 plane_normal = cross(across_x, across_y);
  float rate = dot(leaving.xyz, plane_normal);
  float ahead = dot(mesh_point_interp - exit_ray.xyz, plane_normal) / (abs(rate) > 1e-30 ? rate : 1e-30);
  vec3 offset = exit_ray.xyz + ahead * leaving.xyz - mesh_point_interp;
  float xx = dot(across_x, across_x);
  float xy = dot(across_x, across_y);
  float yy = dot(across_y, across_y);
  float det = xx * yy - xy * xy;
  /* The hit's offset from this fragment, in pixels of the drawn triangle. */
  vec2 moved = vec2(yy * dot(offset, across_x) - xy * dot(offset, across_y),
                    xx * dot(offset, across_y) - xy * dot(offset, across_x)) / max(det, 1e-38);
  vec3 at = barycentric_interp + moved.x * dFdx_barycentric + moved.y * dFdy_barycentric;
  /* Each coordinate's fall per pixel is its gradient's length. */
  vec3 per_pixel = sqrt(dFdx_barycentric * dFdx_barycentric + dFdy_barycentric * dFdy_barycentric);
  bool hit = ahead > 0.0 && det > 0.0 && all(greaterThanEqual(at, -OUTSIDE_PX * per_pixel));
  float radius = abs(leaving.w);
  float reach = REFRACTION_REACH * max(radius, length(mesh_point_interp - exit_ray.xyz) + radius);
  /* The ray through the mesh's bounding box (slabs): a stand-in for a mesh it misses
   * would show the mesh where the pixel sees past it. */
  vec3 low = texelFetch(mesh_boxes, ivec2(2 * mesh_interp, 0), 0).xyz - exit_ray.xyz;
  vec3 high = texelFetch(mesh_boxes, ivec2(2 * mesh_interp + 1, 0), 0).xyz - exit_ray.xyz;
  vec3 inverse = 1.0 / leaving.xyz;
  vec3 t0 = min(low * inverse, high * inverse);
  vec3 t1 = max(low * inverse, high * inverse);
  bool through_box = max(max(t0.x, t0.y), max(t0.z, 0.0)) <= min(min(t1.x, t1.y), t1.z);
  bool stands_in = abs(valid_interp) >= VALID_THRESHOLD && ahead > 0.0 && dot(offset, offset) <= reach * reach &&
                   through_box;
  if (!hit && !stands_in) {
    discard;
  }
  gl_FragDepth = clamp((hit ? ahead : distance_interp) * inverse_diameter, 0.0, 1.0) * order_range;
#endif
  vec4 albedo = color_interp;
  if (use_image != 0) {
    albedo *= texture(image, uv_interp);
  }
  color_out = vec4(shade(albedo.rgb, lit_interp, normal_interp, eye_interp), 1.0 + max(distance_interp, 0.0));
}
