/* SPDX-License-Identifier: GPL-3.0-or-later */
/* Composite, fragment stage (drawing/reflection_draw.py), one full-screen triangle.
 *
 * On reflector pixels (pre-pass id > 0): the traced colour where the caller traced the
 * pixel (exact: it wins over a drawn one, which in a camera's unreliable cells may be an
 * image of the wrong point), else the reflected colour where a reflection was
 * drawn (reflection alpha 1), else the world colour (the reflected ray leaves the
 * scene), blended with the reflector's own colour by its reflectivity (1 = perfect
 * mirror; SBC paper, Popescu, Sacks, Mei 2006, section V-D: "the diffuse component
 * and the reflection are blended with a simple shader"); the reflector's colour comes
 * from `beneath_colors`, the pre-pass's colours unless a pass made others (what glass
 * reflects, beneath its refraction). Elsewhere the pre-pass colour (the world where
 * nothing was drawn), or nothing when `reflectors_only` (a viewport overlay over
 * Blender's own drawing).
 *
 * The band along the footprint's edge: a sample-based camera projects a point only
 * between four rays of its group (engine/methods/sbc/sbc.py), so no reflection can land in the last
 * ray-map cell (up to the down-sampling factor d, in pixels) before the reflector's
 * silhouette or an object in front of it. Where the caller traced those pixels
 * (engine/geometry/band_trace.py), `traced_colors` holds them (alpha 1). Without tracing
 * (`fill_radius` > 0, e.g. d), a reflector pixel within `fill_radius` of its
 * footprint's edge (or of where the clip start cuts into a sealed mirror, below) that
 * has no reflection takes the reflection of the nearest pixel within `fill_radius` that
 * has one on the same reflector, a cheap guess. Elsewhere, or
 * where there is none, it shows the world.
 *
 * Reflector properties (SBC V-D): the label's y is the reflection weight (reflectivity,
 * times Fresnel where asked, reflection_prepass_frag.glsl) and z the attenuation
 * distance A (0: none). A reflection's alpha (and a traced one's) is 1 + its distance d
 * from the mirror along the reflected ray; it fades to the world colour by
 * min(1, (d / A)^2), the paper's quadratic fall-off with distance.
 *
 * Inside a sealed mirror: where the pre-pass marks the pixel's view ray as starting
 * inside a closed mirror that holds nothing (`prepass_normals` w, the camera's clip
 * start cutting into the mirror: reflection_prepass_frag.glsl), the ray would bounce
 * inside without end and meet no light: the reflection is black, whatever was drawn or
 * traced there, and is not faded (Cycles shows black there once its bounces run out).
 *
 * Depth: a mirror pixel is drawn at its pre-pass depth brought nearer by `depth_bias`
 * (a, s): z - s (a - z) (screen_space.depth_bias). A viewport overlay's pre-pass draws
 * the mirrors alone, and the depth test against the scene's own depth (Blender's
 * drawing, in the bound framebuffer) hides a mirror pixel where an object stands in
 * front of it. Elsewhere the test is off. */

vec3 attenuated(vec3 reflected, float alpha, float attenuation)
{
  if (attenuation <= 0.0) {
    return reflected;
  }
  float fade = min(1.0, pow(max(alpha - 1.0, 0.0) / attenuation, 2.0));
  return mix(reflected, world_color.rgb, fade);
}

void main()
{
  ivec2 texel = ivec2(gl_FragCoord.xy) - origin;  /* the view's pixel, wherever its viewport is */
  vec4 label = texelFetch(prepass_labels, texel, 0);
  if (label.x < 0.5) {
    if (reflectors_only != 0) {
      discard;
    }
    vec4 base = texelFetch(prepass_colors, texel, 0);
    color_out = base.a > 0.5 ? vec4(base.rgb, 1.0) : vec4(world_color.rgb, 1.0);
    gl_FragDepth = gl_FragCoord.z;  /* a render's composite: no depth test */
    return;
  }
  vec4 base = texelFetch(beneath_colors, texel, 0);
  float depth = texelFetch(prepass_depth, texel, 0).r;
  gl_FragDepth = depth - depth_bias.y * (depth_bias.x - depth);
  vec4 reflection = texelFetch(reflection_colors, texel, 0);
  vec4 traced = texelFetch(traced_colors, texel, 0);
  vec3 reflected = world_color.rgb;
  if (texelFetch(prepass_normals, texel, 0).w > 0.5) {
    reflected = vec3(0.0);
  }
  else if (traced.a > 0.5) {
    reflected = attenuated(traced.rgb, traced.a, label.z);
  }
  else if (reflection.a > 0.5) {
    reflected = attenuated(reflection.rgb, reflection.a, label.z);
  }
  else if (fill_radius > 0) {
    /* Only in the band along the footprint's edge: elsewhere a missing reflection is
     * the world seen in the mirror. */
    ivec2 size = textureSize(reflection_colors, 0);
    /* The labels first, and the colours only near an edge: most pixels without a
     * reflection are the world seen inside the footprint, and half the fetches then.
     * A window that reaches past the view's border is near an edge. */
    bool near_edge = any(lessThan(texel, ivec2(fill_radius))) ||
                     any(greaterThanEqual(texel, size - ivec2(fill_radius)));
    for (int dy = -fill_radius; dy <= fill_radius && !near_edge; dy++) {
      for (int dx = -fill_radius; dx <= fill_radius; dx++) {
        ivec2 other = texel + ivec2(dx, dy);
        if (abs(texelFetch(prepass_labels, other, 0).x - label.x) >= 0.5 ||
            texelFetch(prepass_normals, other, 0).w > 0.5) {
          near_edge = true;  /* the footprint's edge, or where the clip start cuts into it */
          break;
        }
      }
    }
    int best = 1 << 30;
    vec4 nearest = vec4(reflected, 0.0);
    for (int dy = -fill_radius; dy <= fill_radius && near_edge; dy++) {
      for (int dx = -fill_radius; dx <= fill_radius; dx++) {
        ivec2 other = texel + ivec2(dx, dy);
        if (any(lessThan(other, ivec2(0))) || any(greaterThanEqual(other, size))) {
          continue;
        }
        int distance2 = dx * dx + dy * dy;
        vec4 candidate = texelFetch(reflection_colors, other, 0);
        if (distance2 < best && candidate.a > 0.5 && abs(texelFetch(prepass_labels, other, 0).x - label.x) < 0.5 &&
            texelFetch(prepass_normals, other, 0).w < 0.5) {
          best = distance2;
          nearest = candidate;
        }
      }
    }
    if (near_edge && nearest.a > 0.5) {
      reflected = attenuated(nearest.rgb, nearest.a, label.z);
    }
  }
  color_out = vec4(mix(base.rgb, reflected, clamp(label.y, 0.0, 1.0)), 1.0);
}
