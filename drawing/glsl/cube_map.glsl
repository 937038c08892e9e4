/* SPDX-License-Identifier: GPL-3.0-or-later */
/* A star-shaped surface's cube map on the GPU (layout in
 * engine/methods/iterative/reflector_map.py): which map is in use, its radius and normal
 * along a direction from its centre, and the status codes of paths on it. Read by the
 * per-vertex searches (map_search.glsl) and the per-pixel glass paths (glass_rays.glsl).
 * Expects the samplers `map_params` and `reflector_maps`. */

#define FOUND 1
#define NOT_CONVERGED 0
#define NO_SURFACE -1
#define FACES_AWAY -2
#define OCCLUDED -3
#define INSIDE -4

/* The map in use (use_map): its centre, radii, rows and size. */
vec3 centre;
float max_radius;
float mean_radius;
float min_radius;
int map_row;
int face_size;
int convex;
int patch_row;
int patch_count;
int images;

void use_map(int map)
{
  vec4 a = texelFetch(map_params, ivec2(3 * map, 0), 0);
  vec4 b = texelFetch(map_params, ivec2(3 * map + 1, 0), 0);
  vec4 c = texelFetch(map_params, ivec2(3 * map + 2, 0), 0);
  centre = a.xyz;
  max_radius = a.w;
  map_row = int(b.x);
  face_size = int(b.y);
  convex = int(b.z);
  mean_radius = b.w;
  patch_row = int(c.x);
  patch_count = int(c.y);
  min_radius = c.z;
  images = max(int(c.w), 1);
}


/* Bilinear radius and normal of the map along unit direction d; false on a hole. */
bool map_surface(vec3 d, out float radius, out vec3 normal)
{
  vec3 m = abs(d);
  int axis = (m.x >= m.y && m.x >= m.z) ? 0 : ((m.y >= m.z) ? 1 : 2);
  float major = d[axis];
  float scale = 1.0 / max(abs(major), 1e-30);
  float u = d[(axis + 1) % 3] * scale;
  float v = d[(axis + 2) % 3] * scale;
  int face = 2 * axis + (major < 0.0 ? 1 : 0);
  float size = float(face_size);
  float fx = (u + 1.0) * 0.5 * size + 0.5;
  float fy = (v + 1.0) * 0.5 * size + 0.5;
  float i = clamp(floor(fx), 0.0, size);
  float j = clamp(floor(fy), 0.0, size);
  float tx = fx - i;
  float ty = fy - j;
  ivec2 base = ivec2(int(i), map_row + face * (face_size + 2) + int(j));
  vec4 a = texelFetch(reflector_maps, base, 0);
  vec4 b = texelFetch(reflector_maps, base + ivec2(1, 0), 0);
  vec4 c = texelFetch(reflector_maps, base + ivec2(0, 1), 0);
  vec4 e = texelFetch(reflector_maps, base + ivec2(1, 1), 0);
  vec4 value = (1.0 - tx) * (1.0 - ty) * a + tx * (1.0 - ty) * b + (1.0 - tx) * ty * c + tx * ty * e;
  bool valid = min(min(a.x, b.x), min(c.x, e.x)) > 0.0;
  radius = valid ? value.x : 0.0;
  normal = value.yzw / max(length(value.yzw), 1e-30);
  return valid;
}

bool inside_surface(vec3 p)
{
  float distance = length(p);
  float radius;
  vec3 normal;
  bool valid = map_surface(p / max(distance, 1e-30), radius, normal);
  return valid && distance < radius;
}

vec3 perpendicular(vec3 d)
{
  vec3 m = abs(d);
  vec3 helper = (m.x <= m.y && m.x <= m.z) ? vec3(1.0, 0.0, 0.0) :
                ((m.y <= m.z) ? vec3(0.0, 1.0, 0.0) : vec3(0.0, 0.0, 1.0));
  return normalize(cross(d, helper));
}
