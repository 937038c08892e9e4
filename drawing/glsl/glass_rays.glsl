/* SPDX-License-Identifier: GPL-3.0-or-later */
/* Each pixel's own path through a convex glass solid, compute stage
 * (drawing/methods/glass_rays.py), every frame after the pre-pass: one invocation per
 * pixel, one dispatch per glass.
 *
 * Where the pre-pass saw this glass (`glass_id`), the surface point it saw (its eye depth,
 * label w, along the pixel's ray) gives the direction from the map's centre; the path
 * enters where the map's surface lies along it and is followed through the glass
 * (glass_path.glsl). Output texels: `entry_rays` (the entry's direction from the map's
 * centre, and `glass_id`), `exit_rays` (the exit B relative to the renderer's
 * shift, and the path's status: FOUND, TOTAL_REFLECTION, ...), `leaving_rays` (the unit
 * ray leaving B, and the glass's bounding radius, negative where the glass shows black:
 * it must reflect totally and does not reflect, `reflects` 0, as a Refraction BSDF); where
 * glass that reflects lets the path out, `back_exits` (where the ray it reflects back
 * inside there leaves, and the share it reflects: the exact dielectric reflectance) and
 * `back_leaving_rays` (the unit ray leaving there, and that path's status); and where glass
 * that reflects is seen, `front_points` (the surface point, and the share it reflects,
 * the exact dielectric reflectance: what the composite weighs its refraction by, 1 minus
 * it) and `front_rays` (the unit ray it reflects there).
 *
 * The refracted meshes' fragment stage (reflection_mesh_frag.glsl, REFRACTION_TEST) casts
 * this ray at each fragment's triangle: the refraction's counterpart of the mirrors'
 * law-of-reflection test. The search of the next frame starts from the pixels whose rays
 * pass nearest each vertex (refraction_search.glsl, `pixel_guesses`); the scene is met
 * along the leaving and the reflected rays (glass_trace.glsl). */

void main()
{
  ivec2 pixel = ivec2(gl_GlobalInvocationID.xy);
  if (pixel.x >= int(view_size.x) || pixel.y >= int(view_size.y)) {
    return;
  }
  vec4 label = texelFetch(prepass_labels, pixel, 0);
  if (abs(label.x - glass_id) > 0.5) {
    return;
  }
  use_map(self_map);
  vec2 ndc = (vec2(pixel) + 0.5) / view_size * 2.0 - 1.0;
  vec4 near = inverse_view_projection * vec4(ndc, -1.0, 1.0);
  vec4 far = inverse_view_projection * vec4(ndc, 1.0, 1.0);
  vec3 direction = normalize(far.xyz / far.w - near.xyz / near.w);
  /* Perspective: from the eye, at eye depth 0; orthographic: from the near plane. */
  vec3 origin = camera.w > 0.5 ? camera.xyz : near.xyz / near.w;
  float start = camera.w > 0.5 ? 0.0 : -dot(origin, camera.xyz);
  vec3 d = normalize(origin + (label.w - start) * direction - centre);
  int status = INSIDE;
  vec3 b = vec3(0.0);
  vec3 o = vec3(0.0);
  vec3 last = vec3(0.0);
  vec3 normal = vec3(0.0);
  if (!(camera.w > 0.5 && inside_surface(camera.xyz - centre))) {
    float radius;
    vec3 n;
    status = map_surface(d, radius, n) ? refracted_path(radius * d, n, b, o, last, normal) : NO_SURFACE;
  }
  if (reflects != 0) {
    /* The ray the glass reflects where the pixel sees it, off the smooth normal the
     * pre-pass drew there (the mesh's, as Render Image reflects it). */
    vec3 normal_seen = normalize(texelFetch(prepass_normals, pixel, 0).xyz);
    normal_seen = dot(normal_seen, direction) > 0.0 ? -normal_seen : normal_seen;
    float share = dielectric_reflectance(-dot(direction, normal_seen), 1.0 / eta);
    imageStore(front_points, pixel, vec4(origin + (label.w - start) * direction, share));
    imageStore(front_rays, pixel, vec4(reflect(direction, normal_seen), 0.0));
  }
  bool dark = status == TOTAL_REFLECTION && reflects == 0;
  imageStore(entry_rays, pixel, vec4(d, glass_id));
  imageStore(exit_rays, pixel, vec4(b + centre, float(status)));
  imageStore(leaving_rays, pixel, vec4(o, dark ? -max_radius : max_radius));
  if (status == FOUND && reflects != 0) {
    /* What glass that reflects reflects back inside where the path leaves: followed until
     * it leaves in turn, once, as Render Image follows it (glass_layer.py). */
    vec3 back_exit, back_leaving, back_last, back_normal;
    int back = leave_glass(b, reflect(last, -normal), back_exit, back_leaving, back_last, back_normal);
    imageStore(back_exits, pixel, vec4(back_exit + centre, dielectric_reflectance(dot(last, normal), eta)));
    imageStore(back_leaving_rays, pixel, vec4(back_leaving, float(back)));
  }
}
