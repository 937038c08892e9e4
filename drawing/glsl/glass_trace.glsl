/* SPDX-License-Identifier: GPL-3.0-or-later */
/* What each glass pixel shows, ray traced through the glass's own triangles, compute stage
 * (drawing/methods/glass_trace.py), every frame after the pre-pass: one invocation per
 * pixel of the glass's box on screen (from `rect_origin`, its lower left pixel).
 *
 * Where the pre-pass saw glass, the eye's ray is followed from just before the surface
 * it saw (LEAD of its depth: the point from float32 depth lies within about 1e-6 of it;
 * the surface is looked for within twice that first, a short walk of the tree)
 * through every glass interface and off mirrors (scene_colors.glsl's `followed_color`):
 * convex or not, open sheets, glass seen through glass; from inside the glass the eye is
 * in (`eye_medium`: its index, -1 for air, and index of refraction). Then, as Render
 * Image mixes them
 * (blender/glass_layer.py) and Cycles' Glass BSDF weighs them, by the exact dielectric
 * reflectance (Fresnel's equations): where the path last leaves glass that reflects, the
 * ray reflected back inside is followed until it leaves in turn (black where it does not)
 * and mixed into what the path shows; where the eye's ray first meets glass that
 * reflects, the ray reflected there is followed and mixed in likewise. Output: the
 * pixel's colour in `traced_colors` (alpha 1; 0 where a ray meets an image texture that
 * did not fit the atlas: nothing is drawn there) and in `front_colors` (what the composite
 * shows beneath it: the same colour, whatever the pre-pass's Fresnel weight), its alpha
 * 2 where the path met one glass inside another (glass in glass: a ray leaving the inner
 * glass goes on as if into air), else 1. */

void main()
{
  ivec2 pixel = ivec2(gl_GlobalInvocationID.xy) + rect_origin;
  if (any(greaterThanEqual(pixel, textureSize(prepass_labels, 0)))) {
    return;
  }
  vec4 label = texelFetch(prepass_labels, pixel, 0);
  if (label.x < 0.5) {
    return;
  }
  vec3 origin, direction;
  float start;
  pixel_ray(inverse_view_projection, camera, pixel, vec2(textureSize(prepass_labels, 0)), origin, direction, start);
  float depth = label.w - start;
  GlassCrossings path;
  bool known;
  float distance;
  vec4 eye = texelFetch(eye_medium, ivec2(0), 0);
  int medium = int(round(eye.x));
  vec3 color = followed_color(origin + (1.0 - LEAD) * depth * direction, direction, -1, max_order, medium, eye.y,
                              2.0 * LEAD * depth, path, known, distance);
  if (known && path.exit_glass >= 0 && path.exit_reflects) {
    GlassCrossings back_path;
    bool back_known;
    vec3 back = followed_color(path.exit_position, reflect(path.exit_incoming, path.exit_normal), path.exit_slot,
                               max_order, path.exit_glass, path.exit_ior, NOWHERE, back_path, back_known, distance);
    known = back_known;
    color = mix(color, back_path.exit_glass >= 0 ? back : vec3(0.0),
                dielectric_reflectance(-dot(path.exit_incoming, path.exit_normal), path.exit_ior));
  }
  if (known && path.first_glass >= 0 && path.first_reflects) {
    GlassCrossings front_path;
    vec3 front = followed_color(path.first_position, reflect(direction, path.first_normal), path.first_slot,
                                max_order, medium, eye.y, NOWHERE, front_path, known, distance);
    color = mix(color, front, dielectric_reflectance(-dot(direction, path.first_normal), path.first_ratio));
  }
  if (known) {
    imageStore(traced_colors, pixel, vec4(color, 1.0));
    imageStore(front_colors, pixel, vec4(color, path.nested ? 2.0 : 1.0));
  }
}
