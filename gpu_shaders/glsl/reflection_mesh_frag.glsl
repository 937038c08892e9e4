/* SPDX-License-Identifier: GPL-3.0-or-later */
/* Reflected-mesh pass, fragment stage.
 *
 * A reflection is kept only on pixels where the pre-pass saw this sheet's first
 * reflector (id = history[0] + 1): that confines it to the visible footprint of the
 * reflector, and real objects in front of the mirror stay in front, their pre-pass id
 * being 0 (Roger & Holzschuch 2006, section 3.3.6, with an id texture for the stencil).
 * Hidden-surface removal between reflected points is the depth test on the depth
 * written by the vertex stage (SBC paper section V-A, cases 2 and 3). */

void main()
{
  float id = texelFetch(prepass_labels, ivec2(gl_FragCoord.xy), 0).x;
  if (abs(id - float(first_reflector_id)) > 0.5) {
    discard;
  }
  color_out = vec4(color_interp.rgb, 1.0);
}
