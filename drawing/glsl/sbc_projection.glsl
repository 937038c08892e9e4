/* SPDX-License-Identifier: GPL-3.0-or-later */
/* Sample-based camera projection in a vertex shader (SBC paper, Popescu, Sacks, Mei 2006,
 * section V-A: scene vertices are projected by the sample-based camera on the GPU).
 *
 * GLSL twin of engine/methods/sbc/sbc.py SampleBasedCamera.project for one reflection group, reading
 * the textures packed by drawing/methods/sbc_pack.py (layout documented there):
 *   1. descend the group's BSP tree to a leaf;
 *   2. camera leaf: Newton on the leaf's ray patch t(a, b) + s r(a, b) = p (ray_patch._newton),
 *      accepted on a small residual and a cell within the leaf's cells +- 0.5; a banded
 *      leaf hands answers in its band of s, and failures, to its ray list (bsp.to_fallback);
 *      ray-list leaf: the CANDIDATE_CELLS cells whose centre ray passes closest
 *      (sbc._closest_cells), Newton on each in order of distance, the first inside wins;
 *   3. the four rays around the cell must exist in the group and the point must lie
 *      between their interpolated tail and head (sbc._interpolate_rays, _project_group);
 *   4. the first-reflector depth is interpolated bilinearly.
 *
 * Float32 instead of float64: Newton runs on p - origin with tails stored relative to
 * the patch's origin (see sbc_pack.py); tolerances are float32-sized where the engine's
 * float64 ones would be below float32 resolution (SBC_STEP_TOLERANCE, and the floor
 * SBC_ROUNDING_TOLERANCE of the residual test; see drawing/methods/sbc_gpu.py).
 * The SBC_* constants are #defined by drawing/methods/sbc_gpu.py from the engine's own
 * constants. Samplers: sbc_groups, sbc_nodes, sbc_leaves, sbc_patches,
 * sbc_scalars, sbc_rays (RGBA32F, read with texelFetch only). */

#define SBC_FETCH(tex, index) texelFetch(tex, ivec2((index) % SBC_TEXTURE_WIDTH, (index) / SBC_TEXTURE_WIDTH), 0)

float sbc_scalar(int index)
{
  vec4 texel = SBC_FETCH(sbc_scalars, index / 4);
  int component = index % 4;
  return component == 0 ? texel.x : (component == 1 ? texel.y : (component == 2 ? texel.z : texel.w));
}

/* Quadratic patch value c0 + u (c1 + u c3 + v c4) + v (c2 + v c5), as ray_patch._newton. */
vec4 sbc_patch_value(vec4 c[6], float u, float v)
{
  return c[0] + u * (c[1] + u * c[3] + v * c[4]) + v * (c[2] + v * c[5]);
}

/* Newton's method for t(u, v) + s r(u, v) = q on the patch whose first texel is `base`
 * (ray_patch._newton): q is the point relative to the patch origin. Same start
 * (u = v = `start`, s from the start ray), same clamping of u and v to [-4, 4], same
 * iteration count; stops when a step moves (u, v) less than SBC_STEP_TOLERANCE. */
void sbc_newton(int base, vec3 q, float start, out vec2 uv, out float s, out float residual)
{
  vec4 t[6];
  vec4 d[6];
  for (int k = 0; k < 6; k++) {
    t[k] = SBC_FETCH(sbc_patches, base + 1 + k);
    d[k] = SBC_FETCH(sbc_patches, base + 7 + k);
  }
  float u = start;
  float v = start;
  vec3 ray_tail = sbc_patch_value(t, u, v).xyz;
  vec3 ray_direction = sbc_patch_value(d, u, v).xyz;
  s = dot(q - ray_tail, ray_direction) / max(length(ray_direction), 1e-30);
  for (int iteration = 0; iteration < SBC_NEWTON_ITERATIONS; iteration++) {
    ray_tail = sbc_patch_value(t, u, v).xyz;
    ray_direction = sbc_patch_value(d, u, v).xyz;
    vec3 tail_u = (t[1] + 2.0 * u * t[3] + v * t[4]).xyz;
    vec3 tail_v = (t[2] + u * t[4] + 2.0 * v * t[5]).xyz;
    vec3 direction_u = (d[1] + 2.0 * u * d[3] + v * d[4]).xyz;
    vec3 direction_v = (d[2] + u * d[4] + 2.0 * v * d[5]).xyz;
    vec3 a = tail_u + s * direction_u;
    vec3 b = tail_v + s * direction_v;
    vec3 f = ray_tail + s * ray_direction - q;
    vec3 bc = cross(b, ray_direction);
    vec3 ca = cross(ray_direction, a);
    vec3 ab = cross(a, b);
    float det = dot(a, bc);
    det = abs(det) > 1e-30 ? det : 1e-30;
    float step_u = dot(f, bc) / det;
    float step_v = dot(f, ca) / det;
    u = clamp(u - step_u, -4.0, 4.0);
    v = clamp(v - step_v, -4.0, 4.0);
    s = s - dot(f, ab) / det;
    if (abs(step_u) + abs(step_v) < SBC_STEP_TOLERANCE) {
      break;
    }
  }
  ray_tail = sbc_patch_value(t, u, v).xyz;
  ray_direction = sbc_patch_value(d, u, v).xyz;
  residual = length(ray_tail + s * ray_direction - q);
  uv = vec2(u, v);
}

/* Newton converged: the engine's residual test, 1e-6 (|p| + 1), floored at a few float32
 * roundings of the terms of t + s r - q (converged float32 solves stay near one). */
bool sbc_converged(float residual, vec3 p, vec3 q, float s)
{
  return residual < max(SBC_RESIDUAL_TOLERANCE * (length(p) + 1.0),
                        SBC_ROUNDING_TOLERANCE * (length(q) + abs(s)));
}

/* Ray-map cell at chart coordinates uv of a camera-leaf patch (RayPatches.cells_at). */
vec2 sbc_patch_cell(int base, vec2 uv)
{
  vec2 c[6];
  for (int k = 0; k < 6; k++) {
    c[k] = vec2(SBC_FETCH(sbc_patches, base + 1 + k).w, SBC_FETCH(sbc_patches, base + 7 + k).w);
  }
  return c[0] + uv.x * (c[1] + uv.x * c[3] + uv.y * c[4]) + uv.y * (c[2] + uv.y * c[5]);
}

/* Camera leaf (ray_patch.project_patches): converged, and within the member cells +- margin;
 * `s` is the distance along the patch's ray. */
bool sbc_project_camera(int patch_index, vec3 p, out vec2 cell, out float s, out bool converged)
{
  int base = patch_index * SBC_PATCH_TEXELS;
  vec3 origin = SBC_FETCH(sbc_patches, base).xyz;
  vec2 uv;
  float residual;
  vec3 q = p - origin;
  sbc_newton(base, q, 0.0, uv, s, residual);
  cell = sbc_patch_cell(base, uv);
  vec4 bounds = SBC_FETCH(sbc_patches, base + 13);
  converged = sbc_converged(residual, p, q, s);
  return converged &&
         all(greaterThanEqual(cell, bounds.xy - SBC_CELL_MARGIN)) &&
         all(lessThanEqual(cell, bounds.zw + SBC_CELL_MARGIN));
}

/* Are the four rays (corners 00, 10, 01, 11) folded over at depth s (sbc.rays_fold_at):
 * do the cell's corner triangles (edges' cross product along the mean direction)
 * disagree in orientation there? */
bool sbc_rays_fold_at(vec3 tail[4], vec3 direction[4], float s)
{
  vec3 mean = 0.25 * (direction[0] + direction[1] + direction[2] + direction[3]);
  ivec3 triangles[4] = ivec3[4](ivec3(0, 1, 2), ivec3(1, 3, 0), ivec3(3, 2, 1), ivec3(2, 0, 3));
  bool positive = false, negative = false;
  for (int k = 0; k < 4; k++) {
    ivec3 t = triangles[k];
    vec3 a = tail[t.x] + s * direction[t.x];
    float value = dot(cross(tail[t.y] + s * direction[t.y] - a, tail[t.z] + s * direction[t.z] - a), mean);
    positive = positive || value > 0.0;
    negative = negative || value < 0.0;
  }
  return positive && negative;
}

/* Ray-list leaf (sbc._project_ray_lists), and fold cells' sub-cells (sbc._refine_in_folds,
 * `fold` true): Newton on the `keep` cells whose centre ray passes closest to p
 * (sbc._closest_cells; ties keep the cell order), nearest first; the first cell holding
 * the point (bilinear coordinates in [0, 1] +- tolerance, converged, in front of the
 * tails; for a fold sub-cell also usable, texel 0 w >= 0, and its rays not folded
 * over at the point's depth) wins. `cell` is lo + the bilinear coordinates. */
bool sbc_project_ray_list(int first_patch, int first_cell, int stop_cell, vec3 p, int keep, bool fold,
                          out vec2 cell)
{
  float best_miss[SBC_MAX_CANDIDATES];
  int best_cell[SBC_MAX_CANDIDATES];
  for (int k = 0; k < SBC_MAX_CANDIDATES; k++) {
    best_miss[k] = 3.0e38;
    best_cell[k] = -1;
  }
  for (int c = first_cell; c < stop_cell; c++) {
    int base = (first_patch + c) * SBC_PATCH_TEXELS;
    vec4 origin_texel = SBC_FETCH(sbc_patches, base);
    if (origin_texel.w < 0.0) {
      continue;  /* a fold sub-cell whose rays leave the group */
    }
    vec3 q = p - origin_texel.xyz;
    vec3 centre_tail = SBC_FETCH(sbc_patches, base + 14).xyz;
    vec3 centre_direction = SBC_FETCH(sbc_patches, base + 15).xyz;
    float miss = length(cross(q - centre_tail, centre_direction));
    /* Insertion into the sorted short list; strict < keeps earlier cells first on ties. */
    for (int k = 0; k < keep; k++) {
      if (miss < best_miss[k] || best_cell[k] < 0) {
        for (int m = keep - 1; m > k; m--) {
          best_miss[m] = best_miss[m - 1];
          best_cell[m] = best_cell[m - 1];
        }
        best_miss[k] = miss;
        best_cell[k] = c;
        break;
      }
    }
  }
  for (int k = 0; k < keep; k++) {
    if (best_cell[k] < 0) {
      break;
    }
    int base = (first_patch + best_cell[k]) * SBC_PATCH_TEXELS;
    vec3 origin = SBC_FETCH(sbc_patches, base).xyz;
    vec2 uv;
    float s, residual;
    vec3 q = p - origin;
    sbc_newton(base, q, 0.5, uv, s, residual);
    if (all(greaterThanEqual(uv, vec2(-SBC_CELL_TOLERANCE))) &&
        all(lessThanEqual(uv, vec2(1.0 + SBC_CELL_TOLERANCE))) &&
        sbc_converged(residual, p, q, s) && s >= 0.0)
    {
      if (fold) {
        vec3 t0 = SBC_FETCH(sbc_patches, base + 1).xyz, t1 = SBC_FETCH(sbc_patches, base + 2).xyz;
        vec3 t2 = SBC_FETCH(sbc_patches, base + 3).xyz, t4 = SBC_FETCH(sbc_patches, base + 5).xyz;
        vec3 d0 = SBC_FETCH(sbc_patches, base + 7).xyz, d1 = SBC_FETCH(sbc_patches, base + 8).xyz;
        vec3 d2 = SBC_FETCH(sbc_patches, base + 9).xyz, d4 = SBC_FETCH(sbc_patches, base + 11).xyz;
        vec3 tails[4] = vec3[4](t0, t0 + t1, t0 + t2, t0 + t1 + t2 + t4);
        vec3 directions[4] = vec3[4](d0, d0 + d1, d0 + d2, d0 + d1 + d2 + d4);
        if (sbc_rays_fold_at(tails, directions, s)) {
          continue;
        }
      }
      cell = SBC_FETCH(sbc_patches, base + 13).xy + uv;
      return true;
    }
  }
  cell = vec2(0.0);
  return false;
}

/* An answer `cell` in a fold cell is solved again on the cell's traced sub-rays
 * (sbc._refine_in_folds), the fold-cell grid starting at scalar `block` + 2 rows x columns;
 * false where no sub-cell holds p. Answers in other cells stand as they are. */
bool sbc_refine_in_fold(int block, int columns, int rows, vec3 p, inout vec2 cell)
{
  vec2 base = floor(cell);
  if (base.x < 0.0 || base.y < 0.0 || base.x >= float(columns) || base.y >= float(rows)) {
    return true;
  }
  int fold = int(sbc_scalar(block + (2 * rows + int(base.y)) * columns + int(base.x)));
  if (fold < 0) {
    return true;
  }
  vec2 sub_cell;
  if (!sbc_project_ray_list(fold, 0, SBC_FOLD_SAMPLES * SBC_FOLD_SAMPLES, p, SBC_FOLD_CANDIDATES, true, sub_cell)) {
    return false;
  }
  cell = sub_cell / float(SBC_FOLD_SAMPLES);
  return true;
}

/* Project world point p in reflection group `group` (SampleBasedCamera.project).
 * Returns whether the point is seen reflected in this group; then `pixel` is its
 * desired-view pixel (x right, y up, origin bottom-left), `first_depth` the distance
 * along that pixel's view ray (from its near-plane origin, View.pixel_rays) to the
 * first reflector point, `ray_distance` the distance from the last reflector point
 * along the reflected ray, and `leaf_kind` 1 (camera leaf) or 2 (ray-list leaf).
 * Where not, leaf_kind is 0 and the other outputs are 0. */
bool sbc_project(vec3 p, int group, out vec2 pixel, out float first_depth, out float ray_distance,
                 out int leaf_kind)
{
  pixel = vec2(0.0);
  first_depth = 0.0;
  ray_distance = 0.0;
  leaf_kind = 0;
  /* Texel 2 of group 0 holds the number of groups (zero padding when there is none). */
  if (group < 0 || group >= int(SBC_FETCH(sbc_groups, 2).w)) {
    return false;
  }
  vec4 h0 = SBC_FETCH(sbc_groups, group * SBC_GROUP_TEXELS);
  vec4 h1 = SBC_FETCH(sbc_groups, group * SBC_GROUP_TEXELS + 1);
  vec4 h2 = SBC_FETCH(sbc_groups, group * SBC_GROUP_TEXELS + 2);
  vec4 owned = SBC_FETCH(sbc_groups, group * SBC_GROUP_TEXELS + 3);
  int node_offset = int(h0.x);

  /* 1. BSP descent (bsp.descend_tree): plane_normal . p >= plane_offset goes left. */
  int node = 0;
  int leaf = -1;
  int depth = int(h1.z);
  for (int level = 0; level <= depth + 1; level++) {
    vec4 links = SBC_FETCH(sbc_nodes, (node_offset + node) * SBC_NODE_TEXELS + 1);
    leaf = int(links.z);
    if (leaf >= 0) {
      break;
    }
    vec4 plane = SBC_FETCH(sbc_nodes, (node_offset + node) * SBC_NODE_TEXELS);
    node = dot(p, plane.xyz) >= plane.w ? int(links.x) : int(links.y);
  }
  if (leaf < 0) {
    return false;
  }
  vec4 leaf_texel = SBC_FETCH(sbc_leaves, int(h0.y) + leaf);
  int kind = int(leaf_texel.x);
  int row = int(leaf_texel.y);

  /* 2. The leaf's model gives the fractional ray-map cell; an answer in a fold cell is
   * solved again on the cell's traced sub-rays. */
  int columns = int(h2.x);
  int rows = int(h2.y);
  vec2 cell;
  bool accepted = false;
  int fallback = int(leaf_texel.w);
  if (kind == SBC_CAMERA_LEAF) {
    float s;
    bool converged;
    accepted = sbc_project_camera(int(h0.z) + row, p, cell, s, converged);
    /* A banded leaf's answers in its band, where Newton fails and where its fold cell
     * refuses them come from its ray list (bsp._depth_bands, bsp.to_fallback). */
    bool handed = false;
    if (fallback >= 0) {
      vec4 band = SBC_FETCH(sbc_patches, (int(h0.z) + row) * SBC_PATCH_TEXELS + 14);
      handed = !converged || (s > band.x && s < band.y);
    }
    if (!handed && accepted) {
      accepted = sbc_refine_in_fold(int(h1.y), columns, rows, p, cell);
      handed = fallback >= 0 && !accepted;
    }
    if (handed) {
      kind = SBC_RAY_LIST_LEAF;
      row = fallback;
    }
  }
  if (kind != SBC_CAMERA_LEAF) {
    int starts = int(h1.x);
    accepted = sbc_project_ray_list(int(h0.w), int(sbc_scalar(starts + row)), int(sbc_scalar(starts + row + 1)),
                                    p, fallback >= 0 ? SBC_BAND_CANDIDATES : SBC_CANDIDATE_CELLS, false, cell)
               && sbc_refine_in_fold(int(h1.y), columns, rows, p, cell);
  }
  if (!accepted) {
    return false;
  }

  /* Only the sheet owning the cell answers (sbc.SampleBasedCamera.owned). */
  if (any(lessThan(cell, owned.xy)) || any(greaterThanEqual(cell, owned.zw))) {
    return false;
  }

  /* 3. The four rays around the cell exist in the group (sbc._interpolate_rays). */
  vec2 base = floor(cell);
  vec2 frac = cell - base;
  int i0 = int(base.x);
  int j0 = int(base.y);
  if (i0 < 0 || j0 < 0 || i0 + 1 >= columns || j0 + 1 >= rows) {
    return false;
  }
  int grid = int(h1.y) + j0 * columns + i0;
  int corner[4];
  corner[0] = int(sbc_scalar(grid));
  corner[1] = int(sbc_scalar(grid + 1));
  corner[2] = int(sbc_scalar(grid + columns));
  corner[3] = int(sbc_scalar(grid + columns + 1));
  if (corner[0] < 0 || corner[1] < 0 || corner[2] < 0 || corner[3] < 0) {
    return false;
  }
  float weight[4];
  weight[0] = (1.0 - frac.x) * (1.0 - frac.y);
  weight[1] = frac.x * (1.0 - frac.y);
  weight[2] = (1.0 - frac.x) * frac.y;
  weight[3] = frac.x * frac.y;
  /* p - tail accumulated per corner: exact-ish where p is near the tails. */
  vec3 to_point = vec3(0.0);
  vec3 direction = vec3(0.0);
  float head = 0.0;
  bool blocked = false;
  float depth_first = 0.0;
  vec3 corner_tail[4];
  vec3 corner_direction[4];
  for (int k = 0; k < 4; k++) {
    vec4 tail_head = SBC_FETCH(sbc_rays, corner[k] * SBC_RAY_TEXELS);
    vec4 direction_first = SBC_FETCH(sbc_rays, corner[k] * SBC_RAY_TEXELS + 1);
    corner_tail[k] = tail_head.xyz;
    corner_direction[k] = direction_first.xyz;
    to_point += weight[k] * (p - tail_head.xyz);
    head += weight[k] * abs(tail_head.w);
    blocked = blocked || tail_head.w > 0.0;
    direction += weight[k] * direction_first.xyz;
    depth_first += weight[k] * direction_first.w;
  }
  /* A mixed cell (corner rays ending partly on a reflector, partly at the box): the
   * head of the nearest traced sub-ray decides (sbc.MixedCells). */
  int mixed = int(sbc_scalar(grid + columns * rows));
  if (mixed >= 0) {
    int a = min(int(frac.x * float(SBC_SUBCELL_SAMPLES)), SBC_SUBCELL_SAMPLES - 1);
    int b = min(int(frac.y * float(SBC_SUBCELL_SAMPLES)), SBC_SUBCELL_SAMPLES - 1);
    float sub_head = sbc_scalar(mixed + b * SBC_SUBCELL_SAMPLES + a);
    blocked = sub_head >= 0.0;
    head = blocked ? sub_head : head;
  }
  direction /= max(length(direction), 1e-30);
  float s = dot(to_point, direction);
  float tolerance = SBC_DISTANCE_TOLERANCE * (1.0 + head);
  /* Only a head on another reflector limits the segment (sbc._project_group). */
  if (!(s >= -tolerance && (!blocked || s <= head + tolerance))) {
    return false;
  }
  /* The point lies on the ray map's own ray within one cell spacing (sbc._cell_spacing). */
  float miss = length(to_point - s * direction);
  float along_u = length(corner_tail[1] - corner_tail[0] + s * (corner_direction[1] - corner_direction[0]));
  float along_v = length(corner_tail[2] - corner_tail[0] + s * (corner_direction[2] - corner_direction[0]));
  if (!(miss <= SBC_MISS_CELLS * max(along_u, along_v) + tolerance)) {
    return false;
  }
  /* 4. Cell (i, j) is the desired-view pixel centre d (i + 0.5, j + 0.5). */
  pixel = (cell + 0.5) * h2.z;
  first_depth = depth_first;
  ray_distance = s;
  leaf_kind = kind;
  return true;
}
