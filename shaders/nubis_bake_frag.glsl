/* The VDB bake: the same density the march uses, at voxel centres, full detail.
 * One draw evaluates a block of `bake_tile.w` rows per Z slice, the slices stacked up the target:
 * fragment row r is voxel row r mod rows of slice r / rows. Voxel (i, j, k) of the bake's box sits at
 * bake_origin.xyz + (i, j, k) * voxel size, with (i, j, k) = fragment + the block's integer offset
 * `bake_tile.xyz` (slice k counted from bake_origin.w), so a tiled bake computes exactly the positions
 * a whole-box bake does. Permutations: NUBIS_BAKE_VELOCITY writes the clouds' motion and density;
 * NUBIS_BAKE_PACKED the density alone of four voxels along x per fragment (a quarter of the read-back,
 * for skies without glow or absorption). */

/* The baked density at p: the volume's, plus the 2D cirrus layer as a thin slab holding the same
 * optical depth the march gives it. */
float nubis_bake_density(vec3 p, out NubisDensity d)
{
  d = nubis_density(p, false, 0.0);
  float density = d.fine;
  /* See docs/sources.md#cirrus-bake. */
  float from_cirrus = abs(nubis_altitude(p, P.layer_planet_radius) - P.cirrus_altitude);
  if (from_cirrus < 0.5 * P.cirrus_slab && P.density_sigma > 0.0) {
    density += nubis_cirrus_density(p.xy, 0.0) * P.cirrus_opacity / (P.cirrus_slab * P.density_sigma);
  }
  return density;
}

void main()
{
  vec2 frag = floor(gl_FragCoord.xy);
  float rows = max(bake_tile.w, 1.0);
  float slice = floor(frag.y / rows);
  vec3 index = vec3(frag.x, frag.y - slice * rows, slice) + bake_tile.xyz + vec3(0.0, 0.0, bake_origin.w);
  NubisDensity d;
#if NUBIS_BAKE_PACKED
  index.x = frag.x * 4.0 + bake_tile.x;
  vec4 densities;
  for (int c = 0; c < 4; c++) {
    densities[c] = nubis_bake_density(bake_origin.xyz + (index + vec3(float(c), 0.0, 0.0)) * bake_voxel.x, d);
  }
  color = densities;
#else
  vec3 p = bake_origin.xyz + index * bake_voxel.x;
  float density = nubis_bake_density(p, d);
#  if NUBIS_BAKE_VELOCITY
  /* Where the cloud at p was one frame ago (the motion vectors' own model, GDC22): the displacement
   * per frame, which Python scales to metres per second. */
  color = vec4(p - nubis_previous_position(p, P.motion_dt), density);
#  else
  /* The storm glow as an emission grid: what the march adds per unit length is sigma x density x
   * glow, so the grid holds density x glow (its strongest channel) and Cycles multiplies by sigma. */
  vec3 glow = nubis_storm_glow(p, d.fine) * d.fine;
  /* Rain's and storms' extra absorption (GPU Pro 7, GDC22; docs/sources.md#rain-and-storm-absorption)
   * in density units: Cycles adds it as a Volume Absorption. */
  float absorption = d.fine * (nubis_extinction_factor(p, d.precipitation) - 1.0);
  color = vec4(density, max(glow.r, max(glow.g, glow.b)), absorption, 1.0);
#  endif
#endif
}
