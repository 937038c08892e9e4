/* SPDX-License-Identifier: GPL-3.0-or-later */
/* Reflection morphing on the GPU, compute stage (drawing/methods/morph_pass.py): the float32
 * twin of MorphingGrid._matched_images and MorphingGrid._blend (engine/methods/morphing/morphing.py), one
 * invocation per diffuse vertex, every frame.
 *
 * The NODES nodes of the cell holding the eye (SBC paper, Popescu, Sacks, Mei 2006,
 * section VI: the 4 of a tetrahedron, then the other nodes of its cube outside the mirror,
 * which only join the fit of step 3 (MorphingGrid.locate_view); Martin & Popescu 2004,
 * section 6: the 8 of a cube, engine/methods/octree; the first BLEND_NODES are blended
 * with the eye's weights) have each projected the vertex once (their first reflector
 * points, `node0` .. `node<NODES - 1>`, kept while the diffuse geometry stays: SLOTS
 * regular images, then SLOTS images of the widened leaf charts, in the grid's rigid
 * frame). Per frame:
 *   1. the reference images are those of the heaviest node that has any; every node's
 *      image nearest to each reference image within `match_distance` plus MATCH_SLOPE
 *      times the two nodes' distance, and mutually nearest, is its match, from its
 *      widened charts where its regular images have none (remedy 2);
 *   2. the matches are blended with the eye's barycentric or trilinear weights, the
 *      weights of missing nodes left out where the others weigh PARTIAL_WEIGHT or more
 *      (the fit's other nodes weigh 0 and may be missing);
 *   3. our refinement: a quadric, written as a height field, fitted to the nodes'
 *      reflector points and the normals the law of reflection gives them
 *      (refine_on_local_surface), and
 *      Newton's method for the point of it whose normal bisects the directions to the
 *      eye and to the vertex; the Jacobian is analytic here (float32 has no room for the
 *      numpy twin's finite differences);
 *   4. the answer faces the eye and the vertex, and lies between the view's near and far
 *      planes.
 * Output: one texel per vertex and image slot, (reflector point relative to the
 * renderer's shift, FOUND_CODE or 0), read by iterative_mesh_vert.glsl. */

/* REGULAR_SLOTS and WIDENED_SLOTS: the most regular and widened-chart images any node of
 * the cell has of any vertex (morph_pass.blend_shader compiles one shader per pair, at
 * most SLOTS each): every loop over images runs to them, a constant. llvmpipe runs the
 * code of a branch or a loop iteration whether or not any invocation takes it, so loops
 * over slots that no node fills cost as much as filled ones (a convex mirror's nodes
 * fill one of three).
 * Push constants: n_vertices, positions_width and slot_rows (rows of one slot in a node
 * texture). The view's parameters, in the uniform block `frame` (struct MorphFrame,
 * drawing/methods/morph_pass.py): frame_from_shifted and shifted_from_frame (the grid's rigid
 * frame and the renderer's shift), view_projection (of shifted points), the eye in the
 * frame and match_distance, per node its position in the frame and weight (`nodes`), and
 * how many regular and widened-chart slots hold any image (`node_slots`; the others are
 * not read). */
vec4 node_image(int n, int slot, ivec2 texel)
{
  ivec2 at = ivec2(texel.x, texel.y + slot * slot_rows);
  if (n == 0) {
    return texelFetch(node0, at, 0);
  }
  if (n == 1) {
    return texelFetch(node1, at, 0);
  }
  if (n == 2) {
    return texelFetch(node2, at, 0);
  }
#if NODES > 4
  if (n == 3) {
    return texelFetch(node3, at, 0);
  }
#endif
#if NODES > 5
  if (n == 4) {
    return texelFetch(node4, at, 0);
  }
#endif
#if NODES > 6
  if (n == 5) {
    return texelFetch(node5, at, 0);
  }
#endif
#if NODES > 7
  if (n == 6) {
    return texelFetch(node6, at, 0);
  }
#endif
  /* The last node. */
#if NODES == 4
  return texelFetch(node3, at, 0);
#elif NODES == 5
  return texelFetch(node4, at, 0);
#elif NODES == 6
  return texelFetch(node5, at, 0);
#elif NODES == 7
  return texelFetch(node6, at, 0);
#else
  return texelFetch(node7, at, 0);
#endif
}

vec3 unit(vec3 v)
{
  return v / max(length(v), 1e-30);
}

/* The nearest present image of `images` (the first `count` of them, at most `bound`, a
 * constant) to `reference` within `threshold` that has no nearer one among `others`
 * (`count_others` of them: the reference node's regular images; mutually nearest, as
 * morphing._match); w 0 where none. */
vec4 nearest(vec4 images[SLOTS], const int bound, int count, vec3 reference, float threshold, vec4 others[SLOTS],
             int count_others)
{
  float best = 1e30;
  vec4 chosen = vec4(0.0);
  for (int j = 0; j < bound; j++) {
    float d = distance(images[j].xyz, reference);
    if (j < count && images[j].w > 0.5 && d < best) {
      best = d;
      chosen = images[j];
    }
  }
  for (int j = 0; j < REGULAR_SLOTS; j++) {
    if (j < count_others && others[j].w > 0.5 && distance(others[j].xyz, chosen.xyz) < best) {
      best = 1e30;
    }
  }
  return best <= threshold ? chosen : vec4(0.0);
}

/* A node's match of `reference`: among its regular images, else (remedy 2) among its
 * widened charts', fetched only then (most vertices match a regular image); a node that
 * only joins the fit (n >= BLEND_NODES) matches regular images alone (MorphingGrid._matched_images). */
vec4 match_node(int n, vec4 regular[SLOTS], ivec2 texel, vec3 reference, float threshold, vec4 others[SLOTS],
                int count_others)
{
  vec4 found = nearest(regular, REGULAR_SLOTS, int(frame.node_slots[n].x), reference, threshold, others, count_others);
#if WIDENED_SLOTS > 0
  int widened = int(frame.node_slots[n].y);
  if (found.w > 0.5 || widened == 0 || n >= BLEND_NODES) {
    return found;
  }
  vec4 extended[SLOTS];
  for (int s = 0; s < SLOTS; s++) {
    extended[s] = s < WIDENED_SLOTS && s < widened ? node_image(n, SLOTS + s, texel) : vec4(0.0);
  }
  return nearest(extended, WIDENED_SLOTS, widened, reference, threshold, others, count_others);
#else
  return found;
#endif
}

/* The fitted quadric's height at chart (u, v) (morph_surface.quadric_height), its slopes
 * (h_u, h_v) and second derivatives (h_uu, h_uv, h_vv), by implicit differentiation of
 * h = q(u, v) + c6 h^2 + c7 u h + c8 v h. */
float quadric_height(float c[9], vec2 uv, out vec2 slope, out vec3 second)
{
  float q = c[0] + c[1] * uv.x + c[2] * uv.y + 0.5 * c[3] * uv.x * uv.x + c[4] * uv.x * uv.y
            + 0.5 * c[5] * uv.y * uv.y;
  float linear = 1.0 - c[7] * uv.x - c[8] * uv.y;
  float h = 2.0 * q / (linear + sqrt(max(linear * linear - 4.0 * c[6] * q, 0.0)));
  float along_h = linear - 2.0 * c[6] * h;
  slope = vec2(c[1] + c[3] * uv.x + c[4] * uv.y + c[7] * h, c[2] + c[4] * uv.x + c[5] * uv.y + c[8] * h) / along_h;
  second = vec3(c[3] + 2.0 * c[7] * slope.x + 2.0 * c[6] * slope.x * slope.x,
                c[4] + c[7] * slope.y + c[8] * slope.x + 2.0 * c[6] * slope.x * slope.y,
                c[5] + 2.0 * c[8] * slope.y + 2.0 * c[6] * slope.y * slope.y) / along_h;
  return h;
}

/* (I - d d^T) v / length, the derivative of unit(target - x) along -v, for the two
 * directions of the bisector. */
vec3 bisector_derivative(vec3 to_eye, float eye_length, vec3 to_point, float point_length, vec3 v)
{
  return (v - to_eye * dot(to_eye, v)) / eye_length + (v - to_point * dot(to_point, v)) / point_length;
}

void main()
{
  int index = int(gl_GlobalInvocationID.y) * positions_width + int(gl_GlobalInvocationID.x);
  if (int(gl_GlobalInvocationID.x) >= positions_width || index >= n_vertices) {
    return;
  }
  ivec2 texel = ivec2(gl_GlobalInvocationID.xy);
  mat4 frame_from_shifted = frame.frame_from_shifted;
  vec3 eye = frame.eye_match.xyz;
  vec3 p = (frame_from_shifted * vec4(texelFetch(vertex_positions, texel, 0).xyz, 1.0)).xyz;

  vec4 images[NODES][SLOTS];
  int reference = -1;
  float heaviest = -1.0;
  for (int n = 0; n < NODES; n++) {
    bool has = false;
    int regular = int(frame.node_slots[n].x);
    for (int s = 0; s < SLOTS; s++) {
      images[n][s] = s < REGULAR_SLOTS && s < regular ? node_image(n, s, texel) : vec4(0.0);
      has = has || images[n][s].w > 0.5;
    }
    if (has && frame.nodes[n].w > heaviest) {
      heaviest = frame.nodes[n].w;
      reference = n;
    }
  }

  for (int k = 0; k < REGULAR_SLOTS; k++) {
    vec4 answer = vec4(0.0);
    vec4 own = reference >= 0 ? images[reference][k] : vec4(0.0);
    if (own.w > 0.5) {
      vec3 matched[NODES];
      float w[NODES];
      bool present[NODES];
      bool all_present = true;
      float total = 0.0;
      vec3 blended = vec3(0.0);
      for (int n = 0; n < NODES; n++) {
        float threshold = frame.eye_match.w
                          + MATCH_SLOPE * distance(frame.nodes[n].xyz, frame.nodes[reference].xyz);
        vec4 found = match_node(n, images[n], texel, own.xyz, threshold, images[reference],
                                int(frame.node_slots[reference].x));
        matched[n] = found.xyz;
        present[n] = found.w > 0.5;
        w[n] = present[n] ? frame.nodes[n].w : 0.0;
        all_present = all_present && (found.w > 0.5 || n >= BLEND_NODES);
        total += w[n];
        blended += w[n] * found.xyz;
      }
      bool usable = all_present || total >= PARTIAL_WEIGHT;
      blended /= max(total, 1e-30);

      /* refine_on_local_surface */
      vec3 origin = blended;
      vec3 normals[NODES];
      vec3 normal = vec3(0.0);
      for (int n = 0; n < NODES; n++) {
        normals[n] = unit(unit(frame.nodes[n].xyz - matched[n]) + unit(p - matched[n]));
        normal += w[n] * normals[n];
      }
      normal = unit(normal);
      int n_usable = 0;
      bool use[NODES];
      for (int n = 0; n < NODES; n++) {
        use[n] = present[n] && dot(normals[n], normal) > SURFACE_NORMAL_MIN;
        n_usable += use[n] ? 1 : 0;
      }
      bool ok = false;
      vec3 fitted_normal = normal;
      if (n_usable >= MIN_SURFACE_NODES) {
        vec3 helper = abs(normal.x) < 0.9 ? vec3(1.0, 0.0, 0.0) : vec3(0.0, 1.0, 0.0);
        vec3 t1 = unit(cross(normal, helper));
        vec3 t2 = cross(normal, t1);
        float spread = 0.0;
        for (int n = 0; n < NODES; n++) {
          vec3 o = matched[n] - origin;
          if (present[n]) {
            spread = max(spread, dot(o, t1) * dot(o, t1) + dot(o, t2) * dot(o, t2));
          }
        }
        spread = max(sqrt(spread), 1e-12);
        /* The normal equations in scalars (shader_sources.normal_equations_glsl): as
         * arrays with loops, llvmpipe keeps them in memory, which is much slower. */
        fit_clear();
        for (int n = 0; n < NODES; n++) {
          if (!use[n]) {
            continue;
          }
          vec3 o = (matched[n] - origin) / spread;
          float a = dot(o, t1), b = dot(o, t2), nz = dot(normals[n], normal);
          float h = dot(o, normal), slope_a = -dot(normals[n], t1) / nz, slope_b = -dot(normals[n], t2) / nz;
          fit_add(1.0, a, b, 0.5 * a * a, a * b, 0.5 * b * b, h * h, a * h, b * h, h);
          fit_add(0.0, 1.0, 0.0, a, b, 0.0, 2.0 * slope_a * h, h + slope_a * a, slope_a * b, slope_a);
          fit_add(0.0, 0.0, 1.0, 0.0, a, b, 2.0 * slope_b * h, slope_b * a, h + slope_b * b, slope_b);
        }
        fit_solve();
        float c[9] = float[9](fit_b0, fit_b1, fit_b2, fit_b3, fit_b4, fit_b5, fit_b6, fit_b7, fit_b8);

        /* Newton's steps; the residual where they end decides (below, once: llvmpipe would
         * run a test inside the loop on every step). */
        vec2 uv = vec2(0.0);
        bool singular = false;
        for (int iteration = 0; iteration < SURFACE_ITERATIONS; iteration++) {
          vec2 slope;
          vec3 second;
          vec3 x = origin + spread * (uv.x * t1 + uv.y * t2 + quadric_height(c, uv, slope, second) * normal);
          vec3 ta = t1 + slope.x * normal;
          vec3 tb = t2 + slope.y * normal;
          vec3 to_eye = eye - x, to_point = p - x;
          float le = max(length(to_eye), 1e-30), lp = max(length(to_point), 1e-30);
          to_eye /= le;
          to_point /= lp;
          vec3 bisector = to_eye + to_point;
          vec2 residual = vec2(dot(bisector, ta), dot(bisector, tb));
          vec3 d_bu = -spread * bisector_derivative(to_eye, le, to_point, lp, ta);
          vec3 d_bv = -spread * bisector_derivative(to_eye, le, to_point, lp, tb);
          float bn = dot(bisector, normal);
          mat2 jacobian = mat2(dot(d_bu, ta) + bn * second.x, dot(d_bu, tb) + bn * second.y,
                               dot(d_bv, ta) + bn * second.y, dot(d_bv, tb) + bn * second.z);
          if (abs(determinant(jacobian)) < 1e-30) {
            singular = true;
            break;
          }
          vec2 step = inverse(jacobian) * residual;
          uv = clamp(uv - step, vec2(-4.0), vec2(4.0));
          if (max(abs(step.x), abs(step.y)) < SURFACE_SETTLED) {
            break;
          }
        }
        vec2 slope;
        vec3 second;
        vec3 x = origin + spread * (uv.x * t1 + uv.y * t2 + quadric_height(c, uv, slope, second) * normal);
        vec3 ta = t1 + slope.x * normal;
        vec3 tb = t2 + slope.y * normal;
        vec3 bisector = unit(eye - x) + unit(p - x);
        vec2 residual = vec2(dot(bisector, ta), dot(bisector, tb));
        ok = !singular && max(abs(residual.x), abs(residual.y)) < SURFACE_RESIDUAL
             && dot(uv, uv) <= SURFACE_REACH * SURFACE_REACH && !any(isnan(x)) && !any(isinf(x));
        fitted_normal = singular ? normal : unit(cross(ta, tb));
        if (ok) {
          blended = x;
        }
        fitted_normal *= dot(fitted_normal, normal) < 0.0 ? -1.0 : 1.0;
      }
      usable = usable && (all_present || ok);
      vec3 facing = ok ? fitted_normal : normal;
      usable = usable && dot(facing, eye - blended) > 0.0 && dot(facing, p - blended) > 0.0;
      vec3 world = (frame.shifted_from_frame * vec4(blended, 1.0)).xyz;
      vec4 clip = frame.view_projection * vec4(world, 1.0);
      usable = usable && clip.w > 0.0 && abs(clip.z) <= clip.w && !any(isnan(world));
      answer = usable ? vec4(world, float(FOUND_CODE)) : vec4(0.0);
    }
    if (k == 0) {
      imageStore(result0, texel, answer);
    }
    else if (k == 1) {
      imageStore(result1, texel, answer);
    }
    else {
      imageStore(result2, texel, answer);
    }
  }
}
