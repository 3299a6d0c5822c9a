/* The clouds seen from one point in every direction, as an equirectangular image in the layout of
 * Blender's Environment Texture (core/sky.py): premultiplied radiance and alpha, flashes and the
 * cirrus layer included, for a World environment (blender/f12/scene_render.py). */
void main()
{
  float azimuth = (0.5 - uv.x) * 2.0 * NUBIS_PI;
  float elevation = (uv.y - 0.5) * NUBIS_PI;
  vec3 dir = vec3(cos(elevation) * cos(azimuth), cos(elevation) * sin(azimuth), sin(elevation));
  vec3 origin = eye.xyz;
  vec4 clouds = nubis_shade_ray(origin, dir, gl_FragCoord.xy);
  color = clouds;
}
