/* Temporal upscaling, step 3: the history onto the view, premultiplied, with GDC22's upscale blur
 * (docs/sources.md#upscale-blur; filter_size.x: 1 = the history's own texels, 2 = twice as wide, the PS4 setting), and the
 * lightning of this frame added from the flash mask at its full intensity (GDC22's flash mask). */
void main()
{
  vec2 texel = filter_size.zw;
  float r = 0.5 * (filter_size.x - 1.0);
  vec4 c, f;
  if (r <= 0.0) {
    c = textureLod(hist_color, uv, 0.0);
    f = textureLod(hist_flash, uv, 0.0);
  }
  else {
    /* Four bilinear taps at +-r texels: a tent twice as wide at r = 0.5. */
    c = vec4(0.0);
    f = vec4(0.0);
    for (int i = 0; i < 4; i++) {
      vec2 o = vec2((i & 1) == 0 ? -r : r, (i & 2) == 0 ? -r : r) * texel;
      c += 0.25 * textureLod(hist_color, uv + o, 0.0);
      f += 0.25 * textureLod(hist_flash, uv + o, 0.0);
    }
  }
  vec4 intensities = vec4(P.storm_glow[0].w, P.storm_glow[1].w, P.storm_glow[2].w, P.storm_glow[3].w);
  c.rgb += NUBIS_FLASH_COLOUR * (dot(f, intensities) / NUBIS_FLASH_MASK_SCALE);
  color = c;
}
