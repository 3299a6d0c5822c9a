/* The World's sky behind the clouds in Solid shading: the same capture of the World the clouds are lit
 * by (nubis_sky_radiance), towards each pixel's view ray, drawn on the far plane so the scene's objects
 * stay in front (blender/live/viewport.py). */
void main()
{
  vec3 origin, dir;
  nubis_view_ray(uv, inv_view_proj, eye, origin, dir);
  color = vec4(nubis_sky_radiance(dir), 1.0);
}
