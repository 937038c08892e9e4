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
 * it must reflect totally and does not reflect, `reflects` 0, as a Refraction BSDF).
 *
 * The refracted meshes' fragment stage (reflection_mesh_frag.glsl, REFRACTION_TEST) casts
 * this ray at each fragment's triangle: the refraction's counterpart of the mirrors'
 * law-of-reflection test. The search of the next frame starts from the pixels whose rays
 * pass nearest each vertex (refraction_search.glsl, `pixel_guesses`). */

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
  vec3 origin, direction;
  float start;
  pixel_ray(inverse_view_projection, camera, pixel, view_size, origin, direction, start);
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
  bool dark = status == TOTAL_REFLECTION && reflects == 0;
  imageStore(entry_rays, pixel, vec4(d, glass_id));
  imageStore(exit_rays, pixel, vec4(b + centre, float(status)));
  imageStore(leaving_rays, pixel, vec4(o, dark ? -max_radius : max_radius));
}
