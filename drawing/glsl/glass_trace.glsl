/* SPDX-License-Identifier: GPL-3.0-or-later */
/* What each glass pixel's leaving rays meet, compute stage (drawing/methods/scene_trace.py),
 * every frame after the pixels' paths (glass_rays.glsl): one invocation per pixel of a
 * glass's box on screen (`rect`: x0, y0, x1, y1).
 *
 * Where the path left the glass (exit status FOUND, not dark), its ray from the exit is
 * met with the scene (scene_bvh.glsl) and the hit lit as the refracted meshes light a
 * vertex: its interpolated colour and normal, with the true direction back along the ray
 * (reflection_shading.glsl, SBC paper section V-C); a ray that meets nothing shows the
 * `world` colour, one that meets a mirror what the mirror reflects (`traced_color`). Where glass that reflects reflected a share back inside as the path
 * left, the ray that share leaves along is met likewise and mixed in by it (black where
 * that path does not leave), as Render Image mixes it (blender/glass_layer.py). Output
 * `traced_colors`: (colour, 1); 0 where the pixel is left to the refracted meshes: its
 * path was not followed out, or a ray meets a mesh with an image texture. Where glass
 * that reflects is seen, the ray it reflects there is met likewise: `front_colors`, what
 * the composite shows beneath the refraction, by the same reflectance (left as it was,
 * the world colour, where that ray meets an image texture). */

/* The lit colour the ray meets, or `world`; `textured` where it meets an image texture. A
 * mirror (seen through the glass) reflects the ray off its smooth normal, `max_order`
 * times at most, as Render Image follows it (band_trace.BandTracer.trace_rays): where it
 * would reflect once more, or the reflection turns through its face, the world shows. */
vec3 traced_color(vec3 origin, vec3 direction, out bool textured)
{
  textured = false;
  int skip = -1;
  for (int order = 0; order <= max_order; order++) {
    float t;
    vec2 uv;
    int slot = nearest_hit(origin, direction, t_min, skip, t, uv);
    if (slot < 0) {
      break;
    }
    vec4 corners = table_texel(bvh_slots, slot);
    vec3 weights = vec3(1.0 - uv.x - uv.y, uv);
    ivec3 v = ivec3(corners.xyz);
    vec4 n0 = table_texel(vertex_normals, v.x);
    vec3 normal = weights.x * n0.xyz + weights.y * table_texel(vertex_normals, v.y).xyz +
                  weights.z * table_texel(vertex_normals, v.z).xyz;
    if (corners.w > MIRROR_CODE + 0.5) {
      textured = corners.w >= 0.0;
      vec4 albedo = weights.x * table_texel(vertex_colors, v.x) + weights.y * table_texel(vertex_colors, v.y) +
                    weights.z * table_texel(vertex_colors, v.z);
      return shade(albedo.rgb, n0.w, normal, -direction);
    }
    vec3 a = table_texel(scene_vertices, v.x).xyz;
    vec3 face = cross(table_texel(scene_vertices, v.y).xyz - a, table_texel(scene_vertices, v.z).xyz - a);
    vec3 reflected = reflect(direction, normalize(normal));
    if (order == max_order || dot(direction, face) * dot(reflected, face) >= 0.0) {
      break;
    }
    origin += t * direction;
    direction = reflected;
    skip = slot;
  }
  return world.rgb;
}

void main()
{
  ivec2 pixel = ivec2(gl_GlobalInvocationID.xy) + rect.xy;
  if (pixel.x >= rect.z || pixel.y >= rect.w) {
    return;
  }
  vec4 front = texelFetch(front_points, pixel, 0);
  if (front.w > 0.0) {
    bool front_textured;
    vec3 reflected = traced_color(front.xyz, texelFetch(front_rays, pixel, 0).xyz, front_textured);
    if (!front_textured) {
      imageStore(front_colors, pixel, vec4(reflected, 1.0));
    }
  }
  vec4 exit_ray = texelFetch(exit_rays, pixel, 0);
  vec4 leaving = texelFetch(leaving_rays, pixel, 0);
  if (int(round(exit_ray.w)) != FOUND || leaving.w <= 0.0) {
    return;
  }
  bool textured;
  vec3 color = traced_color(exit_ray.xyz, leaving.xyz, textured);
  vec4 back = texelFetch(back_exits, pixel, 0);
  if (!textured && back.w > 0.0) {
    vec4 back_leaving = texelFetch(back_leaving_rays, pixel, 0);
    vec3 reflected = vec3(0.0);
    if (int(round(back_leaving.w)) == FOUND) {
      reflected = traced_color(back.xyz, back_leaving.xyz, textured);
    }
    color = mix(color, reflected, back.w);
  }
  if (!textured) {
    imageStore(traced_colors, pixel, vec4(color, 1.0));
  }
}
