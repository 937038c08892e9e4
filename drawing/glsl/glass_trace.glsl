/* SPDX-License-Identifier: GPL-3.0-or-later */
/* What each glass pixel's leaving rays meet, compute stage (drawing/methods/scene_trace.py),
 * every frame after the pixels' paths (glass_rays.glsl): one invocation per pixel of a
 * glass's box on screen (`rect`: x0, y0, x1, y1).
 *
 * Where the path left the glass (exit status FOUND, not dark), its ray from the exit is
 * met with the scene and lit (scene_colors.glsl's `traced_color`: a mirror shows what it
 * reflects, nothing the `world` colour). Where glass that reflects reflected a share back
 * inside as the path left, the ray that share leaves along is met likewise and mixed in
 * by it (black where that path does not leave), as Render Image mixes it
 * (blender/glass_layer.py). Output `traced_colors`: (colour, 1); 0 where the pixel is
 * left to the refracted meshes: its path was not followed out, or a ray meets an image
 * texture past the first MAX_IMAGES. Where glass that reflects is seen, the ray it
 * reflects there is met likewise: `front_colors`, what the composite shows beneath the
 * refraction, by the same reflectance (left as it was, the world colour, where that ray
 * meets an image texture past those). */

void main()
{
  ivec2 pixel = ivec2(gl_GlobalInvocationID.xy) + rect.xy;
  if (pixel.x >= rect.z || pixel.y >= rect.w) {
    return;
  }
  float distance;
  vec4 front = texelFetch(front_points, pixel, 0);
  if (front.w > 0.0) {
    bool front_known;
    vec3 reflected = traced_color(front.xyz, texelFetch(front_rays, pixel, 0).xyz, -1, max_order, front_known,
                                  distance);
    if (front_known) {
      imageStore(front_colors, pixel, vec4(reflected, 1.0));
    }
  }
  vec4 exit_ray = texelFetch(exit_rays, pixel, 0);
  vec4 leaving = texelFetch(leaving_rays, pixel, 0);
  if (int(round(exit_ray.w)) != FOUND || leaving.w <= 0.0) {
    return;
  }
  bool known;
  vec3 color = traced_color(exit_ray.xyz, leaving.xyz, -1, max_order, known, distance);
  vec4 back = texelFetch(back_exits, pixel, 0);
  if (known && back.w > 0.0) {
    vec4 back_leaving = texelFetch(back_leaving_rays, pixel, 0);
    vec3 reflected = vec3(0.0);
    if (int(round(back_leaving.w)) == FOUND) {
      reflected = traced_color(back.xyz, back_leaving.xyz, -1, max_order, known, distance);
    }
    color = mix(color, reflected, back.w);
  }
  if (known) {
    imageStore(traced_colors, pixel, vec4(color, 1.0));
  }
}
