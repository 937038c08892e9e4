/* SPDX-License-Identifier: GPL-3.0-or-later */
/* The nearest triangle along a ray, through a bounding volume hierarchy on the GPU
 * (drawing/methods/scene_tables.py packs it from engine/geometry/bvh.py's tree).
 *
 * The tree is complete: node h's children are 2h and 2h + 1, the root is 1 and the leaves
 * are `leaf_first` + i, each holding LEAF_SIZE triangle slots. `bvh_boxes` holds two texels
 * per node: its lowest corner, with in w the order its parent visits its children in
 * (`split`, below; EMPTY further from 0 where the node holds no triangle), and its highest corner,
 * with in w the order it visits its own (`split`: +(axis + 1) where its left child's box
 * lies lower along that axis, -(axis + 1) where the right one's does). `bvh_slots` holds
 * SLOT_TEXELS per slot: its triangle's first corner and its two edges from it, each
 * with in w a corner's vertex index (-1 for an empty slot); `vertex_uvs` z the index of
 * a vertex's mesh's image (-1 for none, MIRROR_CODE for a mirror's, GLASS_CODE for glass),
 * `scene_vertices` the vertices (relative to the renderer's shift, as the ray). A complete
 * tree is walked without a stack: past a node, climb while it is the second child its
 * parent visits, then go to its sibling. Each node carries its parent's order, so the
 * walk reads two texels a node it visits, and one more a level it climbs past the first. */

/* Texel `index` of a table of TABLE_ROW texels a row (a power of two: no division). */
vec4 table_texel(sampler2D table, int index)
{
  return texelFetch(table, ivec2(index & (TABLE_ROW - 1), index >> TABLE_ROW_BITS), 0);
}

/* Whether the ray meets the box within [near, far] (slabs; `inverse` holds 1 / direction). */
bool meets_box(vec3 origin, vec3 inverse, vec3 low, vec3 high, float near, float far)
{
  vec3 t0 = (low - origin) * inverse;
  vec3 t1 = (high - origin) * inverse;
  vec3 near3 = min(t0, t1);
  vec3 far3 = max(t0, t1);
  return max(max(near3.x, near3.y), max(near3.z, near)) <= min(min(far3.x, far3.y), min(far3.z, far));
}

/* Whether a ray along `direction` visits the left child first of a node whose children are
 * ordered by `split` (their lower one along axis |split| - 1 first; EMPTY aside). */
bool left_first(float split, vec3 direction)
{
  int code = int(abs(split));
  int axis = clamp(((code - 1) & 3), 0, 2);
  return (split > 0.0) == (direction[axis] >= 0.0);
}

/* The vertex indices of slot `slot`'s triangle's corners. */
ivec3 slot_corners(int slot)
{
  return ivec3(table_texel(bvh_slots, SLOT_TEXELS * slot).w, table_texel(bvh_slots, SLOT_TEXELS * slot + 1).w,
               table_texel(bvh_slots, SLOT_TEXELS * slot + 2).w);
}

/* The nearest hit of the ray past `t_min` and before `t_hit` (in: how far to look, e.g.
 * 3e38), slot `skip` aside (the triangle a reflected ray leaves; -1: none): its slot (-1
 * for none), distance (out, in `t_hit`) and barycentric (u, v) of its second and third
 * corners (Moller & Trumbore 1997). Children are visited nearer first, so that a near hit
 * prunes the boxes behind it. */
int nearest_hit(vec3 origin, vec3 direction, float t_min, int skip, inout float t_hit, out vec2 hit_uv)
{
  vec3 safe = mix(direction, vec3(1e-30), lessThan(abs(direction), vec3(1e-30)));
  vec3 inverse = 1.0 / safe;
  hit_uv = vec2(0.0);
  int hit = -1;
  int node = 1;
  for (int visits = 0; visits < 4 * leaf_first; visits++) {
    vec4 low = table_texel(bvh_boxes, 2 * node);
    vec4 high = table_texel(bvh_boxes, 2 * node + 1);
    if (abs(low.w) < float(EMPTY) && meets_box(origin, inverse, low.xyz, high.xyz, t_min, t_hit)) {
      if (node < leaf_first) {
        node = 2 * node + (left_first(high.w, direction) ? 0 : 1);
        continue;
      }
      for (int k = 0; k < LEAF_SIZE; k++) {
        int slot = (node - leaf_first) * LEAF_SIZE + k;
        vec4 corner = table_texel(bvh_slots, SLOT_TEXELS * slot);
        if (corner.w < 0.0 || slot == skip) {
          continue;
        }
        vec3 a = corner.xyz;
        vec3 e1 = table_texel(bvh_slots, SLOT_TEXELS * slot + 1).xyz;
        vec3 e2 = table_texel(bvh_slots, SLOT_TEXELS * slot + 2).xyz;
        vec3 p = cross(direction, e2);
        float det = dot(e1, p);
        if (abs(det) < 1e-30) {
          continue;
        }
        vec3 s = (origin - a) / det;
        float u = dot(s, p);
        vec3 q = cross(s, e1);
        float v = dot(direction, q);
        float t = dot(e2, q);
        /* EDGE_SLACK: a ray along the edge two triangles share meets one of them in float32. */
        if (u >= -EDGE_SLACK && v >= -EDGE_SLACK && u + v <= 1.0 + EDGE_SLACK && t > t_min && t < t_hit) {
          t_hit = t;
          hit_uv = vec2(u, v);
          hit = slot;
        }
      }
    }
    /* Up while this node is its parent's second child visited, then to its sibling. */
    float order = low.w;
    while (node > 1 && ((node & 1) == 0) != left_first(order, direction)) {
      node >>= 1;
      order = table_texel(bvh_boxes, 2 * node).w;
    }
    if (node <= 1) {
      break;
    }
    node ^= 1;
  }
  return hit;
}
