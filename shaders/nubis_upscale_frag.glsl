/* Temporal upscaling, step 3: the history onto the view, premultiplied, with GDC22's upscale blur
 * (docs/sources.md#upscale-blur; filter_size.x: 1 = the history's own texels, 2 = twice as wide, the PS4 setting), and the
 * lightning of this frame added from the flash mask at its full intensity (GDC22's flash mask).
 * With the scene's depth bound (scene.x), each view pixel takes only history texels that saw its own surface
 * (or the sky, for a pixel of sky) where its taps straddle a silhouette, so an object's edge is neither
 * veiled by the sky's clouds nor left clear by its own (docs/viewport.md#clouds-in-front-of-the-scene). */

void main()
{
  vec2 texel = filter_size.zw;
  float r = 0.5 * (filter_size.x - 1.0);
  vec4 c, f;
  float seen;
  if (r <= 0.0) {
    c = textureLod(hist_color, uv, 0.0);
    f = textureLod(hist_flash, uv, 0.0);
    seen = scene.x > 0.5 ? textureLod(hist_attr, uv, 0.0).y : 0.0;
  }
  else {
    /* Four bilinear taps at +-r texels: a tent twice as wide at r = 0.5. */
    c = vec4(0.0);
    f = vec4(0.0);
    seen = 0.0;
    for (int i = 0; i < 4; i++) {
      vec2 o = vec2((i & 1) == 0 ? -r : r, (i & 2) == 0 ? -r : r) * texel;
      c += 0.25 * textureLod(hist_color, uv + o, 0.0);
      f += 0.25 * textureLod(hist_flash, uv + o, 0.0);
      if (scene.x > 0.5) {
        seen += 0.25 * textureLod(hist_attr, uv + o, 0.0).y;
      }
    }
  }
  if (scene.x > 0.5) {
    float surface = nubis_axial_depth(texelFetch(scene_depth, ivec2(gl_FragCoord.xy), 0).r, depth_map);
    if (!nubis_same_surface(seen, surface)) {
      /* The taps mix surfaces: the history texels around this pixel that saw its own, nearest first. */
      vec2 size = 1.0 / texel;
      vec2 p = uv * size - 0.5;
      ivec2 centre = ivec2(floor(p + 0.5));
      ivec2 last = ivec2(size) - 1;
      vec4 sum_c = vec4(0.0), sum_f = vec4(0.0);
      float sum_w = 0.0;
      for (int dy = -1; dy <= 1; dy++) {
        for (int dx = -1; dx <= 1; dx++) {
          ivec2 t = clamp(centre + ivec2(dx, dy), ivec2(0), last);
          if (!nubis_same_surface(texelFetch(hist_attr, t, 0).y, surface)) {
            continue;
          }
          vec2 d = vec2(t) - p;
          float w = 1.0 / (1.0 + 4.0 * dot(d, d));
          sum_c += w * texelFetch(hist_color, t, 0);
          sum_f += w * texelFetch(hist_flash, t, 0);
          sum_w += w;
        }
      }
      /* None saw it (a surface thinner than a history texel): the taps as they are. */
      if (sum_w > 0.0) {
        c = sum_c / sum_w;
        f = sum_f / sum_w;
      }
    }
  }
  vec4 intensities = vec4(P.storm_glow[0].w, P.storm_glow[1].w, P.storm_glow[2].w, P.storm_glow[3].w);
  c.rgb += NUBIS_FLASH_COLOUR * (dot(f, intensities) / NUBIS_FLASH_MASK_SCALE);
  color = c;
}
