/* SPDX-License-Identifier: GPL-3.0-or-later */
/* What a ray meets in the scene, lit (drawing/methods/scene_tables.py; scene_bvh.glsl and
 * reflection_shading.glsl before this). Expects the push constants `t_min`, `leaf_first`
 * and `max_order`, WORLD_COLOR (the `world` push constant's, or black), the tables
 * `vertex_colors`, `vertex_normals` (normal, lit), `vertex_uvs` (uv, the mesh's image
 * code) and `image_rects` beside the tree's, and the image textures' atlas `scene_images`
 * (drawing/methods/image_atlas.py). */

/* Image texture `rect` (its rectangle in the atlas `scene_images`: lower left texel,
 * width and height) at `uv`: bilinear, repeating within it, texel centres at (k + 0.5) /
 * size, as the CPU's tracer samples the image (band_trace.sample_image). */
vec4 scene_image(vec4 rect, vec2 uv)
{
  ivec2 origin = ivec2(rect.xy);
  ivec2 size = ivec2(rect.zw);
  vec2 x = uv * vec2(size) - 0.5;
  vec2 low = floor(x);
  vec2 w = x - low;
  /* mod of floats: GLSL leaves % of a negative int undefined (llvmpipe's is off but for
   * sizes that are powers of two). */
  ivec2 a = min(ivec2(mod(low, vec2(size))), size - 1);
  ivec2 b = (a + 1) % size;
  return mix(mix(texelFetch(scene_images, origin + a, 0), texelFetch(scene_images, origin + ivec2(b.x, a.y), 0), w.x),
             mix(texelFetch(scene_images, origin + ivec2(a.x, b.y), 0), texelFetch(scene_images, origin + b, 0), w.x),
             w.y);
}

/* Farther than any hit: a segment looked along to its end. */
#define NOWHERE 3.0e38

/* Where a followed ray crossed glass (followed_color): the first glass surface it met
 * (the glass's index, -1 for none; its slot, the point, the normal there facing the ray,
 * the ratio of the indices of refraction before and after it, and whether the glass
 * reflects) and its last crossing out of glass into air (the same, with the direction it
 * came in along and the glass's index); `nested`: it met one glass while inside another,
 * and went on as if it had left the first. */
struct GlassCrossings {
  int first_glass;
  int first_slot;
  vec3 first_position;
  vec3 first_normal;
  float first_ratio;
  bool first_reflects;
  int exit_glass;
  int exit_slot;
  vec3 exit_position;
  vec3 exit_incoming;
  vec3 exit_normal;
  float exit_ior;
  bool exit_reflects;
  bool nested;
};

/* The lit colour the ray meets (the refracted or reflected meshes' shading: vertex colour
 * times image texture, lit with the true direction back along the ray, SBC paper section
 * V-C), or WORLD_COLOR, and in `distance` how far along its last segment (-1: the world).
 * `known` is false where it meets an image texture that did not fit the atlas (the
 * caller leaves that pixel to another method). A mirror reflects the ray off its smooth
 * normal, `bounces` times at most, as band_trace.BandTracer.trace_rays follows it: where
 * it would reflect once more, or the reflection turns through its face, the world shows.
 * Glass (GLASS_CODE) bends the ray by Snell's law off its smooth normal, from the index of
 * the medium the ray is in (`medium`, the glass's index, -1 for air, of index
 * `medium_ior`) into the other's, or past the critical angle reflects it inside (total
 * internal reflection), as engine/glass/paths.py follows Render Image's rays; glass that
 * does not reflect (a Refraction BSDF) loses that light, and a ray still meeting glass
 * after MAX_INTERFACES interfaces is trapped: both black, as Cycles shows them.
 * `skip`: a slot the ray leaves (-1: none); `reach`: how far its first segment is looked
 * along first (a surface known to lie that near is met without walking the tree beyond
 * it; past it, the rest of the segment is looked along too). */
vec3 followed_color(vec3 origin, vec3 direction, int skip, int bounces, int medium, float medium_ior, float reach,
                    out GlassCrossings crossings, out bool known, out float distance)
{
  known = true;
  distance = -1.0;
  crossings = GlassCrossings(-1, -1, vec3(0.0), vec3(0.0), 1.0, false, -1, -1, vec3(0.0), vec3(0.0), vec3(0.0), 1.0,
                             false, false);
  int order = 0;
  int interfaces = 0;
  for (int step = 0; step <= bounces + MAX_INTERFACES; step++) {
    float t = reach;
    vec2 uv;
    int slot = nearest_hit(origin, direction, t_min, skip, t, uv);
    if (slot < 0 && reach < NOWHERE) {
      t = NOWHERE;
      slot = nearest_hit(origin, direction, t_min, skip, t, uv);
    }
    reach = NOWHERE;
    if (slot < 0) {
      break;
    }
    vec3 weights = vec3(1.0 - uv.x - uv.y, uv);
    ivec3 v = slot_corners(slot);
    vec4 uv0 = table_texel(vertex_uvs, v.x); /* z: the mesh's image index, or MIRROR_CODE, GLASS_CODE */
    vec4 n0 = table_texel(vertex_normals, v.x);
    vec3 normal = weights.x * n0.xyz + weights.y * table_texel(vertex_normals, v.y).xyz +
                  weights.z * table_texel(vertex_normals, v.z).xyz;
    if (uv0.z > MIRROR_CODE + 0.5) {
      vec4 albedo = weights.x * table_texel(vertex_colors, v.x) + weights.y * table_texel(vertex_colors, v.y) +
                    weights.z * table_texel(vertex_colors, v.z);
      int image = int(uv0.z);
      if (image >= 0) {
        vec4 rect = table_texel(image_rects, image);
        known = rect.z > 0.5; /* else it did not fit the atlas */
        vec2 texel_uv = weights.x * uv0.xy + weights.y * table_texel(vertex_uvs, v.y).xy +
                        weights.z * table_texel(vertex_uvs, v.z).xy;
        albedo *= known ? scene_image(rect, texel_uv) : vec4(1.0);
      }
      distance = t;
      return shade(albedo.rgb, n0.w, normal, -direction);
    }
    vec3 hit = origin + t * direction;
    if (uv0.z < GLASS_CODE + 0.5) {
      vec4 glass = table_texel(vertex_colors, v.x); /* index of refraction, reflects, index */
      int index = int(round(glass.z));
      vec3 facing = normalize(normal);
      facing = dot(facing, direction) > 0.0 ? -facing : facing;
      bool leaving = medium == index;
      float ior = leaving ? 1.0 : glass.x;
      if (crossings.first_glass < 0) {
        crossings.first_glass = index;
        crossings.first_slot = slot;
        crossings.first_position = hit;
        crossings.first_normal = facing;
        crossings.first_ratio = medium_ior / ior;
        crossings.first_reflects = glass.y > 0.5;
      }
      if (interfaces == MAX_INTERFACES) {
        return vec3(0.0);
      }
      interfaces++;
      crossings.nested = crossings.nested || (medium >= 0 && !leaving);
      vec3 bent = refract(direction, facing, medium_ior / ior);
      origin = hit;
      skip = slot;
      if (dot(bent, bent) == 0.0) {
        if (glass.y < 0.5) {
          return vec3(0.0);
        }
        direction = reflect(direction, facing);
        continue;
      }
      if (leaving) {
        crossings.exit_glass = index;
        crossings.exit_slot = slot;
        crossings.exit_position = hit;
        crossings.exit_incoming = direction;
        crossings.exit_normal = facing;
        crossings.exit_ior = glass.x;
        crossings.exit_reflects = glass.y > 0.5;
      }
      medium = leaving ? -1 : index;
      medium_ior = ior;
      direction = normalize(bent);
      continue;
    }
    vec3 a = table_texel(scene_vertices, v.x).xyz;
    vec3 face = cross(table_texel(scene_vertices, v.y).xyz - a, table_texel(scene_vertices, v.z).xyz - a);
    vec3 reflected = reflect(direction, normalize(normal));
    if (order == bounces || dot(direction, face) * dot(reflected, face) >= 0.0) {
      break;
    }
    order++;
    origin = hit;
    direction = reflected;
    skip = slot;
  }
  return WORLD_COLOR;
}

/* followed_color from air, its crossings dropped: what a mirror's reflected ray shows. */
vec3 traced_color(vec3 origin, vec3 direction, int skip, int bounces, out bool known, out float distance)
{
  GlassCrossings crossings;
  return followed_color(origin, direction, skip, bounces, -1, 1.0, NOWHERE, crossings, known, distance);
}
