/* Temporal upscaling, step 1 (S15, GDC22): the working buffer holds one pixel of every 4x4 block of
 * the history, the block's pixel `block.xy` (the Bayer order of this redraw). Its full-resolution
 * pixel is marched exactly as the full-resolution march would march it (same ray, same jitter), so a
 * still view converges to that image. Outputs: the clouds and cirrus without the lightning flashes,
 * (cloud distance, the scene's surface's distance along the view's axis or 0, -, -), and the per-storm
 * flash mask (nubis_march). Where the scene's geometry stands (T.scene.x = 1 when its depth is bound;
 * T.scene.yz scale history pixels to its pixels), the march ends at its surface (GDC22: the march stops at the depth
 * of what the scene draws) and holds the clouds in front of it, which the upscale lays over the object
 * (docs/viewport.md#clouds-in-front-of-the-scene); T carries the view's depth mapping. */
void main()
{
  ivec2 pixel = ivec2(gl_FragCoord.xy) * NUBIS_BLOCK + ivec2(block.xy);
  attr = vec4(0.0);
  flash = vec4(0.0);
  color = vec4(0.0);
  if (pixel.x >= int(block.z) || pixel.y >= int(block.w)) {
    return;
  }
  float surface = 0.0;
  if (T.scene.x > 0.5) {
    surface = nubis_axial_depth(texelFetch(scene_depth, ivec2(vec2(pixel) * T.scene.yz), 0).r, T.depth_map);
  }
  vec2 centre = vec2(pixel) + 0.5;
  vec3 origin, dir;
  nubis_view_ray(centre / block.zw, inv_view_proj, eye, origin, dir);
  float cloud_depth;
  vec4 flash_mask;
  vec4 clouds;
  if (surface > 0.0) {
    float split = nubis_axial_to_ray(surface, origin, dir, T.view_axis);
    clouds = nubis_march_in_front(origin, dir, centre, split, cloud_depth, flash_mask);
  }
  else {
    clouds = nubis_march(origin, dir, centre, cloud_depth, flash_mask);
#if NUBIS_CIRRUS
    float behind;
    clouds = nubis_with_cirrus(clouds, origin, dir, centre, behind);
    flash_mask *= behind;
#endif
  }
#if NUBIS_FETCH_STATS
  clouds = vec4(float(nubis_fetches_3d), float(nubis_view_samples), float(nubis_density_calls), 1.0);
#endif
  color = clouds;
  attr = vec4(cloud_depth, surface, 0.0, 0.0);
  flash = flash_mask * NUBIS_FLASH_MASK_SCALE;
}
