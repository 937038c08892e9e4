/* SPDX-License-Identifier: GPL-3.0-or-later */
/* The iterative search for reflection points (Roger & Holzschuch 2006), compute stage.
 *
 * The float32 twin of engine/methods/iterative/search.py, step by step: one invocation
 * per diffuse vertex (texel of `vertex_positions`), every frame. The reflector is the
 * cube map of its radius and normal around its centre O (`reflector_map`, layout in
 * engine/methods/iterative/reflector_map.py); the vertex's reflection point P is where
 * the normal bisects the directions to the eye and to the vertex:
 *   1. first guess: the reflection on the sphere of the map's mean radius, by bisection
 *      on the arc between the directions to the eye and to the vertex (section 3.3.4);
 *   2. damped Newton in a gnomonic chart around it on the tangent part of the half
 *      vector (section 3.3.2-3.3.3), Jacobian by finite differences, restarts around
 *      the guess where a start fails;
 *   3. stop when a step moves P by less than `stop_per_w` times the view's clip w at P
 *      (a share of the accuracy in pixels, section 3.2);
 *   4. checks: P faces the eye and the vertex (by the interpolated normal and by the map
 *      surface's own), the residual vanishes, and on a non-convex mirror nothing of it
 *      lies between P and either.
 * A folded mirror's map (images > 1) is searched for every image instead (search_images).
 * Everything runs relative to O. Output texel: (P relative to the renderer's shift,
 * (status + 8) + 16 * steps + FLIPPED_CODE * flipped), status as the numpy twin's
 * (FOUND = 1), flipped: the image lies beyond the caustic (flipped_image). */


/* Push constants: camera (eye relative to the shift, w 1; or the unit direction toward
 * the viewer, w 0), w_row (the view-projection's last row, for clip w), stop_per_w,
 * n_vertices, positions_width, warm (start from the answer of the last search, still in
 * `result`, where it had one), self_map (the searched reflector's map) and n_maps.
 * `reflector_maps` holds every star-shaped reflector's (or piece's) cube map, one below
 * another; `map_params` three texels per map: (O relative to the shift, largest radius),
 * (first row, face size, convex, mean radius) and (first patch, patches, smallest radius,
 * images: answer slots); `map_patches`
 * a piece's patches (engine/methods/iterative/pieces.py), three texels a row: (normal-
 * cone axis, its half-angle), (bounding sphere's centre relative to O, its radius),
 * (start direction, 0). */

vec3 to_eye(vec3 p)
{
  return camera.w > 0.5 ? normalize(camera.xyz - centre - p) : camera.xyz;
}

vec3 sphere_guess(vec3 point)
{
  float distance = length(point);
  vec3 b = point / max(distance, 1e-30);
  vec3 a;
  float reach;
  if (camera.w > 0.5) {
    vec3 eye = camera.xyz - centre;
    a = normalize(eye);
    reach = min(distance, length(eye));
  }
  else {
    a = camera.xyz;
    reach = distance;
  }
  float cosine = clamp(dot(a, b), -1.0, 1.0);
  float theta = acos(cosine);
  vec3 c = b - cosine * a;
  float across = length(c);
  c = across > 1e-9 ? c / across : perpendicular(a);
  float sphere = min(mean_radius, 0.999 * reach);
  float lo = 0.0;
  float hi = theta;
  for (int k = 0; k < GUESS_BISECTIONS; k++) {
    float mid = 0.5 * (lo + hi);
    vec3 u = cos(mid) * a + sin(mid) * c;
    vec3 p = sphere * u;
    float balance = dot(to_eye(p), u) - dot(normalize(point - p), u);
    if (balance > 0.0) {
      lo = mid;
    }
    else {
      hi = mid;
    }
  }
  float phi = 0.5 * (lo + hi);
  return cos(phi) * a + sin(phi) * c;
}

/* The chart around the guess and the residual there. */
vec3 chart_axis;
vec3 chart_t1;
vec3 chart_t2;

bool evaluate(vec2 x, out vec2 f, out vec3 p, out vec3 n, out vec3 h)
{
  vec3 d = normalize(chart_axis + x.x * chart_t1 + x.y * chart_t2);
  float radius;
  bool valid = map_surface(d, radius, n);
  p = radius * d;
  h = to_eye(p) + normalize(vertex - p);
  vec3 tangent = h - dot(h, n) * n;
  f = vec2(dot(tangent, chart_t1), dot(tangent, chart_t2));
  return valid;
}

/* The numpy twin's flipped_images: whether the vertex lies beyond the caustic of the
 * reflected rays seen through its reflection point p (det [Q_u, Q_v, R] < 0 for the map
 * (u, v, t) -> P + t R), from the chart samples pu, pv a step along each chart axis. */
bool flipped_image(vec3 p, vec3 n, vec3 pu, vec3 pv, vec3 nu, vec3 nv)
{
  vec3 r = reflect(-to_eye(p), n);
  float t = length(vertex - p);
  vec3 qu = pu - p + t * (reflect(-to_eye(pu), nu) - r);
  vec3 qv = pv - p + t * (reflect(-to_eye(pv), nv) - r);
  return dot(cross(qu, qv), r) < 0.0;
}

/* Whether the last converged answer of newton() is a flipped image. */
bool flipped;

/* Whether the residual vanishes: the sine of the angle between the normal and the half
 * vector below RESIDUAL_TOLERANCE. */
bool residual_passes(vec3 n, vec3 h)
{
  return length(cross(n, h)) / max(length(h), 1e-30) < RESIDUAL_TOLERANCE;
}

int check(vec3 p, vec3 n, vec3 h, vec3 face)
{
  vec3 e = to_eye(p);
  vec3 v = normalize(vertex - p);
  if (!residual_passes(n, h)) {
    return NOT_CONVERGED;
  }
  if (!(dot(n, e) > 0.0 && dot(n, v) > 0.0 && dot(face, e) > 0.0 && dot(face, v) > 0.0)) {
    return FACES_AWAY;
  }
  if (convex == 0) {
    float eye_length = camera.w > 0.5 ? length(camera.xyz - centre - p) : 1e30;
    if (segment_blocked(p, e, eye_length, true) || segment_blocked(p, v, length(vertex - p), true)) {
      return OCCLUDED;
    }
  }
  return FOUND;
}

/* Whether a start whose line search finds no smaller |F| fails there (search_images:
 * near a fold |F| has minima that are no roots). */
bool give_up_stalled = false;

/* Damped Newton from chart point x; returns NOT_CONVERGED, NO_SURFACE or the verdict
 * of check() on the converged sample (in p). */
int newton(vec2 x, inout int steps, out vec3 p)
{
  vec2 f;
  vec3 n, h, face;
  if (!evaluate(x, f, p, n, h)) {
    return NO_SURFACE;
  }
  for (int step = 0; step < MAX_ITERATIONS; step++) {
    vec2 fu, fv, ft;
    vec3 pt, nt, ht, pu, pv, nu, nv;
    evaluate(x + vec2(DERIVATIVE_STEP, 0.0), fu, pu, nu, ht);
    evaluate(x + vec2(0.0, DERIVATIVE_STEP), fv, pv, nv, ht);
    /* The map surface's own normal: the ray from the eye must meet its front and the
     * reflected ray leave it (as engine/reference/exact.py asks of the facet). */
    vec3 facet = cross(pu - p, pv - p);
    face = dot(facet, p) < 0.0 ? -facet : facet;
    vec2 ju, jv;
    vec2 delta = trusted_step(f, fu, fv, ju, jv);
    /* Line search: scales 1, 1/2, ... until |F| falls; the last one is taken regardless. */
    float current = length(f);
    float scale = 1.0;
    vec3 previous = p;
    vec3 previous_n = n;
    bool valid = false;
    bool fell = false;
    for (int k = 0; k <= HALVINGS; k++) {
      valid = evaluate(x + scale * delta, ft, pt, nt, ht);
      fell = valid && length(ft) < current;
      if (fell || k == HALVINGS) {
        break;
      }
      scale *= 0.5;
    }
    x += scale * delta;
    f = ft;
    p = pt;
    n = nt;
    h = ht;
    steps += 1;
    if (!valid || length(x) > MAX_CHART || give_up_stalled && !fell) {
      return NO_SURFACE;
    }
    /* The step after this one, predicted with this step's Jacobian (a chord step): where
     * it would move P by less than the tolerance, it is taken without new samples (P
     * moved along the chart's tangents, the residual's normal and half vector kept),
     * and the search has converged one step earlier. */
    vec2 next = newton_step(ju, jv, f);
    vec3 predicted = ((pu - previous) * next.x + (pv - previous) * next.y) / DERIVATIVE_STEP;
    float tolerance = pixel_tolerance(p);
    /* Only where the residual already passes check()'s test (a singular Jacobian
     * predicts no step at all). */
    bool settled = length(predicted) < tolerance && residual_passes(n, h);
    if (length(p - previous) < tolerance || settled) {
      flipped = flipped_image(previous, previous_n, pu, pv, nu, nv);  /* read only once converged */
      if (settled) {
        p += predicted;
      }
      return check(p, n, h, face);
    }
  }
  return NOT_CONVERGED;
}

/* The numpy twin's patch_admits: whether patch k of the map in use may hold the vertex's
 * reflection (the half vector between the directions from the patch to the eye and to
 * the vertex within its normals' cone, widened by PATCH_MARGIN and the angles its
 * bounding sphere subtends from both, bounded without trigonometry; or the vertex within
 * NEAR_PATCH radii of it). Every patch is tested for every vertex: two fetches, no
 * transcendental function. */
bool patch_admits(int k)
{
  vec4 cone = texelFetch(map_patches, ivec2(0, patch_row + k), 0);
  vec4 sphere = texelFetch(map_patches, ivec2(1, patch_row + k), 0);
  vec3 to_point = vertex - sphere.xyz;
  float point_distance = max(length(to_point), 1e-30);
  vec3 toward_eye = camera.xyz;
  float eye_slack = 0.0;
  if (camera.w > 0.5) {
    toward_eye = camera.xyz - centre - sphere.xyz;
    float eye_distance = max(length(toward_eye), 1e-30);
    eye_slack = sphere.w / eye_distance;
    toward_eye /= eye_distance;
  }
  vec3 half_vector = normalize(to_point / point_distance + toward_eye);
  float reach = cone.w + PATCH_MARGIN + 1.57079633 * (eye_slack + sphere.w / point_distance);
  return 1.0 - dot(half_vector, cone.xyz) <= 0.5 * reach * reach || point_distance < NEAR_PATCH * sphere.w;
}

/* Whether the vertex or the eye lies inside the mirror (or the vertex at its centre):
 * there it has no reflection. */
bool vertex_or_eye_inside()
{
  bool eye_inside = camera.w > 0.5 && inside_surface(camera.xyz - centre);
  return eye_inside || length(vertex) <= 1e-9 * max(max_radius, 1e-30) || inside_surface(vertex);
}

/* A folded mirror (images > 1, engine/methods/iterative/fold_patches.py): the numpy
 * twin's search_images. Newton from the first guess and from every patch that admits
 * the vertex, each distinct root kept (SAME_IMAGE), up to `images` of them, in answer
 * slots one below another (slot k at row k times the rows of vertices). No warm start:
 * a slot's root may be another image's next frame. */
void search_images(ivec2 texel)
{
  vec4 roots[MAX_IMAGES];
  give_up_stalled = true;
  int count = 0;
  int steps = 0;
  bool inside = vertex_or_eye_inside();
  /* The one-image search's first guess (attempt -1), then every patch that admits the vertex. */
  int next = -1;
  while (!inside && next < patch_count && count < images) {
    int attempt = next;
    if (attempt < 0) {
      chart_axis = sphere_guess(vertex);
    }
    else {
      while (attempt < patch_count && !patch_admits(attempt)) {
        attempt++;
      }
      if (attempt >= patch_count) {
        break;
      }
      chart_axis = texelFetch(map_patches, ivec2(2, patch_row + attempt), 0).xyz;
    }
    next = attempt + 1;
    chart_t1 = perpendicular(chart_axis);
    chart_t2 = cross(chart_axis, chart_t1);
    vec3 answer;
    if (newton(vec2(0.0), steps, answer) != FOUND) {
      continue;
    }
    float same = SAME_IMAGE_PER_STOP * pixel_tolerance(answer);
    bool known = false;
    for (int k = 0; k < count; k++) {
      known = known || length(roots[k].xyz - answer) < same;
    }
    if (!known) {
      roots[count] = vec4(answer, flipped ? 1.0 : 0.0);
      count++;
    }
  }
  int rows = (n_vertices + positions_width - 1) / positions_width;
  vec3 point = vertex + centre;
  vec3 shift = centre;  /* other_map_blocks leaves another map in use */
  for (int k = 0; k < images; k++) {
    int status = inside ? INSIDE : NO_SURFACE;
    vec3 answer = vec3(0.0);
    if (k < count) {
      answer = roots[k].xyz + shift;
      status = other_map_blocks(answer, point) ? OCCLUDED : FOUND;
    }
    /* Every start's steps in slot 0, within the code's step field. */
    int counted = k == 0 ? min(steps, FLIPPED_CODE / 16 - 1) : 0;
    bool image_flipped = k < count && roots[k].w > 0.5;
    imageStore(result, texel + ivec2(0, k * rows), vec4(answer, answer_code(status, counted, image_flipped)));
  }
}

const vec2 starts[5] = vec2[5](vec2(0.0, 0.0), vec2(RESTART_OFFSET, 0.0), vec2(-RESTART_OFFSET, 0.0),
                               vec2(0.0, RESTART_OFFSET), vec2(0.0, -RESTART_OFFSET));

void main()
{
  ivec2 texel;
  vec4 last;
  bool resume;
  if (!start_search(texel, last, resume)) {
    return;
  }
  if (images > 1) {
    search_images(texel);
    return;
  }
  int status = NO_SURFACE;
  int steps = 0;
  bool image_flipped = false;
  vec3 p = vec3(0.0);
  /* Last frame's answer first (attempt -1: the view moved a little), then the restarts
   * around the sphere guess. A found answer faces the eye and the vertex, and on a
   * non-convex mirror no part of the surface lies between them (check()): neither lies
   * inside the mirror, which is tested only before the first restart. One loop calls
   * newton() once: the compiled shader holds one copy of it, not one per start (a copy
   * per start makes the search far slower on llvmpipe). */
  /* A piece of a mirror that is not star-shaped starts from every patch that admits the
   * vertex instead (patch_admits), found by a scan that runs no Newton step: on llvmpipe a
   * loop whose body holds newton() costs nearly all of it per pass, lanes or not. */
  int attempts = patch_count > 0 ? patch_count : (convex != 0 ? 1 : 5);  /* one reflection at most on a convex mirror */
  int next = resume ? -1 : 0;
  bool outside_checked = false;
  while (next < attempts) {
    int attempt = next;
    vec2 start = vec2(0.0);
    if (attempt < 0) {
      chart_axis = normalize(last.xyz - centre);
    }
    else {
      if (!outside_checked) {
        if (vertex_or_eye_inside()) {
          status = INSIDE;
          break;
        }
        outside_checked = true;
        if (patch_count == 0) {
          chart_axis = sphere_guess(vertex);
        }
      }
      if (patch_count > 0) {
        while (attempt < patch_count && !patch_admits(attempt)) {
          attempt++;
        }
        if (attempt >= patch_count) {
          break;
        }
        chart_axis = texelFetch(map_patches, ivec2(2, patch_row + attempt), 0).xyz;
      }
      else {
        start = starts[attempt];
      }
    }
    next = attempt + 1;
    chart_t1 = perpendicular(chart_axis);
    chart_t2 = cross(chart_axis, chart_t1);
    vec3 answer;
    int verdict = newton(start, steps, answer);
    if (attempt == 0 || verdict == FOUND) {
      status = verdict;
      p = answer;
      image_flipped = flipped;
    }
    if (verdict == FOUND) {
      break;
    }
  }
  /* The other star-shaped mirrors may block the reflected segment: there this point's
   * reflection is of another mirror (a higher order). */
  vec3 answer = p + centre;
  if (status == FOUND && other_map_blocks(answer, vertex + centre)) {
    status = OCCLUDED;
  }
  imageStore(result, texel, vec4(answer, answer_code(status, steps, image_flipped)));
}
