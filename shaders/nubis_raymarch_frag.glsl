/* The full-resolution march: the headless render, the naive march of the benchmark and the offline
 * path. Every pixel is marched, flashes included, and the cirrus layer composited in the order the
 * camera sees it. */
void main()
{
  vec3 origin, dir;
  nubis_view_ray(uv, inv_view_proj, eye, origin, dir);
  vec4 clouds = nubis_shade_ray(origin, dir, gl_FragCoord.xy);
#if NUBIS_FETCH_STATS
  color = vec4(float(nubis_fetches_3d), float(nubis_view_samples), float(nubis_density_calls), 1.0);
#else
  color = clouds;
#endif
}
