/* SPDX-License-Identifier: GPL-3.0-or-later */
/* Vertex projection pass, fragment stage: the point's texels get its projection. */

void main()
{
  projected_out = projected;
  eye_out = projected_eye;
}
