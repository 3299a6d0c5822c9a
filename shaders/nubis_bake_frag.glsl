/* One Z slice of the VDB bake: the same density the march uses, at voxel centres, full detail. */
void main()
{
  vec2 ij = floor(gl_FragCoord.xy);
  vec3 p = bake_origin.xyz + vec3(ij, bake_origin.w) * bake_voxel.x;
  NubisDensity d = nubis_density(p, false, 0.0);
  float density = d.fine;
  /* The 2D cirrus layer becomes a thin slab holding the same optical depth the march gives it
   * (docs/sources.md#cirrus-bake). */
  float from_cirrus = abs(nubis_altitude(p, P.layer_planet_radius) - P.cirrus_altitude);
  if (from_cirrus < 0.5 * P.cirrus_slab && P.density_sigma > 0.0) {
    density += nubis_cirrus_density(p.xy, 0.0) * P.cirrus_opacity / (P.cirrus_slab * P.density_sigma);
  }
  /* The storm glow as an emission grid: what the march adds per unit length is sigma x density x
   * glow, so the grid holds density x glow (its strongest channel) and Cycles multiplies by sigma. */
  vec3 glow = nubis_storm_glow(p, d.fine) * d.fine;
  /* Rain's and storms' absorption (GPU Pro 7, GDC22; docs/sources.md#rain-and-storm-absorption) in density units: Cycles adds it as a Volume
   * Absorption. */
  float absorption = d.fine * (nubis_extinction_factor(p, d.precipitation) - 1.0);
  color = vec4(density, max(glow.r, max(glow.g, glow.b)), absorption, 1.0);
}
