/* The viewport and offscreen render: clouds, then the cirrus layer behind them. */
void main()
{
  vec3 origin, dir;
  nubis_view_ray(uv, inv_view_proj, eye, origin, dir);
  float cloud_depth;
  vec4 clouds = nubis_march(origin, dir, gl_FragCoord.xy, cloud_depth);
  /* SPEC 1.8, GPU Pro 7: the high layer is sampled at the end of the march, behind the volume. */
  vec4 cirrus = nubis_cirrus(origin, dir);
  color = clouds + (1.0 - clouds.a) * cirrus;
}
