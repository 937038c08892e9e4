/* SPDX-License-Identifier: GPL-3.0-or-later */
/* Pre-pass, vertex stage (drawing/reflection_draw.py).
 *
 * Every diffuse mesh and every reflector, drawn once with the depth test from the
 * desired view: the real scene's visibility (SBC paper, Popescu, Sacks, Mei 2006,
 * section V-A, visibility case 1: the closest scene point or reflector is visible).
 * Positions arrive relative to a shift that is folded into `view_projection` (and
 * `camera`) in float64, so large world coordinates keep their precision in float32.
 * `label` is (id, reflectivity, Fresnel F0 or -1 for none, attenuation distance):
 * id 0 for diffuse meshes, reflector index + 1 for reflectors; it becomes the id target
 * that confines each reflection to the visible footprint of its first reflector (the
 * stencil of Roger & Holzschuch 2006, 3.3.6, which Blender's Python gpu module does not
 * expose). `normal_lit` is the smooth normal and, for diffuse meshes, whether the
 * colour is lit (1) or an unlit emission (0). */

void main()
{
  color_interp = color;
  label_interp = label;
  normal_interp = normal_lit.xyz;
  lit_interp = normal_lit.w;
  uv_interp = uv;
  position_interp = position;
  gl_Position = view_projection * vec4(position, 1.0);
}
