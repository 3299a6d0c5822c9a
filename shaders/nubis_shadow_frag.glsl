/* The clouds' transmittance towards the sun over a plane below them: the map a shadow caster in the
 * scene carries (blender/f12/scene_render.py), so Cycles and EEVEE cast the clouds' shadows on the scene.
 * Each texel marches the full-detail density along its sun ray from where it enters the cloud shell
 * to where it leaves (rain's and storms' absorption included) and adds the cirrus layer's optical
 * depth. */
void main()
{
  vec3 p = shadow_origin.xyz + (uv.x - 0.5) * shadow_u.xyz + (uv.y - 0.5) * shadow_v.xyz;
  vec3 sun = P.sun_dir.xyz;
  float R = P.layer_planet_radius;
  vec2 inner = nubis_ray_sphere(p, sun, R, P.shell_bottom);
  vec2 outer = nubis_ray_sphere(p, sun, R, P.shell_top);
  float altitude = nubis_altitude(p, R);
  float t0 = altitude < P.shell_bottom ? max(inner.y, 0.0) : 0.0;
  float t1 = max(outer.y, 0.0);
  /* Only the clouds within the draw radius exist (the density fades them); a sun at the horizon
   * would otherwise march hundreds of kilometres. */
  t1 = min(t1, t0 + 2.0 * P.layer_draw_radius);
  float tau = 0.0;
  if (sun.z > -0.05 && t1 > t0) {
    const int samples = 48;
    float dt = (t1 - t0) / float(samples);
    for (int i = 0; i < samples; i++) {
      vec3 q = p + sun * (t0 + (float(i) + 0.5) * dt);
      NubisDensity d = nubis_density(q, false, 0.0);
      tau += d.fine * nubis_extinction_factor(q, d.precipitation) * dt;
    }
    tau *= P.density_sigma;
#if NUBIS_CIRRUS
    tau += nubis_cirrus_optical_depth(p, sun, 0.0);
#endif
  }
  float transmittance = sun.z > -0.05 ? exp(-tau) : 0.0;
  color = vec4(vec3(transmittance), 1.0);
}
