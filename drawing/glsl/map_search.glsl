/* SPDX-License-Identifier: GPL-3.0-or-later */
/* What the per-vertex searches on a star-shaped surface's cube map (cube_map.glsl, before
 * this) share (iterative_search.glsl, refraction_search.glsl): the invocation's vertex,
 * the Newton step in a chart of the map, the test of the other maps on a segment and the
 * answer's code. Expects the sampler `vertex_positions`, the
 * image `result`, the push constants `camera`, `w_row`, `stop_per_w`, `n_vertices`,
 * `positions_width`, `warm`, `self_map` and `n_maps`, and the defines OCCLUSION_SAMPLES,
 * FLIPPED_CODE, DERIVATIVE_STEP and TRUST_RADIUS. */

/* The Newton step -J^-1 f for the Jacobian's columns ju, jv (zero where J is singular). */
vec2 newton_step(vec2 ju, vec2 jv, vec2 f)
{
  float det = ju.x * jv.y - jv.x * ju.y;
  return abs(det) > 1e-30 ? -vec2(jv.y * f.x - jv.x * f.y, ju.x * f.y - ju.y * f.x) / det : vec2(0.0);
}

/* The damped Newton step from the residual f and its values fu, fv a DERIVATIVE_STEP along
 * each chart axis: -J^-1 f for the finite-difference Jacobian (its columns left in ju,
 * jv), no longer than TRUST_RADIUS. */
vec2 trusted_step(vec2 f, vec2 fu, vec2 fv, out vec2 ju, out vec2 jv)
{
  ju = (fu - f) / DERIVATIVE_STEP;
  jv = (fv - f) / DERIVATIVE_STEP;
  vec2 delta = newton_step(ju, jv, f);
  float reach = length(delta);
  if (reach > TRUST_RADIUS) {
    delta *= TRUST_RADIUS / reach;
  }
  return delta;
}

float pixel_tolerance(vec3 p)
{
  return stop_per_w * abs(dot(w_row, vec4(p + centre, 1.0)));
}

/* Whether one of OCCLUSION_SAMPLES samples of the segment from `start` (relative to the
 * map in use) along unit `direction`, where it runs inside the map's bounding sphere,
 * lies inside its surface; samples denser next to the start where `dense_near_start`. */
bool segment_blocked(vec3 start, vec3 direction, float length_, bool dense_near_start)
{
  float b = dot(start, direction);
  float disc = b * b - (dot(start, start) - max_radius * max_radius);
  if (disc <= 0.0) {
    return false;
  }
  float root = sqrt(disc);
  float t0 = max(-b - root, 0.0);
  float t1 = min(-b + root, length_);
  if (t1 <= t0) {
    return false;
  }
  for (int k = 0; k < OCCLUSION_SAMPLES; k++) {
    float fraction = dense_near_start ? pow(float(k + 1) / float(OCCLUSION_SAMPLES), 2.0) :
                                        (float(k) + 0.5) / float(OCCLUSION_SAMPLES);
    if (inside_surface(start + (t0 + (t1 - t0) * fraction) * direction)) {
      return true;
    }
  }
  return false;
}

/* The searched vertex, relative to the centre of the searched map (start_search). */
vec3 vertex;

/* This invocation's vertex (one per diffuse vertex, rows of `positions_width`; false
 * past the last vertex): its texel, the searched map in use and `vertex` relative to its
 * centre, the answer texel the last search left, and whether to resume from it (a warm
 * frame, and that search found the vertex's point). */
bool start_search(out ivec2 texel, out vec4 last, out bool resume)
{
  texel = ivec2(gl_GlobalInvocationID.xy);
  if (texel.x >= positions_width || texel.y * positions_width + texel.x >= n_vertices) {
    return false;
  }
  use_map(self_map);
  vertex = texelFetch(vertex_positions, texel, 0).xyz - centre;
  last = imageLoad(result, texel);
  resume = warm != 0 && int(last.w) % 16 == FOUND + 8;
  return true;
}

/* Whether a searched map other than `self_map` holds a point of the segment from `start`
 * to `end` (relative to the renderer's shift): there the path meets another surface the
 * search does not follow. Leaves the last map tested in use. */
bool other_map_blocks(vec3 start, vec3 end)
{
  vec3 along = end - start;
  for (int map = 0; map < n_maps; map++) {
    if (map != self_map) {
      use_map(map);
      if (segment_blocked(start - centre, normalize(along), length(along), false)) {
        return true;
      }
    }
  }
  return false;
}

/* An answer texel's code: (status + 8) + 16 steps, plus FLIPPED_CODE for a found flipped
 * image (reflected_meshes.py reads it). */
float answer_code(int status, int steps, bool flipped)
{
  return float(status + 8) + 16.0 * float(steps) + (status == FOUND && flipped ? float(FLIPPED_CODE) : 0.0);
}
