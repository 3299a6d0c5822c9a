/* The full-resolution march: the headless render, the naive march of the benchmark and the offline
 * path. Every pixel is marched, flashes included, and the cirrus layer composited in the order the
 * camera sees it. */
void main()
{
  vec3 origin, dir;
  nubis_view_ray(uv, inv_view_proj, eye, origin, dir);
  float cloud_depth;
  vec4 flash_mask;
  vec4 clouds = nubis_march(origin, dir, gl_FragCoord.xy, cloud_depth, flash_mask);
  clouds.rgb += NUBIS_FLASH_COLOUR * dot(flash_mask, nubis_flash_intensities());
#if NUBIS_CIRRUS
  float behind;
  clouds = nubis_with_cirrus(clouds, origin, dir, behind);
#endif
#if NUBIS_FETCH_STATS
  color = vec4(float(nubis_fetches_3d), float(nubis_view_samples), float(nubis_density_calls), 1.0);
#else
  color = clouds;
#endif
}
