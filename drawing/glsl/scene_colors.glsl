/* SPDX-License-Identifier: GPL-3.0-or-later */
/* What a ray meets in the scene, lit (drawing/methods/scene_tables.py; scene_bvh.glsl and
 * reflection_shading.glsl before this). Expects the push constants `t_min`, `leaf_first`
 * and `max_order`, WORLD_COLOR (the `world` push constant's, or black), the tables `vertex_colors` and `vertex_normals` (normal,
 * lit) beside the tree's, the image samplers `scene_image0` .. `scene_image<MAX_IMAGES - 1>`
 * and `vertex_uvs`. */

/* Bilinear lookup of `image` at `uv`, repeating, texel centres at (k + 0.5) / size: the CPU
 * tracer's (band_trace.sample_image), whatever the sampler's state. */
vec4 bilinear(sampler2D image, vec2 uv)
{
  ivec2 size = textureSize(image, 0);
  vec2 x = uv * vec2(size) - 0.5;
  vec2 low = floor(x);
  vec2 w = x - low;
  ivec2 a = (ivec2(low) % size + size) % size;
  ivec2 b = (a + 1) % size;
  return mix(mix(texelFetch(image, a, 0), texelFetch(image, ivec2(b.x, a.y), 0), w.x),
             mix(texelFetch(image, ivec2(a.x, b.y), 0), texelFetch(image, b, 0), w.x), w.y);
}

/* The first MAX_IMAGES image textures at `uv` (white past them). */
vec4 scene_image(int image, vec2 uv)
{
  if (image == 0) {
    return bilinear(scene_image0, uv);
  }
  if (image == 1) {
    return bilinear(scene_image1, uv);
  }
  if (image == 2) {
    return bilinear(scene_image2, uv);
  }
  if (image == 3) {
    return bilinear(scene_image3, uv);
  }
  return vec4(1.0);
}

/* The lit colour the ray meets (the refracted or reflected meshes' shading: vertex colour
 * times image texture, lit with the true direction back along the ray, SBC paper section
 * V-C), or WORLD_COLOR, and in `distance` how far along its last segment (-1: the world).
 * `known` is false where it meets an image texture past the first MAX_IMAGES (the
 * caller leaves that pixel to another method). A mirror reflects the ray off its smooth
 * normal, `bounces` times at most, as band_trace.BandTracer.trace_rays follows it: where
 * it would reflect once more, or the reflection turns through its face, the world shows.
 * `skip`: a slot the ray leaves (-1: none). */
vec3 traced_color(vec3 origin, vec3 direction, int skip, int bounces, out bool known, out float distance)
{
  known = true;
  distance = -1.0;
  for (int order = 0; order <= bounces; order++) {
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
      vec4 albedo = weights.x * table_texel(vertex_colors, v.x) + weights.y * table_texel(vertex_colors, v.y) +
                    weights.z * table_texel(vertex_colors, v.z);
      int image = int(corners.w);
      if (image >= 0) {
        known = image < MAX_IMAGES;
        vec2 texel_uv = weights.x * table_texel(vertex_uvs, v.x).xy + weights.y * table_texel(vertex_uvs, v.y).xy +
                        weights.z * table_texel(vertex_uvs, v.z).xy;
        albedo *= scene_image(image, texel_uv);
      }
      distance = t;
      return shade(albedo.rgb, n0.w, normal, -direction);
    }
    vec3 a = table_texel(scene_vertices, v.x).xyz;
    vec3 face = cross(table_texel(scene_vertices, v.y).xyz - a, table_texel(scene_vertices, v.z).xyz - a);
    vec3 reflected = reflect(direction, normalize(normal));
    if (order == bounces || dot(direction, face) * dot(reflected, face) >= 0.0) {
      break;
    }
    origin += t * direction;
    direction = reflected;
    skip = slot;
  }
  return WORLD_COLOR;
}
