/* SPDX-License-Identifier: GPL-3.0-or-later */
/* Polish Node Images on the GPU: each node image moved onto the mirror's exact
 * reflection point of its scene point near it, the float32 twin of
 * engine/methods/morphing/image_polish.py's Newton (engine/reference/exact.py,
 * newton_in_triangles: the law of reflection in a triangle's barycentric (u, v), the
 * half vector minus the interpolated normal in two axes of its plane).
 *
 * Where the numpy twin finds each triangle by a ray through the BVH, this one walks:
 * from the triangle a grid cell holds (engine/geometry/triangle_grid.py), across the
 * edge of the most negative barycentric weight, to the triangle under the image
 * (locate). Newton then runs in that triangle, as in the numpy twin (its plane and
 * normals extended past its edges); where the root lies outside, the next round starts
 * in the triangle under the root, up to ROUNDS. Newton kept in one triangle and
 * walking only between rounds is what converges: walking inside Newton's loop, the
 * iterate crossed edges where the in-plane residual jumps (images seen 80-87 degrees
 * off the normal) and wandered off.
 *
 * One invocation per image, the texel (x, y) of the result (row y * work_width + x),
 * reading the texels (2 x, y) and (2 x + 1, y) of `work`: (point, 0), (image, 0); `mirror`: six
 * texels per triangle, (corner k, neighbour opposite k) for k = 0..2, then the three
 * corner normals, the first with the triangle's closed side (ReflectorSet.closed_sides);
 * `cells`: the grid's triangle per cell, four cells a texel; `params`:
 * (eye, 0), (grid origin, cell size), (grid shape, 0). Output: (reflection point,
 * 1) where one is found, else (0, 0, 0, 0). Every position is relative to the mirror's
 * centre (float32). */

vec3 eye;
vec3 p_point;

vec3 v0;
vec3 e1;
vec3 e2;
vec3 n0;
vec3 n1;
vec3 n2;
vec3 axis_u;
vec3 axis_v;
ivec3 across;
float closed_side;
float orientation;

vec4 param(int k) { return texelFetch(params, ivec2(k, 0), 0); }

vec4 mirror_texel(int t, int k)
{
  int i = t * 6 + k;
  return texelFetch(mirror, ivec2(i % mirror_width, i / mirror_width), 0);
}

int grid_triangle(vec3 x)
{
  vec4 origin = param(1);
  ivec3 shape = ivec3(param(2).xyz);
  ivec3 c = ivec3(floor((x - origin.xyz) / origin.w));
  if (any(lessThan(c, ivec3(0))) || any(greaterThanEqual(c, shape))) {
    return -1;
  }
  int flat_index = (c.x * shape.y + c.y) * shape.z + c.z;
  int texel = flat_index / 4;
  vec4 four = texelFetch(cells, ivec2(texel % cells_width, texel / cells_width), 0);
  return int(four[flat_index % 4]);
}

void load_triangle(int t)
{
  vec4 c0 = mirror_texel(t, 0);
  vec4 c1 = mirror_texel(t, 1);
  vec4 c2 = mirror_texel(t, 2);
  v0 = c0.xyz;
  e1 = c1.xyz - c0.xyz;
  e2 = c2.xyz - c0.xyz;
  across = ivec3(int(c0.w), int(c1.w), int(c2.w));
  vec4 normal0 = mirror_texel(t, 3);
  n0 = normal0.xyz;
  closed_side = normal0.w;
  n1 = mirror_texel(t, 4).xyz;
  n2 = mirror_texel(t, 5).xyz;
  vec3 face = normalize(cross(e1, e2));
  axis_u = normalize(e1);
  axis_v = cross(face, axis_u);
}

vec3 surface_point(vec2 uv) { return v0 + uv.x * e1 + uv.y * e2; }

vec3 surface_normal(vec2 uv) { return normalize(n0 + uv.x * (n1 - n0) + uv.y * (n2 - n0)) * orientation; }

vec2 residual(vec2 uv)
{
  vec3 x = surface_point(uv);
  vec3 half_vector = normalize(normalize(eye - x) + normalize(p_point - x));
  vec3 r = half_vector - surface_normal(uv);
  return vec2(dot(r, axis_u), dot(r, axis_v));
}

/* (u, v) of x projected onto the loaded triangle's plane. */
vec2 plane_coordinates(vec3 x)
{
  vec3 offset = x - v0;
  float a = dot(e1, e1);
  float b = dot(e1, e2);
  float c = dot(e2, e2);
  float p = dot(offset, e1);
  float q = dot(offset, e2);
  return vec2(c * p - b * q, a * q - b * p) / max(a * c - b * b, 1e-30);
}

/* The same, clamped into the triangle. */
vec2 plane_barycentric(vec3 x)
{
  vec2 uv = clamp(plane_coordinates(x), 0.0, 1.0);
  return uv / max(uv.x + uv.y, 1.0);
}

/* The triangle under x: from `t`, across the edge of the most negative barycentric
 * weight of x's projection, while there is one (at most LOCATE_STEPS; -1 off an open edge). */
int locate(int t, vec3 x)
{
  for (int k = 0; k < LOCATE_STEPS; k++) {
    load_triangle(t);
    vec2 uv = plane_coordinates(x);
    vec3 w = vec3(1.0 - uv.x - uv.y, uv.x, uv.y);
    float low = min(w.x, min(w.y, w.z));
    if (low >= -INSIDE_TOLERANCE) {
      return t;
    }
    t = across[w.x == low ? 0 : (w.y == low ? 1 : 2)];
    if (t < 0) {
      return -1;
    }
  }
  return t;
}

/* Newton's method in the loaded triangle from `uv` (exact.newton_in_triangles). */
vec2 newton(vec2 uv)
{
  vec2 du = vec2(DIFFERENCE_STEP, 0.0);
  vec2 dv = vec2(0.0, DIFFERENCE_STEP);
  for (int iteration = 0; iteration < ITERATIONS; iteration++) {
    vec2 g = residual(uv);
    mat2 jacobian = mat2((residual(uv + du) - residual(uv - du)) / (2.0 * DIFFERENCE_STEP),
                         (residual(uv + dv) - residual(uv - dv)) / (2.0 * DIFFERENCE_STEP));
    if (abs(determinant(jacobian)) < 1e-20) {
      break;
    }
    vec2 step = inverse(jacobian) * g;
    float length_step = length(step);
    step *= min(1.0, MAX_STEP / max(length_step, 1e-30));
    /* Backtracking: near the mirror the direction to the point swings fast. */
    float size = length(g);
    for (int halving = 0; halving < BACKTRACK_HALVINGS; halving++) {
      if (length(residual(uv - step)) < size) {
        break;
      }
      step *= 0.5;
    }
    uv = clamp(uv - step, -2.0, 3.0);
    bool far_outside = min(uv.x, uv.y) < -ABANDON_DISTANCE || uv.x + uv.y > 1.0 + ABANDON_DISTANCE;
    if (length_step < STEP_TOLERANCE || (far_outside && iteration >= ABANDON_AFTER)) {
      break;
    }
  }
  return uv;
}

/* The reflection point of p_point near `target` seen from `eye` (both set), as (point,
 * 1), else zeros. */
vec4 polish(vec3 target)
{
  vec4 answer = vec4(0.0);
  int triangle = grid_triangle(target);
  for (int round_count = 0; round_count < ROUNDS && triangle >= 0; round_count++) {
    triangle = locate(triangle, target);
    if (triangle < 0) {
      break;
    }
    load_triangle(triangle);
    orientation = dot(eye - (v0 + (e1 + e2) / 3.0), cross(e1, e2)) >= 0.0 ? 1.0 : -1.0;
    vec2 uv = newton(plane_barycentric(target));
    vec3 w = vec3(1.0 - uv.x - uv.y, uv.x, uv.y);
    if (min(w.x, min(w.y, w.z)) >= -INSIDE_TOLERANCE) {
      if (length(residual(uv)) < RESIDUAL_TOLERANCE) {
        vec3 x = surface_point(uv);
        vec3 n = surface_normal(uv);
        vec3 face = cross(e1, e2);
        /* Both ends on one side of the surface (image_polish.py: a grazing ray has none),
         * outside a closed mirror (outside_closed_mirror). */
        if (dot(n, eye - x) * dot(n, p_point - x) > 0.0
            && (closed_side == 0.0
                || (closed_side * dot(face, eye - x) > 0.0 && closed_side * dot(face, p_point - x) > 0.0))) {
          answer = vec4(x, 1.0);
        }
      }
      break;
    }
    /* The root lies outside: the next round starts in the triangle under it. */
    target = surface_point(uv);
  }
  return answer;
}

#ifdef FRAME_ANSWERS
/* A frame's blended answers (morph_blend.glsl), polished where they stand: one
 * invocation per vertex, its texel of `answers` (reflector point relative to the
 * renderer's shift, FOUND_CODE; zeros where none) and of `vertex_positions`. `params`
 * rows 3-5 map the renderer's coordinates to the mirror table's, rows 6-8 back. An
 * answer the polish does not place is dropped (polish_gpu.polish_answers, MorphPass._polish). */
vec3 affine(int first, vec3 x)
{
  return vec3(dot(param(first).xyz, x) + param(first).w, dot(param(first + 1).xyz, x) + param(first + 1).w,
              dot(param(first + 2).xyz, x) + param(first + 2).w);
}

void main()
{
  ivec2 texel = ivec2(gl_GlobalInvocationID.xy);
  if (texel.x >= positions_width || texel.y * positions_width + texel.x >= n_rows) {
    return;
  }
  vec4 blended = imageLoad(answers, texel);
  if (blended.w == 0.0) {
    return;
  }
  eye = param(0).xyz;
  p_point = affine(3, texelFetch(vertex_positions, texel, 0).xyz);
  vec4 answer = polish(affine(3, blended.xyz));
  imageStore(answers, texel, answer.w > 0.5 ? vec4(affine(6, answer.xyz), blended.w) : vec4(0.0));
}
#else
void main()
{
  ivec2 texel = ivec2(gl_GlobalInvocationID.xy);
  int row = texel.y * work_width + texel.x;
  if (texel.x >= work_width || row >= n_rows) {
    return;
  }
  p_point = texelFetch(work, ivec2(2 * texel.x, texel.y), 0).xyz;
  eye = param(0).xyz;
  imageStore(result, texel, polish(texelFetch(work, ivec2(2 * texel.x + 1, texel.y), 0).xyz));
}
#endif
