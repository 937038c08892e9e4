/* SPDX-License-Identifier: GPL-3.0-or-later */
/* Pre-pass, fragment stage: flat (unlit) colour into target 0, (id, reflectivity) into
 * target 1 (see reflection_prepass_vert.glsl). */

void main()
{
  color_out = vec4(color_interp.rgb, 1.0);
  label_out = vec4(label_interp, 0.0, 1.0);
}
