/* SPDX-License-Identifier: GPL-3.0-or-later */
/* Pre-pass, fragment stage (see reflection_prepass_vert.glsl).
 *
 * Target 0, the colour: a diffuse mesh lit as its reflections are (reflection_shading.glsl,
 * with the desired view's eye vector), a reflector at its own flat colour. Target 1, the
 * label: (id, reflection weight, attenuation distance, eye depth of the surface: `eye_depth`). The weight is the reflector's
 * reflectivity, times Schlick's Fresnel term F0 + (1 - F0)(1 - cos t)^5 with cos t = |n . e|
 * when F0 is given (SBC paper, section V-D: the reflected share grows at grazing angles).
 * Glass, whose drawn image is the refracted one, gets 1 minus its exact dielectric
 * reflectance (`dielectric_reflectance`, as Cycles' Glass BSDF and Render Image weigh it; its
 * z holds -2 - F0: draw_geometry.prepare_geometry's `transmits`).
 * Target 2: the smooth normal (for the per-frame passes' law-of-reflection test) and, as
 * w, 1 where the pixel's view ray starts inside a sealed mirror, else 0.
 *
 * A sealed mirror (ReflectorSet.seal_empty_interiors) is a closed solid that holds
 * nothing; its vertices' `lit_interp` is its winding: +1 where its triangles wind
 * counter-clockwise seen from outside, -1 the other way (0: not sealed). Seen from
 * outside, the first surface of a closed solid along a ray is one of its outer sides;
 * a pixel that shows its inner side (its triangle's winding seen from the eye against
 * the solid's) has a view ray starting inside it: the camera's clip start cuts into the
 * mirror. Such a ray bounces inside without end and meets no light: the composite
 * draws it black (reflection_composite_frag.glsl), as Cycles shows it. */

void main()
{
  /* `camera` is the eye (w 1, perspective) or the direction toward it (w 0, orthographic). */
  vec3 to_eye = camera.w > 0.5 ? camera.xyz - position_interp : camera.xyz;
  float weight = label_interp.y;
  vec3 rgb = color_interp.rgb;
  if (label_interp.x < 0.5) {
    vec4 albedo = color_interp;
    if (use_image != 0) {
      albedo *= texture(image, uv_interp);
    }
    rgb = shade(albedo.rgb, lit_interp, normal_interp, to_eye);
  }
  else if (label_interp.z >= 0.0 || label_interp.z <= -2.0) {
    float lengths = length(normal_interp) * length(to_eye);
    float cosine = lengths > 1e-30 ? min(abs(dot(normal_interp, to_eye)) / lengths, 1.0) : 1.0;
    bool transmits = label_interp.z <= -2.0;
    float f0 = transmits ? -2.0 - label_interp.z : label_interp.z;
    /* The index of refraction n from F0 = ((n - 1) / (n + 1))^2. */
    float n = (1.0 + sqrt(f0)) / max(1.0 - sqrt(f0), 1e-6);
    weight *= transmits ? 1.0 - dielectric_reflectance(cosine, 1.0 / n) : f0 + (1.0 - f0) * pow(1.0 - cosine, 5.0);
  }
  float inside = 0.0;
  if (label_interp.x > 0.5 && lit_interp != 0.0 && gl_FrontFacing != (lit_interp > 0.0)) {
    inside = 1.0;
  }
  color_out = vec4(rgb, 1.0);
  label_out = vec4(label_interp.x, weight, label_interp.w, eye_depth(position_interp, camera));
  normal_out = vec4(normal_interp, inside);
}
