/* Density probe, for tests only: one fragment per texel of probe_points, so the density the viewport,
 * the render and the bake share can be read back and compared with an independent implementation.
 * probe_mode.x picks what is written, t being the fragment's texel of probe_points:
 *   0: vec4(fine density, coarse density, height fraction, 0) at the world point t.xyz, of the cheap sample
 *      when probe_mode.y is 1;
 *   1: vec4(remap(t.x, t.y, t.z, t.w, probe_mode.y), 0, 0, 0): the shared helper (GPU Pro 7's remap) as compiled;
 *   2: the raw filtered noise at normalised coordinates t.xyz, from noise_lf (probe_mode.y = 0),
 *      noise_hf (1) or noise_curl (2, t.xy), so a test can see how this GPU filters 8-bit textures;
 *   3: vec4(vortex-moved xy, the second ring's xy) for the world xy t.xy (GDC22's vortex);
 *   4: vec4(storm glow rgb, 0) at the world point t.xyz for a fine density t.w (GDC22's glow);
 *   5: vec4(nubis_slab_multiple_scattering(t.x, t.y, t.z), nubis_slab_scattering(t.x, t.y, t.z),
 *      nubis_slab_exit_shape(t.x, t.z, t.w > 0.5), 0): a slab's light at view cosine t.x, sun cosine t.y,
 *      vertical optical depth t.z, and the angular shape of its diffuse light lit from the far face (t.w 1)
 *      or the viewer's own (0);
 *   6: vec4(nubis_slab_diffusion(t.x, t.y, t.z, t.w, probe_mode.y), nubis_absorbing_decay(t.x, t.y), 0, 0);
 *   7: vec4(nubis_slab_sky_weights(t.x, t.y, t.z, t.w), nubis_slab_leave_unscattered(t.y), 0): a slab's
 *      weights of the far and the near face's diffuse light at view cosine t.x, vertical optical depth t.y;
 *   8: vec4(nubis_layer_reach(0..3)): the altitude each cloud layer's view march ends at;
 *   9: vec4(nubis_sun_at(t.xyz), 0): the sun's light arriving at the world point t.xyz. */
void main()
{
  vec4 t = texelFetch(probe_points, ivec2(gl_FragCoord.xy), 0);
  if (probe_mode.x > 8.5) {
    color = vec4(nubis_sun_at(t.xyz), 0.0);
    return;
  }
  if (probe_mode.x > 7.5) {
    color = vec4(nubis_layer_reach(0), nubis_layer_reach(1), nubis_layer_reach(2), nubis_layer_reach(3));
    return;
  }
  if (probe_mode.x > 6.5) {
    color = vec4(nubis_slab_sky_weights(t.x, t.y, t.z, t.w), nubis_slab_leave_unscattered(t.y), 0.0);
    return;
  }
  if (probe_mode.x > 5.5) {
    color = vec4(nubis_slab_diffusion(t.x, t.y, t.z, t.w, probe_mode.y), nubis_absorbing_decay(t.x, t.y), 0.0, 0.0);
    return;
  }
  if (probe_mode.x > 4.5) {
    color = vec4(nubis_slab_multiple_scattering(t.x, t.y, t.z), nubis_slab_scattering(t.x, t.y, t.z),
                 nubis_slab_exit_shape(t.x, t.z, t.w > 0.5), 0.0);
    return;
  }
  if (probe_mode.x > 3.5) {
    color = vec4(nubis_storm_glow(t.xyz, t.w), 0.0);
    return;
  }
  if (probe_mode.x > 2.5) {
    vec2 second;
    float weight;
    float unturned;
    vec2 moved = nubis_vortex(t.xy, second, weight, unturned);
    color = vec4(moved, second);
    return;
  }
  if (probe_mode.x > 1.5) {
    if (probe_mode.y > 1.5) {
      color = textureLod(noise_curl, t.xy, 0.0);
    }
    else if (probe_mode.y > 0.5) {
      color = textureLod(noise_hf, t.xyz, 0.0);
    }
    else {
      color = textureLod(noise_lf, t.xyz, 0.0);
    }
    return;
  }
  if (probe_mode.x > 0.5) {
    color = vec4(remap(t.x, t.y, t.z, t.w, probe_mode.y), 0.0, 0.0, 0.0);
    return;
  }
  NubisDensity d = nubis_density(t.xyz, probe_mode.y > 0.5, 0.0);
  color = vec4(d.fine, d.coarse, d.h, 0.0);
}
