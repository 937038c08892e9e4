/* SPDX-License-Identifier: GPL-3.0-or-later */
/* A refracted path through a closed convex glass solid on its cube map (cube_map.glsl,
 * before this): the eye's ray enters at A, is bent by Snell's law (GLSL's refract, with
 * the map's interpolated normal), leaves at B (`exit_point`) and is bent again. What the
 * per-vertex search (refraction_search.glsl) drives onto a vertex and what the per-pixel
 * paths (glass_rays.glsl) follow from each pixel of the glass. Expects the push constants
 * `camera`, `eta` and `reflects` and the defines EXIT_STEPS, EXIT_TOLERANCE,
 * EXIT_BISECTIONS, EXIT_START and INSIDE_REFLECTIONS. Everything runs relative to the
 * map's centre. */

#define TOTAL_REFLECTION -5

/* Unit direction of the eye's ray arriving at p. */
vec3 eye_ray(vec3 p)
{
  return camera.w > 0.5 ? normalize(p - (camera.xyz - centre)) : -camera.xyz;
}

/* Where the ray from `a` (on the surface) along unit `t` (into the solid) leaves it: the
 * exit B and its outward normal. Plane steps (the ray met with the tangent plane where
 * the map's surface lies along the current estimate's direction; exact in one step on a
 * flat face), from the chord of the sphere through `a`; bisection on the sign of
 * |x| - r(x / |x|) within the bounding sphere where they fail to settle. */
bool exit_point(vec3 a, vec3 t, out vec3 b, out vec3 n)
{
  float along = dot(a, t);
  float far = -along + sqrt(max(along * along - (dot(a, a) - max_radius * max_radius), 0.0));
  if (far <= 0.0) {
    return false;
  }
  float tolerance = EXIT_TOLERANCE * max_radius;
  float s = clamp(-2.0 * along, 0.0, far);
  float radius;
  for (int k = 0; k < EXIT_STEPS; k++) {
    vec3 x = a + s * t;
    float distance = max(length(x), 1e-30);
    if (!map_surface(x / distance, radius, n)) {
      return false;
    }
    float rate = dot(t, n);
    if (rate <= 1e-4) {
      break;
    }
    float next = clamp(s + dot((radius - distance) * (x / distance), n) / rate, 0.0, far);
    if (abs(next - s) < tolerance) {
      b = a + next * t;
      return map_surface(normalize(b), radius, n);
    }
    s = next;
  }
  float lo = EXIT_START * far;
  float hi = far;
  for (int k = 0; k < EXIT_BISECTIONS; k++) {
    float mid = 0.5 * (lo + hi);
    vec3 x = a + mid * t;
    float distance = max(length(x), 1e-30);
    bool valid = map_surface(x / distance, radius, n);
    if (valid && distance < radius) {
      lo = mid;
    }
    else {
      hi = mid;
    }
  }
  b = a + hi * t;
  return map_surface(normalize(b), radius, n) && dot(t, n) > 0.0;
}

/* The ray inside from `from` (on the surface, relative to the centre) along unit `inside`
 * until it leaves: FOUND with its exit `b`, the unit ray `o` leaving there, and the ray
 * inside that met the surface there (`last`, with the outward normal `normal`), or why it
 * does not leave (a hole of the map, total reflection). Where the ray inside meets the
 * surface past the critical angle, glass that `reflects` (a Glass BSDF) reflects it
 * inside, INSIDE_REFLECTIONS times at most, and the path leaves where it next can; glass
 * that does not (a Refraction BSDF) stops it there, TOTAL_REFLECTION, black in Cycles. */
int leave_glass(vec3 from, vec3 inside, out vec3 b, out vec3 o, out vec3 last, out vec3 normal)
{
  b = vec3(0.0);
  o = vec3(0.0);
  normal = vec3(0.0);
  for (int bounce = 0; bounce <= INSIDE_REFLECTIONS; bounce++) {
    last = inside;
    if (!exit_point(from, inside, b, normal)) {
      return NO_SURFACE;
    }
    o = refract(inside, -normal, eta);
    if (dot(o, o) > 0.0) {
      return FOUND;
    }
    if (reflects == 0) {
      break;
    }
    inside = reflect(inside, -normal);
    from = b;
  }
  o = vec3(0.0);
  return TOTAL_REFLECTION;
}

/* The path entering at `a` (on the surface, relative to the centre) whose outward normal
 * there is `n`: FOUND with its exit `b` and the unit ray `o` leaving there
 * (`leave_glass`, which `last` and `normal` are from), or why there is none (the surface
 * faces away from the eye, or `leave_glass`'s reason). */
int refracted_path(vec3 a, vec3 n, out vec3 b, out vec3 o, out vec3 last, out vec3 normal)
{
  vec3 incoming = eye_ray(a);
  if (dot(incoming, n) >= 0.0) {
    b = vec3(0.0);
    o = vec3(0.0);
    last = vec3(0.0);
    normal = vec3(0.0);
    return FACES_AWAY;
  }
  return leave_glass(a, refract(incoming, n, 1.0 / eta), b, o, last, normal);
}
