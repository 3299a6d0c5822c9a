/* Cloud lighting. Requires nubis_common_lib.glsl and nubis_density_lib.glsl. */

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

/* The storms' light per unit scattering: the constant red glow at the storm's centre, and lightning
 * (SPEC 2.10.4, GDC22): an intra-cloud flash is the same glow at the flash's own position with its
 * animated intensity; a ground discharge adds the external flash that lights the underside around the
 * strike. */
vec3 nubis_storm_glow(vec3 p, float fine_density)
{
  vec3 glow = vec3(0.0);
#if NUBIS_STORMS
  int count = min(int(P.storm_info.x), NUBIS_MAX_STORMS);
  float thickness = P.layer.z - P.layer.y;
  const vec3 flash_colour = vec3(0.85, 0.9, 1.0);
  for (int i = 0; i < count; i++) {
    vec4 shape = P.storm_shape[i];
    if (shape.w <= 0.0) {
      continue;
    }
    float height = P.layer.y + P.storm_info.z * thickness;
    float intensity = P.storm_light[i].z;
    if (intensity > 0.0) {
      float e = nubis_glow_energy(p, vec3(shape.xy, height), shape.z, fine_density, thickness);
      glow += P.storm_glow[i].rgb * intensity * e * shape.w;
    }
    float flash = P.storm_glow[i].w;
    if (flash > 0.0) {
      vec4 where = P.storm_flash[i]; /* offset x, y from the centre; 1 for a ground discharge */
      vec3 at = vec3(shape.xy + where.xy, height);
      glow += flash_colour * flash * nubis_glow_energy(p, at, 0.6 * shape.z, fine_density, thickness) * shape.w;
      if (where.z > 0.5) {
        /* The external flash: highlights on the underside features near the strike. */
        float h = clamp01((nubis_altitude(p, P.layer.x) - P.layer.y) / thickness);
        float near = pow(clamp01(1.0 - distance(p.xy, at.xy) / (0.5 * shape.z)), 4.0);
        glow += flash_colour * flash * 0.05 * near * (1.0 - h) * (1.0 - h) * shape.w;
      }
    }
  }
#endif
  return glow;
}

/* GPU Pro 7: six offsets in [-1, 1]^3 that widen the light march into a cone (SPEC 2.8). */
const vec3 NUBIS_CONE_KERNEL[6] = vec3[6](vec3(0.38051305, 0.92453449, -0.02111345),
                                          vec3(-0.50625799, -0.03590792, -0.86163418),
                                          vec3(-0.32509218, -0.94557439, 0.01428793),
                                          vec3(0.09026238, -0.27376545, 0.95755165),
                                          vec3(0.28128598, 0.42443639, -0.86065785),
                                          vec3(-0.16852403, 0.14748697, 0.97460106));

/* Reference optical depth (without sigma): the full-detail density along `dir` until the ray leaves
 * the cloud shell (or the draw radius ends the clouds). */
float nubis_reference_depth(vec3 p, vec3 dir, int samples)
{
  float altitude = nubis_altitude(p, P.layer.x);
  vec2 top = nubis_ray_sphere(p, dir, P.layer.x, P.shell.y);
  vec2 bottom = nubis_ray_sphere(p, dir, P.layer.x, P.shell.x);
  float len = max(top.y, 0.0);
  if (altitude > P.shell.x && bottom.x <= bottom.y && bottom.x > 0.0) {
    len = min(len, bottom.x); /* heading down out of the layer's floor */
  }
  len = min(len, 2.0 * P.layer.w);
  /* Samples crowd near the point (t = len u^2): the nearby cloud decides most of the shadowing,
   * while a horizontal ray may cross tens of kilometres of layer. */
  float depth = 0.0;
  float n = float(samples);
  for (int i = 0; i < samples; i++) {
    float u = (float(i) + 0.5) / n;
    vec3 q = p + dir * (len * u * u);
    NubisDensity s = nubis_density(q, false, 0.0);
    depth += s.fine * nubis_extinction_factor(q, s.precipitation) * (2.0 * len * u / n);
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

/* Reference sky light: the world is a uniform sphere of radiance (as in the Cycles scene), so single
 * scattering of it is the radiance times the transmittance weighted by the phase function over all
 * directions. The phase is far from isotropic (the silver-lining lobe peaks ~45x above it), so the
 * directions are drawn from the two lobes in proportion to their weights (importance sampling,
 * stratified in the lobe's cosine), turned about the view ray by a per-pixel angle so neighbouring
 * pixels see different directions and supersampling averages them out. */
float nubis_reference_sky_visibility(vec3 p, vec3 view_dir)
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
  float spin = 6.2831853 * fract(nubis_pixel_hash(gl_FragCoord.xy + vec2(0.5, 17.5)) + 0.7548777 * P.options.z);
  float main_lobe = 0.0, silver_lobe = 0.0;
  for (int i = 0; i < count; i++) {
    bool in_silver = i < silver;
    int k = in_silver ? i : i - silver;
    int n = in_silver ? silver : count - silver;
    float g = in_silver ? P.phase.y : P.phase.x;
    float cos_t = nubis_henyey_greenstein_sample(g, (float(k) + 0.5) / float(n));
    float sin_t = sqrt(max(0.0, 1.0 - cos_t * cos_t));
    float phi = spin + float(i) * 2.39996323; /* the golden angle */
    vec3 dir = view_dir * cos_t + (side * cos(phi) + up * sin(phi)) * sin_t;
    float tau = nubis_reference_depth(p, dir, 16) * P.density.x + nubis_cirrus_optical_depth(p, dir);
    if (in_silver) {
      silver_lobe += exp(-tau) / float(n);
    }
    else {
      main_lobe += exp(-tau) / float(n);
    }
  }
  return mix(main_lobe, silver_lobe, P.phase.z);
}

/* Optical depth towards the sun. Mode 0: the real-time march of GPU Pro 7 / S15, five samples in a
 * widening cone plus one long-distance sample at three times the cone length, at the half-resolution
 * noise, switching to cheap samples once the view ray is 30 % opaque. Mode 1: a reference march of
 * many fine samples out of the cloud layer, for measuring the real-time one. */
float nubis_light_optical_depth(vec3 p, float view_alpha)
{
  vec3 sun = P.sun_dir.xyz;
  float step_len = P.march.z;
  float tau = 0.0;
  if (P.march.w < 0.5) {
    bool cheap = view_alpha > 0.3; /* S15: "2x faster", no visible change */
    for (int i = 0; i < 5; i++) {
      float t = step_len * (float(i) + 0.5);
      vec3 q = p + sun * t + NUBIS_CONE_KERNEL[i] * (step_len * float(i) * 0.5);
      NubisDensity s = nubis_density(q, cheap, 1.0);
      tau += (cheap ? s.coarse : s.fine) * nubis_extinction_factor(q, s.precipitation) * step_len;
    }
    /* The long sample catches shadows of distant clouds (GPU Pro 7 fig 4.36). It stands for the
     * stretch between the cone's end and itself, so it is weighted by that length. */
    vec3 far_point = p + sun * (step_len * 15.0);
    NubisDensity far_sample = nubis_density(far_point, true, 1.0);
    tau += far_sample.coarse * nubis_extinction_factor(far_point, far_sample.precipitation) * step_len * 10.0;
  }
  else {
    tau = nubis_reference_depth(p, sun, 48);
  }
  return tau * P.density.x;
}

/* Light scattered towards the eye per unit of scattering at a point inside the cloud. */
/* `extinction_factor` is nubis_extinction_factor at p: where rain or a storm absorbs, the albedo is
 * its inverse. */
vec3 nubis_in_scattering(vec3 p, vec3 view_dir, NubisDensity d, float view_alpha, float extinction_factor)
{
  float tau = nubis_light_optical_depth(p, view_alpha);
  /* High cirrus dims the sun on the clouds below it, as its baked slab does in Cycles. */
  tau += nubis_cirrus_optical_depth(p, P.sun_dir.xyz);
  float cos_angle = dot(view_dir, P.sun_dir.xyz);
  /* SPEC 2.9: NOT from the Guerrilla sources. Wrenninge's octaves (Oz, 2013) stand in for the light
   * that scatters more than once: each octave sees a thinner cloud and a flatter phase. Octave 1 alone
   * is plain single scattering (Beer-Lambert x phase). Octave i stands for light scattered once more
   * than octave i - 1, so it loses another factor of the albedo where the cloud absorbs: without it
   * the octaves kept rain cores and storms bright that Cycles' absorbing bounces make dark. */
  float direct_energy = 0.0;
  float a = 1.0, b = 1.0, c = 1.0;
  float albedo = 1.0 / max(extinction_factor, 1.0);
  int octaves = int(P.scatter.x);
  for (int i = 0; i < octaves; i++) {
    direct_energy += b * exp(-a * tau) * nubis_phase(cos_angle, c);
    a *= P.scatter.y;
    b *= P.scatter.z * albedo;
    c *= P.scatter.w;
  }
  /* SPEC 2.4 (GPU Pro 7 "Beer's powder", S15 view dependence): the in-scatter probability darkens
   * the edges facing the sun, visible only with the sun behind the viewer; GPU Pro 7's factor 2
   * restores the energy where it applies. */
  float powder_weight = P.scatter2.x * clamp01(0.5 - 0.5 * cos_angle);
  direct_energy *= mix(1.0, 2.0 * (1.0 - exp(-2.0 * tau)), powder_weight);
  vec3 direct = P.sun_rad.rgb * direct_energy;
  /* SPEC 2.7: GDC22's ambient probability from the coarse density, growing with height (S15); the
   * reference mode measures the sky's visibility instead. */
  float ambient_probability;
  if (P.march.w < 0.5) {
    ambient_probability = sqrt(1.0 - clamp01(d.coarse)) * mix(P.ambient.w, 1.0, d.h);
  }
  else {
    ambient_probability = nubis_reference_sky_visibility(p, view_dir);
  }
  ambient_probability *= nubis_storm_ambient(p, d.h);
  return direct + P.ambient.rgb * ambient_probability + nubis_storm_glow(p, d.fine);
}
