/* SPDX-License-Identifier: GPL-3.0-or-later */
/* Where each diffuse vertex appears through a convex glass solid, compute stage
 * (drawing/methods/refraction_draw.py), every frame.
 *
 * The iterative search of Roger & Holzschuch (2006, section 3.3) carried over to a
 * refracted path, as Chen & Arvo (2000, section VI) carry path perturbation over: the
 * unknown is the entry point A on the glass's cube map (cube_map.glsl), two chart
 * coordinates around a first guess. From A the eye's ray is refracted in (Snell's law
 * with the map's interpolated normal), followed to where it leaves the surface (B,
 * `exit_point`), and refracted out (glass_path.glsl); the residual is the angle between that ray and the
 * direction from B to the vertex, driven to zero by damped Newton with a finite-difference
 * Jacobian, as iterative_search.glsl does for the half vector:
 *   1. first guesses: entry directions in the plane of the eye, the centre and the vertex
 *      (where a sphere's whole path lies), sampled across the part of the map the eye may
 *      see and bisected where the path's signed miss changes sign (`plane_guesses`);
 *      warm, last frame's answer first;
 *   2. damped Newton on the true map (trust radius, line search);
 *   3. stop when a step moves A by less than `stop_per_w` times the view's clip w at A;
 *   4. checks: the residual vanishes, A faces the eye, neither interface reflects
 *      totally, no other glass lies on the way in or out.
 * A closed convex solid is entered and left once: nothing of it lies between the eye and
 * A, or between B and the vertex, once A faces the eye and the ray leaves toward the
 * vertex. Everything runs relative to the map's centre O.
 * Output texels, IMAGES answer slots one below another: `result` (A relative to the
 * renderer's shift, `answer_code`, with FLIPPED_CODE where the image is mirrored:
 * `flipped_image`); `exit_result` (B relative to the shift, 0). A vertex without an image
 * whose nearest search stopped within PLACED_RESIDUAL of a path to it (beside the edge of
 * what the glass shows, where a triangle has corners on both sides) keeps that search's
 * end in its first slot, marked PLACED_CODE: its triangles are drawn for the fragment
 * stage's ray cast (reflection_mesh_frag.glsl) to keep what the rays through them hit. */

/* The chart around the guess and the residual's fixed axes. */
vec3 chart_axis;
vec3 chart_t1;
vec3 chart_t2;
vec3 residual_e1;
vec3 residual_e2;

/* The refracted path entering at chart point x: entry a, exit b, the ray o leaving b;
 * f, the leaving ray's offset from the direction toward the vertex on the residual's
 * axes. Returns FOUND when the path exists, or why not. */
int evaluate(vec2 x, out vec2 f, out vec3 a, out vec3 b, out vec3 o)
{
  vec3 d = normalize(chart_axis + x.x * chart_t1 + x.y * chart_t2);
  float radius;
  vec3 n;
  f = vec2(0.0);
  b = vec3(0.0);
  o = vec3(0.0);
  if (!map_surface(d, radius, n)) {
    a = vec3(0.0);
    return NO_SURFACE;
  }
  a = radius * d;
  vec3 last, normal;
  int status = refracted_path(a, n, b, o, last, normal);
  if (status == FOUND) {
    vec3 offset = o - normalize(vertex - b);
    f = vec2(dot(offset, residual_e1), dot(offset, residual_e2));
  }
  return status;
}

/* The signed miss of the path entering along direction `d` from O (the eye's ray
 * refracted there, followed to its exit on the map, refracted out): the side of the
 * leaving ray on which the vertex lies, across `side`; `ahead`: the path exists and
 * leaves toward the vertex. */
float path_miss(vec3 d, vec3 side, out bool ahead)
{
  vec2 f;
  vec3 a, b, o;
  chart_axis = d;
  chart_t1 = perpendicular(d);
  chart_t2 = cross(d, chart_t1);
  ahead = evaluate(vec2(0.0), f, a, b, o) == FOUND && dot(o, vertex - b) > 0.0;
  return dot(cross(o, vertex - b), side);
}

/* Up to MAX_STARTS first guesses (unit directions from O, in `guesses`): entry
 * directions in the plane of the eye, O and the vertex (where a sphere's whole path
 * lies), sampled across the part of the map the eye may see, where the path's signed
 * miss across that plane changes sign with the vertex ahead, bisected; or, with none,
 * the sample that misses least. */
vec3 guesses[MAX_STARTS + PIXEL_STARTS];

int plane_guesses()
{
  vec3 toward_eye = camera.w > 0.5 ? camera.xyz - centre : camera.xyz;
  float eye_distance = length(toward_eye);
  toward_eye /= max(eye_distance, 1e-30);
  vec3 across = vertex - dot(vertex, toward_eye) * toward_eye;
  across = length(across) > 1e-9 * length(vertex) ? normalize(across) : perpendicular(toward_eye);
  vec3 side = cross(toward_eye, across);
  /* Up to where the eye's rays graze the sphere of the smallest radius. */
  float cap = camera.w > 0.5 ? acos(clamp(min_radius / max(eye_distance, 1e-30), 0.0, 1.0)) : 1.5707963;
  int count = 0;
  float best = 1e30;
  float best_phi = 0.0;
  bool previous_ahead = false;
  float previous_miss = 0.0;
  float previous_phi = -cap;
  for (int k = 0; k <= GUESS_SAMPLES && count < MAX_STARTS; k++) {
    float phi = -cap + 2.0 * cap * float(k) / float(GUESS_SAMPLES);
    bool ahead;
    float miss = path_miss(cos(phi) * toward_eye + sin(phi) * across, side, ahead);
    if (ahead && abs(miss) < best) {
      best = abs(miss);
      best_phi = phi;
    }
    if (k > 0 && ahead && previous_ahead && (miss < 0.0) != (previous_miss < 0.0)) {
      float lo = previous_phi;
      float hi = phi;
      bool lo_negative = previous_miss < 0.0;
      for (int j = 0; j < GUESS_BISECTIONS; j++) {
        float mid = 0.5 * (lo + hi);
        bool mid_ahead;
        if ((path_miss(cos(mid) * toward_eye + sin(mid) * across, side, mid_ahead) < 0.0) == lo_negative) {
          lo = mid;
        }
        else {
          hi = mid;
        }
      }
      float root = 0.5 * (lo + hi);
      guesses[count] = cos(root) * toward_eye + sin(root) * across;
      count++;
    }
    previous_ahead = ahead;
    previous_miss = miss;
    previous_phi = phi;
  }
  if (count == 0 && best < 1e30) {
    guesses[0] = cos(best_phi) * toward_eye + sin(best_phi) * across;
    count = 1;
  }
  return count;
}

/* Up to PIXEL_STARTS more first guesses after the first `count`, from the pixels' own
 * paths through the glass (glass_rays.glsl), when the frame has them (`pixel_rect`, the
 * glass's box on screen in pixels, x0 y0 x1 y1, empty without): the entries of the pixels,
 * on a grid PIXEL_GRID across the box, whose leaving rays pass the vertex at the smallest
 * angles, PIXEL_APART grid cells apart at least (distinct images). They find what the
 * plane's guesses cannot: images off that plane (a lens seen at an angle), and paths
 * reflected inside (a box's side). */
int pixel_guesses(int count)
{
  if (pixel_rect.z <= pixel_rect.x || pixel_rect.w <= pixel_rect.y) {
    return count;
  }
  float best[PIXEL_STARTS];
  ivec2 best_cell[PIXEL_STARTS];
  vec3 best_entry[PIXEL_STARTS];
  for (int k = 0; k < PIXEL_STARTS; k++) {
    best[k] = PLACED_RESIDUAL;
    best_cell[k] = ivec2(-1000);
  }
  vec3 target = vertex + centre;
  for (int j = 0; j < PIXEL_GRID; j++) {
    for (int i = 0; i < PIXEL_GRID; i++) {
      ivec2 pixel = pixel_rect.xy + (ivec2(i, j) * (pixel_rect.zw - 1 - pixel_rect.xy)) / (PIXEL_GRID - 1);
      vec4 entry = texelFetch(pixel_entries, pixel, 0);
      vec4 exit_ray = texelFetch(pixel_exits, pixel, 0);
      if (abs(entry.w - glass_id) > 0.5 || int(exit_ray.w) != FOUND) {
        continue;
      }
      vec3 toward = target - exit_ray.xyz;
      vec3 leaving = texelFetch(pixel_leaving, pixel, 0).xyz;
      float along = dot(toward, leaving);
      float miss = along > 0.0 ? length(toward - along * leaving) / along : 1e30;
      /* Kept in order of miss, no two within PIXEL_APART cells: a nearer one replaces
       * what it is near. */
      ivec2 cell = ivec2(i, j);
      for (int k = 0; k < PIXEL_STARTS; k++) {
        ivec2 apart = abs(cell - best_cell[k]);
        bool near = max(apart.x, apart.y) < PIXEL_APART;
        if (miss < best[k]) {
          if (!near) {
            for (int m = PIXEL_STARTS - 1; m > k; m--) {
              best[m] = best[m - 1];
              best_cell[m] = best_cell[m - 1];
              best_entry[m] = best_entry[m - 1];
            }
          }
          best[k] = miss;
          best_cell[k] = cell;
          best_entry[k] = entry.xyz;
          break;
        }
        if (near) {
          break;
        }
      }
    }
  }
  for (int k = 0; k < PIXEL_STARTS; k++) {
    if (best[k] < PLACED_RESIDUAL) {
      guesses[count] = best_entry[k];
      count++;
    }
  }
  return count;
}

/* Whether the last converged answer of newton() is a flipped image: the bundle of the
 * eye's rays around the path, oriented as it enters at A (det [A_u, A_v, i] for the
 * incoming direction i), arrives at the vertex turned over (det [Q_u, Q_v, o] for
 * Q = B + s o, as iterative_search.glsl's flipped_image), its sine (the determinant
 * over the lengths of its two columns) below -FLIP_SINE. Refraction keeps the bundle on
 * one side of each interface, so only a caustic changes the sign: half a turn past a
 * lens's focus keeps it (an image turned round, not mirrored), the space between two
 * focal lines (astigmatism, a fold) changes it. Near a focus both columns are short and
 * their finite differences noisy: the margin keeps that noise from marking a vertex. */
bool flipped;
/* The residual (radians) where the last newton() that took a step stopped. */
float newton_residual;

bool flipped_image(vec3 a, vec3 au, vec3 av, vec3 b, vec3 o, vec3 bu, vec3 ou, vec3 bv, vec3 ov)
{
  float s = length(vertex - b);
  float at_entry = dot(cross(au - a, av - a), eye_ray(a));
  vec3 qu = bu - b + s * (ou - o);
  vec3 qv = bv - b + s * (ov - o);
  float sine = dot(cross(qu, qv), o) / max(length(qu) * length(qv), 1e-30);
  return (at_entry < 0.0 ? -sine : sine) < -FLIP_SINE;
}

/* Damped Newton from chart point x; the verdict on the converged path (a in `a`, b in
 * `b`): FOUND, or NOT_CONVERGED, or why the path does not exist. */
int newton(vec2 x, inout int steps, out vec3 a, out vec3 b)
{
  vec2 f;
  vec3 o;
  int status = evaluate(x, f, a, b, o);
  if (status != FOUND) {
    return status;
  }
  for (int step = 0; step < MAX_ITERATIONS; step++) {
    vec2 fu, fv, ft;
    vec3 au, av, bu, bv, ou, ov, at, bt, ot;
    int su = evaluate(x + vec2(DERIVATIVE_STEP, 0.0), fu, au, bu, ou);
    int sv = evaluate(x + vec2(0.0, DERIVATIVE_STEP), fv, av, bv, ov);
    if (su != FOUND || sv != FOUND) {
      /* The path ends within a derivative step (the rim, total reflection): step back. */
      su = evaluate(x - vec2(DERIVATIVE_STEP, 0.0), fu, au, bu, ou);
      sv = evaluate(x - vec2(0.0, DERIVATIVE_STEP), fv, av, bv, ov);
      if (su != FOUND || sv != FOUND) {
        return su != FOUND ? su : sv;
      }
      fu = 2.0 * f - fu;
      fv = 2.0 * f - fv;
      au = 2.0 * a - au;
      av = 2.0 * a - av;
      bu = 2.0 * b - bu;
      bv = 2.0 * b - bv;
      ou = 2.0 * o - ou;
      ov = 2.0 * o - ov;
    }
    vec2 ju, jv;
    vec2 delta = trusted_step(f, fu, fv, ju, jv);
    /* Line search: scales 1, 1/2, ... until |F| falls; the last one is taken regardless. */
    float current = length(f);
    float scale = 1.0;
    vec3 previous = a;
    vec3 previous_b = b;
    vec3 previous_o = o;
    int st = FOUND;
    for (int k = 0; k <= HALVINGS; k++) {
      st = evaluate(x + scale * delta, ft, at, bt, ot);
      if (st == FOUND && length(ft) < current || k == HALVINGS) {
        break;
      }
      scale *= 0.5;
    }
    x += scale * delta;
    steps += 1;
    if (st != FOUND) {
      return st;
    }
    if (length(x) > MAX_CHART) {
      return NO_SURFACE;
    }
    f = ft;
    a = at;
    b = bt;
    newton_residual = length(f);
    if (length(a - previous) < pixel_tolerance(a)) {
      flipped = flipped_image(previous, au, av, previous_b, previous_o, bu, ou, bv, ov);  /* where sampled */
      o = ot;
      return newton_residual < RESIDUAL_TOLERANCE ? FOUND : NOT_CONVERGED;
    }
    o = ot;
  }
  return NOT_CONVERGED;
}

/* Whether `entry` is one of the first `count` images kept (within SAME_IMAGE_PER_STOP of
 * the stop tolerance: half the Accuracy). */
vec3 kept_entry[IMAGES];
vec3 kept_exit[IMAGES];
bool kept_flipped[IMAGES];

bool already_kept(vec3 entry, int count)
{
  for (int k = 0; k < count; k++) {
    if (length(entry - kept_entry[k]) < SAME_IMAGE_PER_STOP * pixel_tolerance(entry)) {
      return true;
    }
  }
  return false;
}

void main()
{
  ivec2 texel;
  vec4 last;
  bool resume;
  if (!start_search(texel, last, resume)) {
    return;
  }
  int status = NO_SURFACE;
  int steps = 0;
  int count = 0;
  /* Where a vertex without an image is placed: the end of the search that came nearest. */
  float placed_residual = PLACED_RESIDUAL;
  vec3 placed_entry = vec3(0.0);
  vec3 placed_exit = vec3(0.0);
  bool eye_inside = camera.w > 0.5 && inside_surface(camera.xyz - centre);
  vec3 toward_eye = camera.w > 0.5 ? normalize(camera.xyz - centre) : camera.xyz;
  if (eye_inside || length(vertex) <= 1e-9 * max(max_radius, 1e-30) || inside_surface(vertex)) {
    status = INSIDE;
  }
  else if (dot(vertex, toward_eye) > max_radius) {
    /* Before the plane that bounds the glass toward the eye: a path turned back that far
     * enters along the rim at grazing incidence, where the glass reflects nearly all the
     * light (and Render Image traces its band); not searched. */
    status = NO_SURFACE;
  }
  else {
    residual_e1 = perpendicular(normalize(vertex));
    residual_e2 = cross(normalize(vertex), residual_e1);
    /* Every image: Newton from each of the plane's guesses, then the pixels', each
     * distinct root kept in that order; warm, from last frame's images instead, where
     * there were any (the guesses find the images a moving view gains when it stops,
     * cold). One loop calls newton() once, as in iterative_search.glsl: llvmpipe
     * compiles one copy of it, not one per start. */
    int starts = 0;
    int rows = imageSize(result).y / IMAGES;
    for (int slot = 0; resume && slot < IMAGES && starts < MAX_STARTS; slot++) {
      vec4 image = imageLoad(result, texel + ivec2(0, slot * rows));
      if (int(image.w) % 16 == FOUND + 8) {
        guesses[starts] = normalize(image.xyz - centre);
        starts++;
      }
    }
    if (starts == 0) {
      starts = pixel_guesses(plane_guesses());
    }
    for (int attempt = 0; attempt < starts && count < IMAGES; attempt++) {
      chart_axis = guesses[attempt];
      chart_t1 = perpendicular(chart_axis);
      chart_t2 = cross(chart_axis, chart_t1);
      vec3 entry, leave;
      flipped = false;
      newton_residual = 1e30;
      int verdict = newton(vec2(0.0), steps, entry, leave);
      if (verdict == NOT_CONVERGED && newton_residual < placed_residual) {
        placed_residual = newton_residual;
        placed_entry = entry;
        placed_exit = leave;
      }
      /* Other glass on the way in or out: there the vertex is seen through more than
       * this glass, which this path does not follow. (Orthographic: the eye's ray starts
       * a thousand of the glass's radii back.) */
      vec3 eye = camera.w > 0.5 ? camera.xyz : entry + centre + 1e3 * max_radius * camera.xyz;
      vec3 entry_at = entry + centre;
      vec3 leave_at = leave + centre;
      vec3 vertex_at = vertex + centre;
      if (verdict == FOUND && (other_map_blocks(leave_at, vertex_at) || other_map_blocks(eye, entry_at))) {
        verdict = OCCLUDED;
      }
      use_map(self_map);
      if (verdict == FOUND && !already_kept(entry, count)) {
        kept_entry[count] = entry;
        kept_exit[count] = leave;
        kept_flipped[count] = flipped;
        count++;
      }
      else if (count == 0 && attempt == 0) {
        status = verdict;
      }
    }
  }
  bool placed = count == 0 && placed_residual < PLACED_RESIDUAL;
  int slots = imageSize(result).y / IMAGES;
  for (int slot = 0; slot < IMAGES; slot++) {
    ivec2 at = texel + ivec2(0, slot * slots);
    bool kept = slot < count;
    int code_status = kept ? FOUND : (slot == 0 ? status : NO_SURFACE);
    vec3 entry = kept ? kept_entry[slot] : (placed ? placed_entry : vec3(0.0));
    vec3 leave = kept ? kept_exit[slot] : (placed ? placed_exit : vec3(0.0));
    float code = answer_code(code_status, steps, kept && kept_flipped[slot]);
    imageStore(result, at, vec4(entry + centre, code + (placed && slot == 0 ? float(PLACED_CODE) : 0.0)));
    imageStore(exit_result, at, vec4(leave + centre, 0.0));
  }
}
