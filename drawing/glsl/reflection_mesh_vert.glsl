/* SPDX-License-Identifier: GPL-3.0-or-later */
/* Reflected-mesh pass, vertex stage (drawing/reflection_draw.py), every frame.
 *
 * SBC paper (Popescu, Sacks, Mei 2006), section V-A/B. The projection of every vertex
 * with the sample-based camera (reflection_project_vert.glsl) ran once, when the camera
 * or the meshes last changed; which reflected triangles are drawn (all three corners
 * projected, stitched across sheet seams, mixed triangles subdivided) was decided then,
 * on the CPU, from its read-back. What stays per frame is this: each vertex of a drawn
 * reflected triangle carries its *first reflector point* in world space (`world_depth.xyz`,
 * relative to the renderer's shift) and is placed where the current view sees that
 * point, with the depth of SBC V-A, (k - 1 + z / D) g (`world_depth.w`, view independent:
 * order and distance along the reflected ray). A reflection therefore stays on its
 * mirror in world space when the view moves away from the camera's view, until a new
 * camera lands. In the camera's own view (`use_camera_pixel`) the projected pixel itself
 * is used (`pixel_reflector.xy`), bit-for-bit what the projection gave. `snap_grid` (the
 * view's cells across and up, 0: none): the live view places each vertex at the centre
 * of its cell, within the camera's Accuracy, so that a triangle inside one cell
 * collapses and is dropped before set-up (reflected_meshes.SNAP_SHARE).
 *
 * w = 1: the reflected triangle is interpolated affinely in the image, as before the
 * cache (the reflected positions are the projections of its corners). A vertex whose
 * reflector point is behind the current view (w <= 0) collapses its triangle off screen.
 * `pixel_reflector.z` is the id the fragment stage requires in the pre-pass (history[0] + 1). */

void main()
{
  color_interp = color;
  normal_interp = normal_lit.xyz;
  lit_interp = normal_lit.w;
  uv_interp = uv;
  eye_interp = eye_distance.xyz;
  distance_interp = eye_distance.w;
  reflector_interp = pixel_reflector.z;
  mirror_point_interp = world_depth.xyz;
  /* Depth (k - 1 + z / D) g: order k = 1 below g. Only then is the eye vector's reflector
   * point the one the eye sees, which the fragment stage's law-of-reflection test needs. */
  first_order_interp = world_depth.w < order_range ? 1.0 : 0.0;
  vec2 ndc;
  if (use_camera_pixel != 0) {
    ndc = pixel_reflector.xy / view_size * 2.0 - 1.0;
  }
  else {
    vec4 clip = view_projection * vec4(world_depth.xyz, 1.0);
    if (clip.w <= 0.0) {
      gl_Position = vec4(2.0, 2.0, 2.0, 1.0);
      return;
    }
    ndc = clip.xy / clip.w;
  }
  if (snap_grid.x > 0.0) {
    ndc = snapped(ndc, snap_grid);
  }
  gl_Position = vec4(ndc, world_depth.w * 2.0 - 1.0, 1.0);
}
