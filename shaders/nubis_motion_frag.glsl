/* Motion vectors for the temporal resolve (GDC22; docs/sources.md#motion-vectors): for each pixel, the screen offset in
 * pixels from where its cloud was one timestep ago to where it is now, from the cloud distance the march
 * reports. Output: (dx, dy) pixels, the cloud distance in metres, the clouds' alpha. */
void main()
{
  vec3 origin, dir;
  nubis_view_ray(uv, inv_view_proj, eye, origin, dir);
  float cloud_depth;
  vec4 flash_mask;
  vec4 clouds = nubis_march(origin, dir, gl_FragCoord.xy, cloud_depth, flash_mask);
  if (clouds.a <= 0.0) {
    color = vec4(0.0);
    return;
  }
  vec3 world = origin + dir * cloud_depth;
  /* Both ends are projected (rather than taking this fragment's own position for "now"), so the
   * error of unprojecting through a far-reaching frustum in float cancels out. */
  vec4 now = C.view_proj * vec4(world, 1.0);
  vec4 before = C.prev_view_proj * vec4(nubis_previous_position(world, P.motion_dt), 1.0);
  vec2 size = gl_FragCoord.xy / uv;
  vec2 motion = (now.xy / now.w - before.xy / before.w) * 0.5 * size;
  color = vec4(motion, cloud_depth, clouds.a);
}
