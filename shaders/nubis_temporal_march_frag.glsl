/* Temporal upscaling, step 1 (S15, GDC22): the working buffer holds one pixel of every 4x4 block of
 * the history, the block's pixel `block.xy` (the Bayer order of this redraw). Its full-resolution
 * pixel is marched exactly as the full-resolution march would march it (same ray, same jitter), so a
 * still view converges to that image. Outputs: the clouds and cirrus without the lightning flashes,
 * (cloud distance, 1 = marched, -, -), and the per-storm flash mask (nubis_march). Pixels the scene's
 * geometry hides are not marched (GDC22: "if objects render in front of the clouds, we do not march
 * from those pixels"; docs/sources.md#pixel-culling): cull.x = 1 when a depth is bound, cull.yz scale history pixels to its pixels. */
void main()
{
  ivec2 pixel = ivec2(gl_FragCoord.xy) * NUBIS_BLOCK + ivec2(block.xy);
  attr = vec4(0.0);
  flash = vec4(0.0);
  color = vec4(0.0);
  if (pixel.x >= int(block.z) || pixel.y >= int(block.w)) {
    return;
  }
  if (cull.x > 0.5) {
    float depth = texelFetch(scene_depth, ivec2(vec2(pixel) * cull.yz), 0).r;
    if (depth < 1.0) {
      attr = vec4(0.0, 1.0, 0.0, 0.0);
      return;
    }
  }
  vec2 centre = vec2(pixel) + 0.5;
  vec3 origin, dir;
  nubis_view_ray(centre / block.zw, inv_view_proj, eye, origin, dir);
  float cloud_depth;
  vec4 flash_mask;
  vec4 clouds = nubis_march(origin, dir, centre, cloud_depth, flash_mask);
#if NUBIS_CIRRUS
  float behind;
  clouds = nubis_with_cirrus(clouds, origin, dir, centre, behind);
  flash_mask *= behind;
#endif
#if NUBIS_FETCH_STATS
  clouds = vec4(float(nubis_fetches_3d), float(nubis_view_samples), float(nubis_density_calls), 1.0);
#endif
  color = clouds;
  attr = vec4(cloud_depth, 1.0, 0.0, 0.0);
  flash = flash_mask * NUBIS_FLASH_MASK_SCALE;
}
