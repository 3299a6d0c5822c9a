/* The clouds seen from one point in every direction, as an equirectangular image in the layout of
 * Blender's Environment Texture (core/sky.py): premultiplied radiance and alpha, flashes and the
 * cirrus layer included, for a World environment (blender/scene_render.py). */
void main()
{
  float azimuth = (0.5 - uv.x) * 2.0 * NUBIS_PI;
  float elevation = (uv.y - 0.5) * NUBIS_PI;
  vec3 dir = vec3(cos(elevation) * cos(azimuth), cos(elevation) * sin(azimuth), sin(elevation));
  vec3 origin = eye.xyz;
  float cloud_depth;
  vec4 flash_mask;
  vec4 clouds = nubis_march(origin, dir, gl_FragCoord.xy, cloud_depth, flash_mask);
  clouds.rgb += NUBIS_FLASH_COLOUR * dot(flash_mask, nubis_flash_intensities());
#if NUBIS_CIRRUS
  float behind;
  clouds = nubis_with_cirrus(clouds, origin, dir, behind);
#endif
  color = clouds;
}
