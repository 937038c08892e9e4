/* SPDX-License-Identifier: GPL-3.0-or-later */
/* Perturbation (Chen & Arvo 2000), compute stage: every vertex's first-order images
 * from one reflector's seed paths, the float32 twin of
 * engine/methods/perturbation/projector.py (its steps: taylor_step.py) for one history
 * of one bounce.
 *
 * One invocation per diffuse vertex (texel of `vertex_positions`):
 *   1. candidates: the local minima, over every coarse-th grid seed, of the distance
 *      from the vertex to the seeds' reflected rays (three rows of distances kept, so
 *      each is computed once); at most MAX_CANDIDATES, none farther than
 *      CANDIDATE_SPREAD times the best;
 *   2. hops: a first-order step predicts the pixel, the grid seed there (else the last
 *      on the way) is taken, until it stays;
 *   3. the second-order Taylor step (path Jacobian and Hessian of the Lagrange system,
 *      path_derivatives.py with N = 1: a 3 x 3 inverse and a Schur complement) and its
 *      error estimate: e2^2 / e1, twice the seed's model error times e1, infinite when
 *      the step is not local (REACH seed spacings in the image, MAX_RELATIVE_STEP of the
 *      path in the scene), lands on the surface's far side, or the target lies beyond
 *      the next reflector on the ray;
 *   4. on an exact surface (`analytic`), adaptive seeds as in the numpy twin: the eye ray
 *      through a damped target pixel meets the quadric, and the step is taken again
 *      from there (REFINE_ROUNDS);
 *   5. answers within the accuracy and the history's footprint, one per image rank
 *      (images closer than SAME_IMAGE_PX merged), into result0 ... result2:
 *      (reflector point relative to the shift, FOUND_CODE), else 0; an image grazing
 *      the mirror is left out (it is drawn by the renderer's traced rim).
 * Seeds (`seeds`, SEED_TEXELS texels each): (tail, head), (outgoing, 0),
 * (Q00, Q01, Q02, Q11), (Q12, Q22, model error, 0), (b, c) of g relative to the shift,
 * (pixel, 0, 0). `grid`: the seed index of each cell of the history's grid (-1 none).
 * `params`: rows of the view-projection, its inverse, the eye, (origin column, origin
 * row, columns, rows), (stride, accuracy, width, height), the analytic quadric and
 * (coarse, 0, 0, 0). */

#define INF 1e30

vec3 p_vertex;
vec3 eye;
mat4 vp;
mat4 inverse_vp;
ivec4 grid_info;
float stride;
float accuracy;
vec2 view_size;
mat3 exact_q;
vec3 exact_b;
float exact_c;

vec4 param(int k) { return texelFetch(params, ivec2(k, 0), 0); }

vec4 seed_texel(int s, int t)
{
  int k = s * SEED_TEXELS + t;
  return texelFetch(seeds, ivec2(k % seeds_width, k / seeds_width), 0);
}

int grid_seed(int column, int row)
{
  if (column < 0 || row < 0 || column >= grid_info.z || row >= grid_info.w) {
    return -1;
  }
  int k = row * grid_info.z + column;
  return int(texelFetch(grid, ivec2(k % grid_width, k / grid_width), 0).x);
}

/* A seed path: its last bounce, ray, quadric, model error and pixel. */
struct Seed {
  vec3 tail;
  float head;
  vec3 outgoing;
  mat3 q;
  vec3 b;
  float model_error;
  vec2 pixel;
};

Seed load_seed(int s)
{
  Seed seed;
  vec4 t0 = seed_texel(s, 0), t1 = seed_texel(s, 1), t2 = seed_texel(s, 2);
  vec4 t3 = seed_texel(s, 3), t4 = seed_texel(s, 4), t5 = seed_texel(s, 5);
  seed.tail = t0.xyz;
  seed.head = t0.w;
  seed.outgoing = t1.xyz;
  seed.q = mat3(t2.x, t2.y, t2.z, t2.y, t2.w, t3.x, t2.z, t3.x, t3.y);
  seed.b = t4.xyz;
  seed.model_error = t3.z;
  seed.pixel = t5.xy;
  return seed;
}

vec2 to_pixel(vec3 x)
{
  vec4 clip = vp * vec4(x, 1.0);
  return (clip.xy / clip.w * 0.5 + 0.5) * view_size;
}

float ray_distance(Seed seed, vec3 p)
{
  vec3 offset = p - seed.tail;
  float along = max(dot(offset, seed.outgoing), 0.0);
  return length(offset - along * seed.outgoing);
}

/* Solve [M g; g^T 0] [x; mu] = [r; s] by the Schur complement. */
vec4 solve_bordered(mat3 m_inverse, vec3 g, vec3 r, float s)
{
  vec3 x0 = m_inverse * r;
  vec3 xg = m_inverse * g;
  float mu = (dot(g, x0) - s) / dot(g, xg);
  return vec4(x0 - xg * mu, mu);
}

/* The Taylor step of the seed's path to `target`: the reflector point moved to first
 * (first) and second order (point), the error estimate and the pixel. */
struct Step {
  vec3 point;
  float estimate;
  vec2 pixel;
};

Step take_step(Seed seed, vec3 target, bool second)
{
  Step step;
  vec3 y = seed.tail;
  float along = dot(target - y, seed.outgoing);
  float reach = max(along, BEHIND_START * length(target - y));
  vec3 foot = y + reach * seed.outgoing;
  vec3 grad = seed.q * y + seed.b;
  float l0 = length(y - foot), l1 = length(eye - y);
  vec3 u0 = (y - foot) / l0, u1 = (eye - y) / l1;
  float lambda = dot(u1 - u0, grad) / dot(grad, grad);
  mat3 p0 = mat3(1.0) - outerProduct(u0, u0);
  mat3 p1 = mat3(1.0) - outerProduct(u1, u1);
  mat3 m_inverse = inverse(p0 / l0 + p1 / l1 + lambda * seed.q);
  vec3 dp = target - foot;
  vec4 first = solve_bordered(m_inverse, grad, p0 * dp / l0, 0.0);
  vec3 dy = first.xyz;
  vec3 d2 = vec3(0.0);
  if (second) {
    vec3 a0 = dy - dp, a1 = -dy;
    vec3 pa0 = p0 * a0, pa1 = p1 * a1;
    vec3 v0 = -(u0 * dot(a0, pa0) + 2.0 * pa0 * dot(u0, a0)) / (l0 * l0);
    vec3 v1 = -(u1 * dot(a1, pa1) + 2.0 * pa1 * dot(u1, a1)) / (l1 * l1);
    vec3 qdy = seed.q * dy;
    vec4 e = solve_bordered(m_inverse, grad, -(v0 - v1 + 2.0 * first.w * qdy), -dot(dy, qdy));
    d2 = 0.5 * e.xyz;
  }
  vec2 at0 = to_pixel(y), at1 = to_pixel(y + dy), at2 = to_pixel(y + dy + d2);
  float e1 = length(at1 - at0), e2 = length(at2 - at1);
  float estimate = e2 > 0.0 ? e2 * e2 / max(e1, e2) : 0.0;
  estimate = max(estimate, MODEL_SAFETY * seed.model_error * e1);
  bool local = length(at2 - seed.pixel) <= REACH * stride;
  bool short_step = length(target - foot) <= MAX_RELATIVE_STEP * max(along, 0.0);
  bool reachable = along < seed.head;
  step.point = y + dy + d2;
  /* A reflection arrives and leaves on one side of the surface: a step carried past the
   * silhouette lands on its far side. */
  vec3 normal = seed.q * step.point + seed.b;
  bool reflects = dot(normal, target - step.point) * dot(normal, eye - step.point) > 0.0;
  /* That holds on a convex mirror's far side too (eye and point both behind the tangent
   * plane): the normal there, oriented along the seed's (a step is local), must face the
   * eye as the seed's does (taylor_step._faces_eye). */
  bool faces_eye = dot(normal, grad) * dot(normal, eye - step.point) * dot(grad, eye - y) > 0.0;
  step.estimate = (local && short_step && reachable && reflects && faces_eye && !isnan(estimate)) ? estimate
                                                                                                    : INF;
  step.pixel = reachable ? at2 : vec2(-INF);
  return step;
}

ivec2 cell_of(vec2 pixel)
{
  return ivec2(floor(pixel / stride)) - grid_info.xy;
}

bool in_footprint(vec2 pixel)
{
  ivec2 cell = cell_of(pixel);
  for (int di = -1; di <= 1; di++) {
    for (int dj = -1; dj <= 1; dj++) {
      if (grid_seed(cell.x + dj, cell.y + di) >= 0) {
        return true;
      }
    }
  }
  return false;
}

/* An adaptive seed on the exact surface through `pixel` (false: the ray misses it, or
 * meets it from inside). */
bool exact_seed(vec2 pixel, out Seed seed)
{
  vec2 ndc = pixel / view_size * 2.0 - 1.0;
  vec4 far_point = inverse_vp * vec4(ndc, 1.0, 1.0);
  vec3 d = normalize(far_point.xyz / far_point.w - eye);
  /* g(eye + t d) = a t^2 + b t + c, the nearer root. */
  float a = 0.5 * dot(d, exact_q * d);
  float b = dot(d, exact_q * eye) + dot(exact_b, d);
  float c = 0.5 * dot(eye, exact_q * eye) + dot(exact_b, eye) + exact_c;
  float disc = b * b - 4.0 * a * c;
  if (disc < 0.0 || a <= 0.0) {
    return false;
  }
  float t = (-b - sqrt(disc)) / (2.0 * a);
  if (t <= 0.0) {
    return false;
  }
  vec3 x = eye + t * d;
  vec3 n = normalize(exact_q * x + exact_b);
  if (dot(n, d) > 0.0) {
    n = -n;
  }
  seed.tail = x;
  seed.head = INF;
  seed.outgoing = d - 2.0 * dot(d, n) * n;
  seed.q = exact_q;
  seed.b = exact_b;
  seed.model_error = 0.0;
  seed.pixel = pixel;
  return true;
}

void main()
{
  int index = int(gl_GlobalInvocationID.y) * positions_width + int(gl_GlobalInvocationID.x);
  if (index >= n_vertices) {
    return;
  }
  ivec2 texel = ivec2(gl_GlobalInvocationID.xy);
  for (int k = 0; k < 4; k++) {
    vp[k] = param(k);
    inverse_vp[k] = param(4 + k);
  }
  eye = param(8).xyz;
  grid_info = ivec4(param(9));
  vec4 settings = param(10);
  stride = settings.x;
  accuracy = settings.y;
  view_size = settings.zw;
  vec4 e0 = param(11), e1 = param(12), e2 = param(13);
  exact_q = mat3(e0.x, e0.y, e0.z, e0.y, e0.w, e1.x, e0.z, e1.x, e1.y);
  exact_b = e2.xyz;
  exact_c = e2.w;
  p_vertex = texelFetch(vertex_positions, texel, 0).xyz;

  /* 1. Candidates: local minima over the coarse sub-grid, three rows kept. */
  int coarse = int(param(14).x);
  int columns = min((grid_info.z - coarse / 2 + coarse - 1) / coarse, MAX_COLUMNS);
  int rows = (grid_info.w - coarse / 2 + coarse - 1) / coarse;
  float ring[3 * MAX_COLUMNS];
  int candidate[MAX_CANDIDATES];
  float candidate_distance[MAX_CANDIDATES];
  int found = 0;
  for (int r = 0; r <= rows; r++) {
    int slot = r % 3;
    for (int c = 0; c < columns; c++) {
      float d = INF;
      if (r < rows) {
        int s = grid_seed(coarse / 2 + coarse * c, coarse / 2 + coarse * r);
        if (s >= 0) {
          vec4 t0 = seed_texel(s, 0), t1 = seed_texel(s, 1);
          vec3 offset = p_vertex - t0.xyz;
          float along = max(dot(offset, t1.xyz), 0.0);
          d = length(offset - along * t1.xyz);
        }
      }
      ring[slot * MAX_COLUMNS + c] = d;
    }
    if (r == 0) {
      continue;
    }
    int middle = (r - 1) % 3;
    for (int c = 0; c < columns; c++) {
      float d = ring[middle * MAX_COLUMNS + c];
      if (d >= INF) {
        continue;
      }
      bool minimum = true;
      for (int dr = -1; dr <= 1 && minimum; dr++) {
        int row = r - 1 + dr;
        if (row < 0 || row >= rows) {
          continue;
        }
        for (int dc = -1; dc <= 1; dc++) {
          int column = c + dc;
          if ((dr == 0 && dc == 0) || column < 0 || column >= columns) {
            continue;
          }
          float n = ring[(row % 3) * MAX_COLUMNS + column];
          bool before = dr < 0 || (dr == 0 && dc < 0);
          if (before ? !(d < n) : !(d <= n)) {
            minimum = false;
            break;
          }
        }
      }
      if (!minimum) {
        continue;
      }
      /* Keep the MAX_CANDIDATES nearest, sorted. */
      int at = found < MAX_CANDIDATES ? found : MAX_CANDIDATES - 1;
      if (found >= MAX_CANDIDATES && d >= candidate_distance[at]) {
        continue;
      }
      while (at > 0 && candidate_distance[at - 1] > d) {
        candidate[at] = candidate[at - 1];
        candidate_distance[at] = candidate_distance[at - 1];
        at--;
      }
      candidate[at] = grid_seed(coarse / 2 + coarse * c, coarse / 2 + coarse * (r - 1));
      candidate_distance[at] = d;
      found = min(found + 1, MAX_CANDIDATES);
    }
  }

  /* 2-5. Hops, step, adaptive seeds; answers ranked. */
  vec3 answer[3];
  vec2 answer_pixel[3];
  int answers = 0;
  bool any_local = false;
  Step steps[MAX_CANDIDATES];
  Seed used[MAX_CANDIDATES];
  for (int k = 0; k < found; k++) {
    if (candidate_distance[k] > CANDIDATE_SPREAD * candidate_distance[0]) {
      found = k;
      break;
    }
    int s = candidate[k];
    for (int hop = 0; hop < HOPS; hop++) {
      Seed from = load_seed(s);
      Step guess = take_step(from, p_vertex, false);
      if (guess.pixel.x <= -INF) {
        break;
      }
      /* The seed at the predicted pixel, else the last one on the way there. */
      vec2 start = floor(from.pixel / stride) - vec2(grid_info.xy) + 0.5;
      vec2 aim = guess.pixel / stride - vec2(grid_info.xy);
      int moved = -1;
      for (int j = 0; j < HOP_SAMPLES && moved < 0; j++) {
        ivec2 cell = ivec2(floor(start + (1.0 - float(j) / float(HOP_SAMPLES)) * (aim - start)));
        moved = grid_seed(cell.x, cell.y);
      }
      if (moved < 0 || moved == s) {
        break;
      }
      s = moved;
    }
    used[k] = load_seed(s);
    steps[k] = take_step(used[k], p_vertex, true);
    any_local = any_local || steps[k].estimate < INF;
  }
  for (int k = 0; k < found; k++) {
    Step step = steps[k];
    Seed seed = used[k];
    if (step.estimate >= INF && any_local) {
      continue;  /* an edge minimum: the point has an image from a local step */
    }
    if (analytic != 0) {
      vec2 aim = step.pixel;
      int misses = 0;
      for (int round = 0; round < REFINE_ROUNDS && !(step.estimate <= accuracy) && aim.x > -INF; round++) {
        vec2 move = aim - seed.pixel;
        float size = length(move);
        vec2 target = seed.pixel + move * min(1.0, REACH * stride / max(size, 1e-12));
        Seed traced;
        if (!exact_seed(target, traced)) {
          misses++;
          aim = misses < MAX_MISSES ? 0.5 * (seed.pixel + target) : vec2(-INF);
          continue;
        }
        Step again = take_step(traced, p_vertex, true);
        seed = traced;
        aim = again.pixel;
        if (!(again.estimate >= step.estimate)) {
          step = again;
        }
      }
    }
    if (!(step.estimate <= accuracy) || !in_footprint(step.pixel) || answers >= 3) {
      continue;
    }
    /* A grazing image is not drawn (projector.grazing): the renderer traces the rim. */
    vec3 to_eye = normalize(eye - step.point);
    if (dot(normalize(to_eye + normalize(p_vertex - step.point)), to_eye) < GRAZING_COSINE) {
      continue;
    }
    vec4 clip = vp * vec4(step.point, 1.0);
    if (clip.w <= 0.0 || any(greaterThan(abs(clip.xyz), vec3(clip.w)))) {
      continue;
    }
    bool same = false;
    for (int a = 0; a < answers; a++) {
      same = same || length(answer_pixel[a] - step.pixel) < SAME_IMAGE_PX;
    }
    if (!same) {
      answer[answers] = step.point;
      answer_pixel[answers] = step.pixel;
      answers++;
    }
  }
  imageStore(result0, texel, answers > 0 ? vec4(answer[0], FOUND_CODE) : vec4(0.0));
  imageStore(result1, texel, answers > 1 ? vec4(answer[1], FOUND_CODE) : vec4(0.0));
  imageStore(result2, texel, answers > 2 ? vec4(answer[2], FOUND_CODE) : vec4(0.0));
}
