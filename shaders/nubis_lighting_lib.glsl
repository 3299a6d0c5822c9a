/* Cloud lighting. Requires nubis_common_lib.glsl and nubis_density_lib.glsl. */

/* The World's radiance towards `dir` (a distant environment): the equirectangular capture of the World
 * (blender/sky.py), in the layout of Blender's Environment Texture (core/sky.py). */
vec3 nubis_sky_radiance(vec3 dir)
{
  vec3 d = normalize(dir);
  vec2 uv = vec2(0.5 - atan(d.y, d.x) / (2.0 * NUBIS_PI), 0.5 + asin(clamp(d.z, -1.0, 1.0)) / NUBIS_PI);
  return texture(sky_env, uv).rgb;
}

/* The sky light of the real-time march at height fraction h in the layer: the World's irradiance from
 * above at the top; at the base S15's fraction of it, from sky and ground alike (the mean of the two
 * hemispheres). A World of one colour gives S15's gradient from the base fraction to 1 unchanged. */
vec3 nubis_ambient_light(float h)
{
  vec3 base = P.ambient.w * 0.5 * (P.ambient.rgb + P.ambient_below.rgb);
  return mix(base, P.ambient.rgb, h);
}

/* SPEC 2.3, GDC22: normalised Henyey-Greenstein (GPU Pro 7's listing multiplies by pi; not used). */
float nubis_henyey_greenstein(float cos_angle, float g)
{
  float g2 = g * g;
  float denom = 1.0 + g2 - 2.0 * g * cos_angle;
  return (1.0 - g2) / (4.0 * NUBIS_PI * denom * sqrt(denom));
}

/* SPEC 2.3: GDC22 combines lobes of different eccentricity for an art-directed silver lining.
 * `eccentricity_scale` < 1 flattens both lobes for the multiple-scattering octaves. */
float nubis_phase(float cos_angle, float eccentricity_scale)
{
  return mix(nubis_henyey_greenstein(cos_angle, P.phase.x * eccentricity_scale),
             nubis_henyey_greenstein(cos_angle, P.phase.y * eccentricity_scale),
             P.phase.z);
}

/* SPEC 2.5, GPU Pro 7: raining clouds absorb more light. Modelled as absorption added to the
 * scattering, so extinction grows by this factor and the albedo is its inverse; the view march, the
 * light march and the bake (an `absorption` grid for Cycles) all use it, so Cycles sees the same
 * dark rain cores. */
float nubis_rain_extinction(float precipitation)
{
  return mix(1.0, P.phase.w, clamp01(precipitation));
}

/* ---- superstorm lighting (SPEC 2.10, GDC22) -------------------------------------------------------- */

/* SPEC 2.10.1: near a storm's centre the cloud counts as denser, so the storm reads darker and
 * thicker (as absorption, see nubis_extinction_factor). GDC22's printed min() never exceeds 1 (SPEC 6 Q13); we keep its pow(., 0.5) falloff and
 * scale towards the storm's darkening factor. */
float nubis_storm_darkening(vec3 q)
{
  float scale = 1.0;
#if NUBIS_STORMS
  int count = min(int(P.storm_info.x), NUBIS_MAX_STORMS);
  for (int i = 0; i < count; i++) {
    vec4 shape = P.storm_shape[i];
    float proximity = clamp01(1.0 - distance(q.xy, shape.xy) / shape.z);
    scale += (P.storm_light[i].y - 1.0) * sqrt(proximity) * shape.w;
  }
#endif
  return scale;
}

/* Extinction over scattering at a point: rain's absorption times the storm's darkening. Both are
 * absorption, so the view march, the light march and the baked `absorption` grid agree. */
float nubis_extinction_factor(vec3 p, float precipitation)
{
  return nubis_rain_extinction(precipitation) * nubis_storm_darkening(p);
}

/* SPEC 2.10.2: a cylindrical field, fading with height, that blends the ambient to the storm's own
 * (ground bounce under a low, dark mesocyclone). GDC22's printed blend is <= 0 (SPEC 6 Q14); this is
 * the described intent: 1 at the storm's foot and centre, 0 at its radius or top. */
float nubis_storm_ambient(vec3 p, float h)
{
  float factor = 1.0;
#if NUBIS_STORMS
  int count = min(int(P.storm_info.x), NUBIS_MAX_STORMS);
  for (int i = 0; i < count; i++) {
    vec4 shape = P.storm_shape[i];
    float blend = clamp01(1.0 - distance(p.xy, shape.xy) / shape.z) * clamp01(1.0 - h) * shape.w;
    factor = mix(factor, P.storm_light[i].w, blend);
  }
#endif
  return factor;
}

/* SPEC 2.10.3: the internal glow without a second light march: a powered linear distance to the
 * light, a height gradient below it, and a pseudo-attenuation from the local fine density.
 * `centre` is the light, `radius` its reach. Returns the unitless energy factor. */
float nubis_glow_energy(vec3 p, vec3 centre, float radius, float fine_density, float thickness)
{
  float potential = pow(clamp01(1.0 - distance(p, centre) / radius), 12.0);
  float below = clamp01((centre.z - nubis_altitude(p, P.layer.x) + thickness) / (2.0 * thickness));
  float pseudo_attenuation = 1.0 - clamp01(fine_density * 5.0);
  return potential * below * pseudo_attenuation;
}

/* Lightning (GDC22, after Uman's *Lightning*): an intra-cloud flash is the internal glow at the flash's own position
 * with its animated intensity; a ground discharge adds the external flash that lights the underside
 * around the strike. This returns each storm's flash energy at unit intensity, so the temporal viewport
 * can accumulate it as GDC22's flash mask and scale it by the intensity of the frame being shown. */
vec4 nubis_flash_energy(vec3 p, float fine_density)
{
  vec4 energy = vec4(0.0);
#if NUBIS_STORMS
  int count = min(int(P.storm_info.x), NUBIS_MAX_STORMS);
  float thickness = P.layer.z - P.layer.y;
  for (int i = 0; i < count; i++) {
    vec4 shape = P.storm_shape[i];
    if (shape.w <= 0.0) {
      continue;
    }
    float height = P.layer.y + P.storm_info.z * thickness;
    vec4 where = P.storm_flash[i]; /* offset x, y from the centre; 1 for a ground discharge */
    vec3 at = vec3(shape.xy + where.xy, height);
    float e = nubis_glow_energy(p, at, 0.6 * shape.z, fine_density, thickness);
    if (where.z > 0.5) {
      /* The external flash: highlights on the underside features near the strike. */
      float h = clamp01((nubis_altitude(p, P.layer.x) - P.layer.y) / thickness);
      float near = pow(clamp01(1.0 - distance(p.xy, at.xy) / (0.5 * shape.z)), 4.0);
      e += 0.05 * near * (1.0 - h) * (1.0 - h);
    }
    energy[i] = e * shape.w;
  }
#endif
  return energy;
}

/* The flash intensities of this frame, one per storm. */
vec4 nubis_flash_intensities()
{
  return vec4(P.storm_glow[0].w, P.storm_glow[1].w, P.storm_glow[2].w, P.storm_glow[3].w);
}

/* The constant red glow at each storm's centre, per unit scattering (GDC22). */
vec3 nubis_storm_steady_glow(vec3 p, float fine_density)
{
  vec3 glow = vec3(0.0);
#if NUBIS_STORMS
  int count = min(int(P.storm_info.x), NUBIS_MAX_STORMS);
  float thickness = P.layer.z - P.layer.y;
  for (int i = 0; i < count; i++) {
    vec4 shape = P.storm_shape[i];
    float intensity = P.storm_light[i].z;
    if (shape.w <= 0.0 || intensity <= 0.0) {
      continue;
    }
    float height = P.layer.y + P.storm_info.z * thickness;
    float e = nubis_glow_energy(p, vec3(shape.xy, height), shape.z, fine_density, thickness);
    glow += P.storm_glow[i].rgb * intensity * e * shape.w;
  }
#endif
  return glow;
}

/* All of the storms' light per unit scattering: the steady glow and this frame's flashes. */
vec3 nubis_storm_glow(vec3 p, float fine_density)
{
  vec4 flashes = nubis_flash_energy(p, fine_density) * nubis_flash_intensities();
  return nubis_storm_steady_glow(p, fine_density) + NUBIS_FLASH_COLOUR * (flashes.x + flashes.y + flashes.z + flashes.w);
}

/* Reference optical depth (without sigma): the full-detail density along `dir` until the ray leaves
 * the cloud shell (or the draw radius ends the clouds), with rain's and storms' absorption; `plain`
 * returns the density alone, for the powder term. */
float nubis_reference_depth(vec3 p, vec3 dir, int samples, out float plain)
{
  float altitude = nubis_altitude(p, P.layer.x);
  vec2 top = nubis_ray_sphere(p, dir, P.layer.x, P.shell.y);
  vec2 bottom = nubis_ray_sphere(p, dir, P.layer.x, P.shell.x);
  float len = max(top.y, 0.0);
  if (altitude > P.shell.x && bottom.x <= bottom.y && bottom.x > 0.0) {
    len = min(len, bottom.x); /* heading down out of the layer's floor */
  }
  len = min(len, 2.0 * P.layer.w);
  /* A comparison keeps only the clouds inside the baked box: beyond its side there is nothing to
   * shadow, so the samples stay inside it (a horizontal ray would otherwise spread its 16 samples
   * over tens of kilometres, most of them outside, and miss the clouds that are there). */
  if (P.clip_box.z >= P.clip_box.x) {
    vec2 side = vec2(dir.x > 0.0 ? P.clip_box.z : P.clip_box.x, dir.y > 0.0 ? P.clip_box.w : P.clip_box.y);
    vec2 exit_t = (side - p.xy) / max(abs(dir.xy), vec2(1e-9)) * sign(dir.xy);
    exit_t = mix(vec2(1e30), max(exit_t, vec2(0.0)), greaterThan(abs(dir.xy), vec2(1e-9)));
    len = min(len, min(exit_t.x, exit_t.y));
  }
  /* Samples crowd near the point (t = len u^2): the nearby cloud decides most of the shadowing,
   * while a horizontal ray may cross tens of kilometres of layer. */
  float depth = 0.0;
  plain = 0.0;
  float n = float(samples);
  for (int i = 0; i < samples; i++) {
    float u = (float(i) + 0.5) / n;
    vec3 q = p + dir * (len * u * u);
    NubisDensity s = nubis_density(q, false, 0.0);
    float w = s.fine * (2.0 * len * u / n);
    plain += w;
    depth += w * nubis_extinction_factor(q, s.precipitation);
  }
  return depth;
}

/* The cosine of the angle from the forward direction for a uniform u in [0, 1), distributed as a
 * Henyey-Greenstein lobe of eccentricity g (inverse of its cumulative distribution). */
float nubis_henyey_greenstein_sample(float g, float u)
{
  if (abs(g) < 1e-3) {
    return 1.0 - 2.0 * u;
  }
  float s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u);
  return clamp((1.0 + g * g - s * s) / (2.0 * g), -1.0, 1.0);
}

/* Reference sky light: single scattering of the World's radiance (as Cycles lights the baked volume
 * with the same World) is the radiance times the transmittance, weighted by the phase function over
 * all directions. The phase is far from isotropic (the silver-lining lobe peaks ~45x above it), so the
 * directions are drawn from the two lobes in proportion to their weights (importance sampling,
 * stratified in the lobe's cosine), turned about the view ray by a per-pixel angle so neighbouring
 * pixels see different directions and supersampling averages them out. */
vec3 nubis_reference_sky_light(vec3 p, vec3 view_dir, vec2 pixel)
{
  /* Budget: Mesa's llvmpipe stops a shader's loops after 65535 iterations in total (its loop
   * limiter), which silently cut long reference marches short; 12 x 16 + 48 per cloud sample keeps
   * a 128-step view ray under it. */
  const int count = 12;
  int silver = int(floor(float(count) * P.phase.z + 0.5));
  silver = clamp(silver, P.phase.z > 0.0 ? 1 : 0, P.phase.z < 1.0 ? count - 1 : count);
  vec3 side = normalize(abs(view_dir.z) < 0.9 ? cross(view_dir, vec3(0.0, 0.0, 1.0)) :
                                                cross(view_dir, vec3(1.0, 0.0, 0.0)));
  vec3 up = cross(view_dir, side);
  float spin = 6.2831853 * fract(nubis_pixel_hash(pixel + vec2(0.5, 17.5)) + 0.7548777 * P.options.z);
  vec3 main_lobe = vec3(0.0), silver_lobe = vec3(0.0);
  for (int i = 0; i < count; i++) {
    bool in_silver = i < silver;
    int k = in_silver ? i : i - silver;
    int n = in_silver ? silver : count - silver;
    float g = in_silver ? P.phase.y : P.phase.x;
    float cos_t = nubis_henyey_greenstein_sample(g, (float(k) + 0.5) / float(n));
    float sin_t = sqrt(max(0.0, 1.0 - cos_t * cos_t));
    float phi = spin + float(i) * 2.39996323; /* the golden angle */
    vec3 dir = view_dir * cos_t + (side * cos(phi) + up * sin(phi)) * sin_t;
    float plain;
    float tau = nubis_reference_depth(p, dir, 16, plain) * P.density.x + nubis_cirrus_optical_depth(p, dir, 0.0);
    /* The phase sampling makes the estimate the mean of the World's radiance times the transmittance. */
    vec3 seen = nubis_sky_radiance(dir) * (exp(-tau) / float(n));
    if (in_silver) {
      silver_lobe += seen;
    }
    else {
      main_lobe += seen;
    }
  }
  return P.ambient_below.w * mix(main_lobe, silver_lobe, P.phase.z);
}

/* What the light of one view ray shares along its length (for a sun light they are constant along
 * the ray, so they are computed once per pixel rather than at every sample): the cosine to the sun,
 * the phase of each multiple-scattering octave (up to 8) and the powder weight. */
struct NubisRayLight {
  float cos_angle;
  vec4 phase_lo; /* octaves 1-4 */
  vec4 phase_hi; /* octaves 5-8 */
  float powder_weight;
};

NubisRayLight nubis_ray_light(vec3 view_dir)
{
  NubisRayLight l;
  l.cos_angle = dot(view_dir, P.sun_dir.xyz);
  l.phase_lo = vec4(0.0);
  l.phase_hi = vec4(0.0);
  float c = 1.0;
  int octaves = min(int(P.scatter.x), 8);
  for (int i = 0; i < octaves; i++) {
    float ph = nubis_phase(l.cos_angle, c);
    if (i < 4) {
      l.phase_lo[i] = ph;
    }
    else {
      l.phase_hi[i - 4] = ph;
    }
    c *= P.scatter.w;
  }
  /* GPU Pro 7's "Beer's powder" with S15's view dependence: the in-scatter probability darkens
   * the edges facing the sun, visible only with the sun behind the viewer. */
  l.powder_weight = P.scatter2.x * clamp01(0.5 - 0.5 * l.cos_angle);
  return l;
}

/* Optical depth towards the sun. Real time: the march of GPU Pro 7 / S15, samples in a widening cone
 * plus one long-distance sample (GPU Pro 7 fig 4.36) at the coarse density. The taps (offset from the
 * point, and the length each stands for) are the same for every sample of a frame, so Python computes
 * them once (core/march.py) into P.light_taps; P.march.w counts them, the long one last. Samples
 * read the noise one mip level coarser than the view ray (GPU Pro 7) and switch to cheap samples
 * once the view ray is half opaque (S15: "2x faster"); the naive march of the benchmark keeps full
 * samples. The reference permutation marches many fine samples out of the
 * layer instead, for measuring the real-time one. */
float nubis_light_optical_depth(vec3 p, float view_alpha, float lod, out float powder_depth)
{
  float tau = 0.0;
  powder_depth = 0.0;
#if NUBIS_REFERENCE
  tau = nubis_reference_depth(p, P.sun_dir.xyz, 48, powder_depth);
#else
#  if NUBIS_NAIVE
  bool cheap = false;
#  else
  /* GPU Pro 7 and S15 switch at 0.3 with "almost no visual difference"; measured against full light
   * samples on the default sky that was 35.9 dB PSNR, 0.5 keeps 40 dB (docs/viewport.md). */
  bool cheap = view_alpha > 0.5;
#  endif
  float light_lod = min(lod + 1.0, 2.0);
  int taps = int(P.march.w);
  for (int i = 0; i < taps - 1; i++) {
    vec4 tap = P.light_taps[i];
    vec3 q = p + tap.xyz;
    NubisDensity s = nubis_density(q, cheap, light_lod);
    float w = (cheap ? s.coarse : s.fine) * tap.w;
    powder_depth += w;
    tau += w * nubis_extinction_factor(q, s.precipitation);
  }
  vec4 long_tap = P.light_taps[taps - 1];
  vec3 far_point = p + long_tap.xyz;
  NubisDensity far_sample = nubis_density(far_point, true, light_lod);
  float w = far_sample.coarse * long_tap.w;
  powder_depth += w;
  tau += w * nubis_extinction_factor(far_point, far_sample.precipitation);
#endif
  powder_depth *= P.density.x;
  return tau * P.density.x;
}

/* Light scattered towards the eye per unit of scattering at a point inside the cloud, without the
 * lightning flashes (nubis_flash_energy). `extinction_factor` is nubis_extinction_factor at p: where
 * rain or a storm absorbs, the albedo is its inverse. */
vec3 nubis_in_scattering(
    vec3 p, vec3 view_dir, NubisDensity d, NubisRayLight ray, float view_alpha, float extinction_factor, float lod, vec2 pixel)
{
  /* The octaves and the powder term see the cloud's own depth towards the sun (GPU Pro 7, GDC22),
   * the powder the density alone: rain's and storms' absorption darken the light, not thin the
   * dark sun-facing rim. */
  float powder_depth;
  float tau = nubis_light_optical_depth(p, view_alpha, lod, powder_depth);
  /* SPEC 2.9: NOT from the Guerrilla sources. Wrenninge's octaves (Oz, 2013) stand in for the light
   * that scatters more than once: each octave sees a thinner cloud and a flatter phase. Octave 1 alone
   * is plain single scattering (Beer-Lambert x phase). Octave i stands for light scattered once more
   * than octave i - 1, so it loses another factor of the albedo where the cloud absorbs: without it
   * the octaves kept rain cores and storms bright that Cycles' absorbing bounces make dark. */
  float direct_energy = 0.0;
  float a = 1.0, b = 1.0;
  float albedo = 1.0 / max(extinction_factor, 1.0);
  int octaves = min(int(P.scatter.x), 8);
  for (int i = 0; i < octaves; i++) {
    float phase = i < 4 ? ray.phase_lo[i] : ray.phase_hi[i - 4];
    direct_energy += b * exp(-a * tau) * phase;
    a *= P.scatter.y;
    b *= P.scatter.z * albedo;
  }
  /* GPU Pro 7's factor 2 restores the energy where the powder term applies. */
  direct_energy *= mix(1.0, 2.0 * (1.0 - exp(-2.0 * powder_depth)), ray.powder_weight);
#if NUBIS_CIRRUS
  /* High cirrus dims the sun on the clouds below it by its own transmittance, as its baked slab does in
   * Cycles: a separate factor, so it neither hides the powder rim nor thins the octaves. */
  direct_energy *= exp(-nubis_cirrus_optical_depth(p, P.sun_dir.xyz, 0.0));
#endif
  vec3 direct = P.sun_rad.rgb * direct_energy;
  /* SPEC 2.7: GDC22's ambient probability from the coarse density, growing with height (S15); the
   * reference permutation measures the sky's visibility instead. */
#if NUBIS_REFERENCE
  vec3 sky_light = nubis_reference_sky_light(p, view_dir, pixel);
#else
  float ambient_probability = sqrt(1.0 - clamp01(d.coarse));
#  if NUBIS_CIRRUS
  /* ... and the sky light by its transmittance overhead. */
  ambient_probability *= exp(-nubis_cirrus_optical_depth(p, normalize(p + vec3(0.0, 0.0, P.layer.x)), 0.0));
#  endif
  vec3 sky_light = nubis_ambient_light(d.h) * ambient_probability;
#endif
  sky_light *= nubis_storm_ambient(p, d.h);
  return direct + sky_light + nubis_storm_steady_glow(p, d.fine);
}
