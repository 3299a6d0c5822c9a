/* Fills an optical-depth volume (core/lightvolume.py, docs/viewport.md#light-volumes): one invocation
 * per column of texels along the light's direction. It marches the column from the side the light
 * comes from and stores the optical depth reached at each depth slice, so texel (i, j, k) holds the
 * depth from its point towards the light until the cloud domain ends. The density is the full sample
 * at the finest noise level, with rain's and storms' absorption, as the reference march reads it: the
 * texels are hundreds of metres wide, but the coarsest level's blurred noise erodes less on average, and
 * its optical depths made the real-time light 3 % darker (docs/viewport.md#light-volumes). */
void main()
{
  ivec3 size = imageSize(volume_out);
  ivec2 column = ivec2(gl_GlobalInvocationID.xy);
  if (column.x >= size.x || column.y >= size.y) {
    return;
  }
  vec2 xy = vec2(column) / vec2(max(size.xy - 1, ivec2(1)));
  vec3 start = volume_origin.xyz + xy.x * volume_u.xyz + xy.y * volume_v.xyz;
  float slices = float(max(size.z - 1, 1));
  float dt = length(volume_w.xyz) / (slices * float(NUBIS_VOLUME_STEPS));
  vec3 step_dir = normalize(volume_w.xyz);
  float tau = 0.0;
  imageStore(volume_out, ivec3(column, 0), vec4(0.0));
  for (int k = 1; k < size.z; k++) {
    for (int i = 0; i < NUBIS_VOLUME_STEPS; i++) {
      float t = (float((k - 1) * NUBIS_VOLUME_STEPS + i) + 0.5) * dt;
      vec3 q = start + step_dir * t;
      NubisDensity d = nubis_density(q, false, 0.0);
      tau += d.fine * nubis_extinction_factor(q, d.precipitation) * dt;
    }
    imageStore(volume_out, ivec3(column, k), vec4(tau * P.density_sigma));
  }
}
