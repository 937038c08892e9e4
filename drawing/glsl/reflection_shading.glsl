/* SPDX-License-Identifier: GPL-3.0-or-later */
/* Shading (and the helpers below) shared by the pre-pass, the reflected meshes and the mixed-triangle pass
 * (drawing/reflection_draw.py; numpy twin in engine/geometry/band_trace.py, `shade`).
 *
 * SBC paper (Popescu, Sacks, Mei 2006), section V-C: a reflected vertex keeps the data
 * of the unreflected mesh (colour, normal, texture coordinates) and is lit with the
 * *true* eye vector, from the reflector point toward the original vertex, not from the
 * desired view's eye. The light is a headlight along that eye vector (Blender's Solid
 * mode studio light is also fixed to the view): Lambert with an ambient floor,
 * albedo * (SHADE_AMBIENT + (1 - SHADE_AMBIENT) |n . e|), two-sided. Emission-only
 * materials (`lit` 0) show their emission colour unlit. */

vec3 shade(vec3 albedo, float lit, vec3 normal, vec3 to_eye)
{
  if (lit < 0.5) {
    return albedo;
  }
  float lengths = length(normal) * length(to_eye);
  float cosine = lengths > 1e-30 ? abs(dot(normal, to_eye)) / lengths : 1.0;
  return albedo * (SHADE_AMBIENT + (1.0 - SHADE_AMBIENT) * cosine);
}

/* Unpolarised Fresnel reflectance of a dielectric interface (Fresnel's equations: the mean
 * of the s and p amplitudes squared) for the incidence cosine `cosine` and `ratio` =
 * n1 / n2 of the indices before and after it; 1 past the critical angle (numpy twin:
 * engine/glass/snell.py, `fresnel_dielectric`). */
float dielectric_reflectance(float cosine, float ratio)
{
  float sine2 = ratio * ratio * (1.0 - cosine * cosine);
  if (sine2 >= 1.0) {
    return 1.0;
  }
  float refracted = sqrt(1.0 - sine2);
  float s = (ratio * cosine - refracted) / max(ratio * cosine + refracted, 1e-30);
  float p = (cosine - ratio * refracted) / max(cosine + ratio * refracted, 1e-30);
  return 0.5 * (s * s + p * p);
}

/* How far `p` lies from the eye: the distance to it (`camera.w` 1: the eye, perspective), or
 * its depth along the view (`camera.w` 0: the unit direction toward the viewer,
 * orthographic). The pre-pass writes it for the visible surface of each pixel; the
 * per-frame passes' reflected meshes compare their reflector points with it. */
float eye_depth(vec3 p, vec4 camera)
{
  return camera.w > 0.5 ? length(camera.xyz - p) : -dot(p, camera.xyz);
}

/* The world point at `first_depth` along the desired view's ray through `pixel`
 * (View.pixel_rays: from the near plane, unit direction). */
vec3 view_ray_point(mat4 inverse_view_projection, vec2 view_size, vec2 pixel, float first_depth)
{
  vec2 ndc = pixel / view_size * 2.0 - 1.0;
  vec4 near = inverse_view_projection * vec4(ndc, -1.0, 1.0);
  vec4 far = inverse_view_projection * vec4(ndc, 1.0, 1.0);
  vec3 origin = near.xyz / near.w;
  return origin + first_depth * normalize(far.xyz / far.w - origin);
}

/* The eye's ray through the centre of `pixel` of a view of `view_size` pixels: its origin
 * (the eye where `camera.w` is 1, perspective; the near plane, orthographic), unit
 * direction, and in `start` the origin's eye depth (eye_depth's measure), so that the
 * point of eye depth d along it lies at origin + (d - start) direction. */
void pixel_ray(mat4 inverse_view_projection, vec4 camera, ivec2 pixel, vec2 view_size, out vec3 origin,
               out vec3 direction, out float start)
{
  vec2 ndc = (vec2(pixel) + 0.5) / view_size * 2.0 - 1.0;
  vec4 near = inverse_view_projection * vec4(ndc, -1.0, 1.0);
  vec4 far = inverse_view_projection * vec4(ndc, 1.0, 1.0);
  direction = normalize(far.xyz / far.w - near.xyz / near.w);
  origin = camera.w > 0.5 ? camera.xyz : near.xyz / near.w;
  start = camera.w > 0.5 ? 0.0 : -dot(origin, camera.xyz);
}

/* `ndc` moved to the centre of its cell of a grid `cells` across and up the view: the live
 * view's snapping of reflected vertices within their Accuracy (reflected_meshes.SNAP_SHARE),
 * so that a triangle inside one cell collapses and is dropped before set-up. */
vec2 snapped(vec2 ndc, vec2 cells)
{
  return (floor((ndc * 0.5 + 0.5) * cells) + 0.5) / cells * 2.0 - 1.0;
}
