/* SPDX-License-Identifier: GPL-3.0-or-later */
/* What each mirror pixel reflects, ray traced, compute stage (drawing/methods/traced_pass.py),
 * every frame after the pre-pass: one invocation per pixel of the traced mirrors' box on
 * screen (`rect`: x0, y0, x1, y1).
 *
 * Where the pre-pass saw a traced mirror (`traced_reflectors`, 1 per reflector index the
 * pass draws), the eye's ray meets it at the pre-pass's depth, where the rasteriser
 * interpolated its smooth normal (in float32, perspective-correct: the normal a ray's hit
 * interpolates). The ray is reflected there and met with the scene (scene_colors.glsl's
 * `traced_color`, reflecting off mirrors `max_order` more times): every image of every
 * point, folds and all, as Render Image traces its band (engine/geometry/band_trace.py).
 * Output `traced_colors`: (colour, 1 + its distance from the last mirror), or MISSED
 * where the ray meets nothing (the composite shows the world); 0 where the ray meets an
 * image texture that did not fit the atlas (nothing is drawn there). */

void main()
{
  ivec2 pixel = ivec2(gl_GlobalInvocationID.xy) + rect.xy;
  if (pixel.x >= rect.z || pixel.y >= rect.w) {
    return;
  }
  vec4 label = texelFetch(prepass_labels, pixel, 0);
  int mirror = int(round(label.x)) - 1;
  if (mirror < 0 || table_texel(traced_reflectors, mirror).x < 0.5) {
    return;
  }
  vec3 origin, direction;
  float start;
  pixel_ray(inverse_view_projection, camera, pixel, vec2(textureSize(prepass_labels, 0)), origin, direction, start);
  vec3 point = origin + (label.w - start) * direction;
  vec3 normal = normalize(texelFetch(prepass_normals, pixel, 0).xyz);
  normal = dot(normal, direction) > 0.0 ? -normal : normal;
  bool known;
  float distance;
  vec3 color = traced_color(point, reflect(direction, normal), -1, max_order, known, distance);
  if (known) {
    imageStore(traced_colors, pixel, distance < 0.0 ? vec4(0.0, 0.0, 0.0, MISSED) : vec4(color, 1.0 + distance));
  }
}
