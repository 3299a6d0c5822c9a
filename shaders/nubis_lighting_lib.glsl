/* Cloud lighting. Requires nubis_common_lib.glsl and nubis_density_lib.glsl. */

/* GDC22's internal glow: the exponent of its powered linear distance to the light, and the factor of
 * its pseudo-attenuation by the local fine density (docs/sources.md#storm-glow). */
const float NUBIS_GLOW_FALLOFF = 12.0;
const float NUBIS_GLOW_DENSITY_ABSORPTION = 5.0;

/* Lightning (docs/sources.md#lightning-flashes): a flash lights this share of its storm's radius around
 * its position; a ground discharge's external flash reaches this share of the radius around the strike,
 * falls off with this power and adds this much energy at the cloud base. */
const float NUBIS_FLASH_REACH = 0.6;
const float NUBIS_EXTERNAL_FLASH_REACH = 0.5;
const float NUBIS_EXTERNAL_FLASH_FALLOFF = 4.0;
const float NUBIS_EXTERNAL_FLASH_STRENGTH = 0.05;

/* The reference march (docs/sources.md#reference-march): samples towards the sun, directions of the sky
 * light and samples along each, within llvmpipe's loop limit (docs/platform-notes.md#shader-loop-limit;
 * core/march.py counts the same numbers); no light path is followed beyond this many draw radii. */
const int NUBIS_REFERENCE_SUN_SAMPLES = 48;
const int NUBIS_REFERENCE_SKY_DIRECTIONS = 12;
const int NUBIS_REFERENCE_SKY_SAMPLES = 16;
/* ... and, for the full model's reference, samples up and down the point's column. */
const int NUBIS_REFERENCE_COLUMN_SAMPLES = 24;
/* ... and sideways, along each of the 8 horizontal directions the sky volume's second channel takes. */
const int NUBIS_REFERENCE_SIDE_SAMPLES = 4;
const float NUBIS_REFERENCE_REACH = 2.0;

/* Below this eccentricity a Henyey-Greenstein lobe is sampled as isotropic (its inverse distribution
 * divides by g). */
const float NUBIS_ISOTROPIC_G = 1e-3;
/* A view direction closer to vertical than this cosine builds its frame on the x axis instead of z. */
const float NUBIS_NEAR_VERTICAL = 0.9;
/* The sky directions' per-pixel turn: 2 pi times a hash, offset from the step jitter's hash, stepped by
 * Roberts' R2 constant (1 / the plastic number) per accumulation pass; successive directions are spread
 * by the golden angle (docs/sources.md#numerical-methods). */
const float NUBIS_TWO_PI = 6.2831853;
const vec2 NUBIS_SKY_HASH_OFFSET = vec2(0.5, 17.5);
const vec2 NUBIS_SHADOW_HASH_OFFSET = vec2(29.5, 3.5);
const vec2 NUBIS_STRATUM_HASH_OFFSET = vec2(7.5, 41.5);
const float NUBIS_R2_STEP = 0.7548777;
const float NUBIS_GOLDEN_ANGLE = 2.39996323;

/* Wrenninge et al.'s multiple-scattering octaves: at most this many (two vec4 of phases per ray). */
const int NUBIS_MAX_OCTAVES = 8;

/* An artist's VDB cloud lights its samples with its own octaves and sky light, these factors on the
 * scene's settings, fitted against converged Cycles on two VDB clouds (docs/vdb.md#light) and measured
 * on a family of seven (docs/vdb.md#a-family-of-clouds), where no other setting of them did better: the
 * octaves see 1.41 times the optical depth (Attenuation 0.355 -> 0.5) and keep 1.33 times the energy, at
 * most all of the last octave's (Contribution 0.753 -> 1), and the sky light is 0.885 of the scene's
 * (Ambient 1.30 -> 1.15). A lone, dense cloud's sunlit surface scatters more of the sun back than the
 * procedural layers' fit gives it, and less reaches its shadowed side and base. */
const float NUBIS_VDB_MS_ATTENUATION_SCALE = 1.41;
const float NUBIS_VDB_MS_CONTRIBUTION_SCALE = 1.33;
const float NUBIS_VDB_AMBIENT_SCALE = 0.885;

/* S15 and GPU Pro 7 switch the light march to cheap samples at 0.3; measured, 0.5 keeps 40 dB against
 * full samples where 0.3 gave 35.9 dB (docs/sources.md#cheap-light-samples). The cheap samples' uneroded
 * density overestimates the optical depth: at 0.5 the real-time light read 4-7 % darker than with full
 * samples, at 0.8 1-2 %, for 4 % more redraw time (docs/viewport.md#light-model). */
const float NUBIS_CHEAP_LIGHT_ALPHA = 0.8;
/* GPU Pro 7: light samples read the noise one mip level coarser than the view sample, at most the
 * coarsest level stored (docs/sources.md#light-mip-level). */
const float NUBIS_LIGHT_LOD_OFFSET = 1.0;
const float NUBIS_LIGHT_COARSEST_LOD = 2.0;

/* GPU Pro 7's Beer's powder 2 e^-d (1 - e^-2d): the factor that restores the energy, and the rate of the
 * in-scattering probability (docs/sources.md#powder). */
const float NUBIS_POWDER_GAIN = 2.0;
const float NUBIS_POWDER_RATE = 2.0;

/* The atmosphere's transmittance towards the sun from altitude `h` (metres) at the cosine `mu` of the sun's
 * zenith angle there: the table core/sky.py air_table fills (sun_air), at the coordinates its
 * air_table_coords gives; zero where the planet stands between the point and the sun (Earth's shadow).
 * P.sun_air holds the radii of the ground and of the atmosphere's top, and the horizon's distance from
 * the top. docs/sky.md#the-sun-each-cloud-sees. */
vec3 nubis_air_transmittance(float h, float mu)
{
  float ground = P.sun_air.y, top = P.sun_air.z, span = P.sun_air.w;
  float above = clamp(h, 0.0, top - ground);
  float r = ground + above;
  /* r^2 - R^2 and top^2 - r^2 as products: float32 keeps them where the squares' difference would not. */
  float rho2 = above * (r + ground), r2mu2 = r * r * mu * mu;
  if (mu < 0.0 && r2mu2 >= rho2) {
    return vec3(0.0);
  }
  float rho = sqrt(rho2);
  float d = max(sqrt(max(r2mu2 + (top - r) * (top + r), 0.0)) - r * mu, 0.0);
  float d_min = top - r, d_max = rho + span;
  float along = clamp((d - d_min) / max(d_max - d_min, 1e-3), 0.0, 1.0);
  return texture(sun_air, vec2(1.0 - sqrt(1.0 - along), rho / span)).rgb;
}

/* The sun's light arriving at `p`: above the atmosphere, through the air along its own path to the sun
 * (the altitude and the sun's angle over the planet's curve at p) when the sky has an atmosphere; the
 * lamp's colour everywhere when it has none (a World not made by Nubis, or the Sun Color setting off). */
vec3 nubis_sun_at(vec3 p)
{
  if (P.sun_air.x == 0.0) {
    return P.sun_radiance.rgb;
  }
  vec3 up = normalize(p + vec3(0.0, 0.0, P.layer_planet_radius));
  float h = nubis_altitude(p, P.layer_planet_radius);
  return P.sun_radiance.rgb * nubis_air_transmittance(h, dot(P.sun_dir.xyz, up));
}

/* The World's radiance towards `dir` (a distant environment): the equirectangular capture of the World
 * (blender/scene/sky.py), in the layout of Blender's Environment Texture (core/sky.py). */
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
  vec3 base = P.lighting_ambient_bottom * 0.5 * (P.ambient.rgb + P.ambient_below.rgb);
  return mix(base, P.ambient.rgb, h);
}

/* GDC22: normalised Henyey-Greenstein (GPU Pro 7's listing multiplies by pi; not used;
 * docs/sources.md#henyey-greenstein-normalisation). */
float nubis_henyey_greenstein(float cos_angle, float g)
{
  float g2 = g * g;
  float denom = 1.0 + g2 - 2.0 * g * cos_angle;
  return (1.0 - g2) / (4.0 * NUBIS_PI * denom * sqrt(denom));
}

/* GDC22 combines lobes of different eccentricity for an art-directed silver lining; two lobes mixed by
 * a weight (docs/sources.md#phase-lobes). `eccentricity_scale` < 1 flattens both lobes for the
 * multiple-scattering octaves. */
float nubis_phase(float cos_angle, float eccentricity_scale)
{
  return mix(nubis_henyey_greenstein(cos_angle, P.lighting_phase_g0 * eccentricity_scale),
             nubis_henyey_greenstein(cos_angle, P.lighting_phase_g1 * eccentricity_scale),
             P.lighting_phase_mix);
}

/* The mean cosine of the two lobes together: the asymmetry g the closed-form slab terms take. */
float nubis_phase_mean_cosine()
{
  return mix(P.lighting_phase_g0, P.lighting_phase_g1, P.lighting_phase_mix);
}

/* GPU Pro 7: raining clouds absorb more light (docs/sources.md#rain-and-storm-absorption). Modelled as
 * absorption added to the
 * scattering, so extinction grows by this factor and the albedo is its inverse; the view march, the
 * light march and the bake (an `absorption` grid for Cycles) all use it, so Cycles sees the same
 * dark rain cores. */
float nubis_rain_extinction(float precipitation)
{
  return mix(1.0, P.lighting_rain_absorption, clamp01(precipitation));
}

/* ---- superstorm lighting (GDC22) -------------------------------------------------------------------- */

/* GDC22: near a storm's centre the cloud counts as denser, so the storm reads darker and thicker (as
 * absorption, see nubis_extinction_factor). GDC22's printed min() never exceeds 1; we keep its
 * pow(., 0.5) falloff and scale towards the storm's darkening factor (docs/sources.md#storm-darkening). */
float nubis_storm_darkening(vec3 q)
{
  float scale = 1.0;
#if NUBIS_STORMS
  int count = min(int(P.storm_count), NUBIS_MAX_STORMS);
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

/* GDC22: a cylindrical field, fading with height, that blends the ambient to the storm's own (ground
 * bounce under a low, dark mesocyclone). GDC22's printed blend is <= 0; this is the described intent: 1
 * at the storm's foot and centre, 0 at its radius or top (docs/sources.md#storm-ambient). */
float nubis_storm_ambient(vec3 p, float h)
{
  float factor = 1.0;
#if NUBIS_STORMS
  int count = min(int(P.storm_count), NUBIS_MAX_STORMS);
  for (int i = 0; i < count; i++) {
    vec4 shape = P.storm_shape[i];
    float blend = clamp01(1.0 - distance(p.xy, shape.xy) / shape.z) * clamp01(1.0 - h) * shape.w;
    factor = mix(factor, P.storm_light[i].w, blend);
  }
#endif
  return factor;
}

/* GDC22: the internal glow without a second light march: a powered linear distance to the light, a
 * height gradient below it, and a pseudo-attenuation from the local fine density (its undefined terms
 * are chosen in docs/sources.md#storm-glow).
 * `centre` is the light, `radius` its reach. Returns the unitless energy factor. */
float nubis_glow_energy(vec3 p, vec3 centre, float radius, float fine_density, float thickness)
{
  float potential = pow(clamp01(1.0 - distance(p, centre) / radius), NUBIS_GLOW_FALLOFF);
  float below = clamp01((centre.z - nubis_altitude(p, P.layer_planet_radius) + thickness) / (2.0 * thickness));
  float pseudo_attenuation = 1.0 - clamp01(fine_density * NUBIS_GLOW_DENSITY_ABSORPTION);
  return potential * below * pseudo_attenuation;
}

/* Lightning (GDC22, after Uman's *Lightning*; docs/sources.md#lightning-flashes): an intra-cloud flash is the internal glow at the flash's own position
 * with its animated intensity; a ground discharge adds the external flash that lights the underside
 * around the strike. This returns each storm's flash energy at unit intensity, so the temporal viewport
 * can accumulate it as GDC22's flash mask and scale it by the intensity of the frame being shown. */
vec4 nubis_flash_energy(vec3 p, float fine_density)
{
  vec4 energy = vec4(0.0);
#if NUBIS_STORMS
  int count = min(int(P.storm_count), NUBIS_MAX_STORMS);
  float thickness = P.layer_top - P.layer_bottom;
  for (int i = 0; i < count; i++) {
    vec4 shape = P.storm_shape[i];
    if (shape.w <= 0.0) {
      continue;
    }
    float height = P.layer_bottom + P.storm_glow_height * thickness;
    vec4 where = P.storm_flash[i]; /* offset x, y from the centre; 1 for a ground discharge */
    vec3 at = vec3(shape.xy + where.xy, height);
    float e = nubis_glow_energy(p, at, NUBIS_FLASH_REACH * shape.z, fine_density, thickness);
    if (where.z > 0.5) {
      /* The external flash: highlights on the underside features near the strike. */
      float h = clamp01((nubis_altitude(p, P.layer_planet_radius) - P.layer_bottom) / thickness);
      float near = pow(clamp01(1.0 - distance(p.xy, at.xy) / (NUBIS_EXTERNAL_FLASH_REACH * shape.z)),
                       NUBIS_EXTERNAL_FLASH_FALLOFF);
      e += NUBIS_EXTERNAL_FLASH_STRENGTH * near * (1.0 - h) * (1.0 - h);
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
  int count = min(int(P.storm_count), NUBIS_MAX_STORMS);
  float thickness = P.layer_top - P.layer_bottom;
  for (int i = 0; i < count; i++) {
    vec4 shape = P.storm_shape[i];
    float intensity = P.storm_light[i].z;
    if (shape.w <= 0.0 || intensity <= 0.0) {
      continue;
    }
    float height = P.layer_bottom + P.storm_glow_height * thickness;
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

/* The reference light samples' offset within their strata for this pixel and accumulation pass (the
 * middle when the march is not jittered). */
float nubis_reference_jitter(vec2 pixel)
{
  if (P.jitter <= 0.5) {
    return 0.5;
  }
  return fract(nubis_pixel_hash(pixel + NUBIS_SHADOW_HASH_OFFSET) + NUBIS_R2_STEP * P.jitter_pass);
}

/* Reference optical depth (without sigma): the full-detail density along `dir` until the ray leaves
 * the cloud shell (or the draw radius ends the clouds), with rain's and storms' absorption; `plain`
 * returns the density alone, for the powder term. `jitter` in [0, 1) places the samples within their
 * strata: a fixed placement (0.5) would sample every shadow ray at the same distances, which misses or
 * doubles whole puffs consistently over a region of the image; jittered per pixel and per pass, the
 * supersampled, accumulated estimate converges to the integral (docs/sources.md#reference-march). */
float nubis_reference_depth(vec3 p, vec3 dir, int samples, float jitter, out float plain)
{
  float altitude = nubis_altitude(p, P.layer_planet_radius);
  vec2 top = nubis_ray_sphere(p, dir, P.layer_planet_radius, P.shell_top);
  vec2 bottom = nubis_ray_sphere(p, dir, P.layer_planet_radius, P.shell_bottom);
  float len = max(top.y, 0.0);
  if (altitude > P.shell_bottom && bottom.x <= bottom.y && bottom.x > 0.0) {
    len = min(len, bottom.x); /* heading down out of the layer's floor */
  }
  len = min(len, NUBIS_REFERENCE_REACH * P.layer_draw_radius);
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
    float u = (float(i) + jitter) / n;
    vec3 q = p + dir * (len * u * u);
    NubisDensity s = nubis_density(q, false, 0.0);
    float w = s.fine * (2.0 * len * u / n);
    plain += w;
    depth += w * nubis_extinction_factor(q, s.precipitation);
  }
  return depth;
}

/* Reference of the sky volume's sideways depth (sigma included; shaders/nubis_sky_side_comp.glsl): the
 * harmonic mean over 8 horizontal directions of the optical depth out to the sideways pass's reach,
 * each marched with samples crowding near the point. */
float nubis_reference_side_depth(vec3 p, float jitter)
{
  float inverse_sum = 0.0;
  float n = float(NUBIS_REFERENCE_SIDE_SAMPLES);
  for (int d = 0; d < 8; d++) {
    float angle = float(d) * (0.25 * NUBIS_PI);
    vec3 dir = vec3(cos(angle), sin(angle), 0.0);
    float depth = 0.0;
    for (int i = 0; i < NUBIS_REFERENCE_SIDE_SAMPLES; i++) {
      float u = (float(i) + jitter) / n;
      vec3 q = p + dir * (P.sky_side_reach * u * u);
      bool inside = P.clip_box.z < P.clip_box.x || all(greaterThanEqual(q.xy, P.clip_box.xy)) && all(lessThanEqual(q.xy, P.clip_box.zw));
      NubisDensity s = nubis_density(q, false, 0.0);
      depth += inside ? s.fine * nubis_extinction_factor(q, s.precipitation) * (2.0 * P.sky_side_reach * u / n) : 0.0;
    }
    inverse_sum += 1.0 / (depth * P.density_sigma + 1.0);
  }
  return 8.0 / inverse_sum;
}

/* The cosine of the angle from the forward direction for a uniform u in [0, 1), distributed as a
 * Henyey-Greenstein lobe of eccentricity g (inverse of its cumulative distribution). */
float nubis_henyey_greenstein_sample(float g, float u)
{
  if (abs(g) < NUBIS_ISOTROPIC_G) {
    return 1.0 - 2.0 * u;
  }
  float s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u);
  return clamp((1.0 + g * g - s * s) / (2.0 * g), -1.0, 1.0);
}

/* The directions the reference sky light samples around a view ray: drawn from the phase function's two
 * lobes in proportion to their weights (importance sampling, stratified in the lobe's cosine), turned
 * about the view ray by a per-pixel angle so neighbouring pixels see different directions and
 * supersampling averages them out. The phase is far from isotropic (the silver-lining lobe peaks ~45x
 * above it), which is why the directions follow it. */
struct NubisSkyDirections {
  vec3 view, side, up;
  float spin;
  float stratum; /* the directions' offset within their strata of the lobe's cosine */
  int silver;    /* the first `silver` directions are the silver-lining lobe's */
};

NubisSkyDirections nubis_sky_directions(vec3 view_dir, vec2 pixel)
{
  NubisSkyDirections s;
  const int count = NUBIS_REFERENCE_SKY_DIRECTIONS;
  s.silver = int(floor(float(count) * P.lighting_phase_mix + 0.5));
  s.silver = clamp(s.silver, P.lighting_phase_mix > 0.0 ? 1 : 0, P.lighting_phase_mix < 1.0 ? count - 1 : count);
  s.view = view_dir;
  s.side = normalize(abs(view_dir.z) < NUBIS_NEAR_VERTICAL ? cross(view_dir, vec3(0.0, 0.0, 1.0)) :
                                                  cross(view_dir, vec3(1.0, 0.0, 0.0)));
  s.up = cross(view_dir, s.side);
  float turn = fract(nubis_pixel_hash(pixel + NUBIS_SKY_HASH_OFFSET) + NUBIS_R2_STEP * P.jitter_pass);
  s.spin = NUBIS_TWO_PI * turn;
  s.stratum = P.jitter > 0.5 ?
                  fract(nubis_pixel_hash(pixel + NUBIS_STRATUM_HASH_OFFSET) + NUBIS_GOLDEN_RATIO_FRACT * P.jitter_pass) :
                  0.5;
  return s;
}

/* Direction i of the set; `weight` is its share of its lobe (1 / the lobe's count) times the lobe's
 * weight, so the weighted sum of the World's radiance over the set estimates its phase-weighted mean. */
vec3 nubis_sky_direction(NubisSkyDirections s, int i, out float weight)
{
  const int count = NUBIS_REFERENCE_SKY_DIRECTIONS;
  bool in_silver = i < s.silver;
  int k = in_silver ? i : i - s.silver;
  int n = in_silver ? s.silver : count - s.silver;
  float g = in_silver ? P.lighting_phase_g1 : P.lighting_phase_g0;
  weight = (in_silver ? P.lighting_phase_mix : 1.0 - P.lighting_phase_mix) / float(n);
  /* Jittered within its stratum: fixed strata would sample each lobe at the same few cone angles in
   * every pixel, a quadrature error no supersampling averages out. */
  float cos_t = nubis_henyey_greenstein_sample(g, (float(k) + s.stratum) / float(n));
  float sin_t = sqrt(max(0.0, 1.0 - cos_t * cos_t));
  float phi = s.spin + float(i) * NUBIS_GOLDEN_ANGLE;
  return s.view * cos_t + (s.side * cos(phi) + s.up * sin(phi)) * sin_t;
}

/* Reference sky light: single scattering of the World's radiance (as Cycles lights the baked volume
 * with the same World) is the radiance times the transmittance, weighted by the phase function over
 * all directions. */
vec3 nubis_reference_sky_light(vec3 p, vec3 view_dir, vec2 pixel)
{
  /* Budget: Mesa's llvmpipe stops a shader's loops after 65535 iterations in total (its loop
   * limiter), which silently cut long reference marches short; 12 x 16 + 48 per cloud sample keeps
   * a 128-step view ray under it. */
  NubisSkyDirections s = nubis_sky_directions(view_dir, pixel);
  float first_jitter = nubis_reference_jitter(pixel);
  vec3 light = vec3(0.0);
  for (int i = 0; i < NUBIS_REFERENCE_SKY_DIRECTIONS; i++) {
    float weight;
    vec3 dir = nubis_sky_direction(s, i, weight);
    float plain;
    /* Each direction's samples sit elsewhere in their strata (golden-ratio steps). */
    float jitter = fract(first_jitter + float(i) * NUBIS_GOLDEN_RATIO_FRACT);
    float tau = nubis_reference_depth(p, dir, NUBIS_REFERENCE_SKY_SAMPLES, jitter, plain) * P.density_sigma +
                nubis_cirrus_optical_depth(p, dir, 0.0);
    light += nubis_sky_radiance(dir) * (exp(-tau) * weight);
  }
  return P.lighting_ambient * light;
}

/* The share of a beam arriving at cosine `mu0` that a homogeneous slab of vertical optical depth `tau`,
 * scattering without absorbing, sends out as diffuse light: on the far side (`transmitted`) or back
 * towards the beam. The Eddington approximation (Shettle and Weinman 1970;
 * docs/sources.md#cirrus-lighting): the reflection (k + (1/2 - 3/4 mu0)(1 - e^(-tau/mu0))) / (1 + k),
 * k = 3/4 (1 - g) tau; the transmission is what neither is reflected nor passes unscattered. */
float nubis_slab_diffuse_share(float mu0, float tau, bool transmitted)
{
  float k = 0.75 * (1.0 - nubis_phase_mean_cosine()) * tau;
  float direct = exp(-tau / mu0);
  float reflected = (k + (0.5 - 0.75 * mu0) * (1.0 - direct)) / (1.0 + k);
  return transmitted ? max(1.0 - reflected - direct, 0.0) : reflected;
}

/* The rate per optical depth at which diffuse light dies out in cloud of single-scattering `albedo`:
 * diffusion theory's sqrt(3 (1 - albedo) (1 - g albedo)), which overestimates it where the cloud absorbs
 * much (by 28 % at albedo 1/2, 42 % at 1/3), bent so that it never exceeds 1, the rate of unscattered
 * light. For isotropic scattering this follows transport theory's exact rate (the root of
 * albedo / (2 kappa) ln((1 + kappa) / (1 - kappa)) = 1) within 6 % at every albedo. */
float nubis_absorbing_decay(float albedo, float g)
{
  if (albedo >= 1.0) {
    return 0.0; /* cloud that does not absorb, nearly all of it: no decay, and no powers to take */
  }
  float kd = sqrt(3.0 * (1.0 - albedo) * (1.0 - g * albedo));
  return kd / pow(1.0 + pow(kd, 6.0), 1.0 / 6.0);
}

/* Diffusion through a slab of cloud lit from one side (docs/viewport.md#light-model): the share of the
 * light entering that side found at a point with optical depth `near` between it and that side and
 * `far` beyond it. In transport depth (`rate` x optical depth) the diffusion equation phi'' = kappa^2 phi
 * holds across the slab, with the extrapolation length `edge` at both boundaries (phi -+ edge phi' = the
 * light coming in: 1 on the lit side, 0 on the far one). Cloud that scatters without absorbing
 * (`kappa` 0) gives the linear falloff (rate far + edge) / (rate (near + far) + 2 edge): one half in a
 * thin cloud. Where rain or a storm absorbs, the light dies out exponentially on its way in, `kappa`
 * per optical depth (nubis_absorbing_decay), from about 1 / (1 + kappa edge / rate) at a thick slab's
 * lit face. */
float nubis_slab_diffusion(float near, float far, float rate, float edge, float kappa)
{
  float u = rate * far, span = rate * (near + far);
  float k = kappa / max(rate, 1e-4);
  if (k * (span + 2.0 * edge) < 1e-3) {
    return (u + edge) / (span + 2.0 * edge);
  }
  /* [sinh(k u) + k edge cosh(k u)] / [(1 + (k edge)^2) sinh(k span) + 2 k edge cosh(k span)], written
   * with decaying exponentials only (u <= span). */
  float a = 1.0 + k * edge, b = 1.0 - k * edge;
  return exp(k * (u - span)) * (a - exp(-2.0 * k * u) * b) / (a * a - exp(-2.0 * k * span) * b * b);
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
  int octaves = min(int(P.lighting_ms_octaves), NUBIS_MAX_OCTAVES);
  for (int i = 0; i < octaves; i++) {
    float ph = nubis_phase(l.cos_angle, c);
    if (i < 4) {
      l.phase_lo[i] = ph;
    }
    else {
      l.phase_hi[i - 4] = ph;
    }
    c *= P.lighting_ms_eccentricity;
  }
  /* GPU Pro 7's "Beer's powder" with S15's view dependence: the in-scatter probability darkens
   * the edges facing the sun, visible only with the sun behind the viewer (docs/sources.md#powder). */
  l.powder_weight = P.lighting_powder * clamp01(0.5 - 0.5 * l.cos_angle);
  return l;
}

/* Where a point's unit coordinates in an optical-depth volume (core/lightvolume.py) are read: between
 * texel centres, the first and last texels sitting on the box's faces. The volumes are read by name,
 * not passed as sampler arguments, which not every shading language Blender translates to accepts. */
vec3 nubis_volume_coord(vec3 unit, vec3 size)
{
#if NUBIS_FETCH_STATS
  nubis_fetches_3d++;
#endif
  return (clamp(unit, 0.0, 1.0) * (size - 1.0) + 0.5) / size;
}

/* p's unit coordinates in the sun's volume: z = 0 on the face towards the sun. */
vec3 nubis_sun_volume_unit(vec3 p)
{
  return vec3(dot(P.sun_volume_x.xyz, p) + P.sun_volume_x.w,
              dot(P.sun_volume_y.xyz, p) + P.sun_volume_y.w,
              dot(P.sun_volume_z.xyz, p) + P.sun_volume_z.w);
}

/* The optical depth from p towards the sun until the cloud domain ends (sigma included). */
float nubis_sun_volume_depth(vec3 p)
{
  return texture(sun_volume, nubis_volume_coord(nubis_sun_volume_unit(p), vec3(textureSize(sun_volume, 0)))).r;
}

/* The optical depth of cloud above p and below it, to the domain's top and floor, and sideways to the
 * open sky (sigma included). */
vec3 nubis_sky_volume_depths(vec3 p)
{
  vec3 unit = vec3(dot(P.sky_volume_x.xyz, p) + P.sky_volume_x.w,
                   dot(P.sky_volume_y.xyz, p) + P.sky_volume_y.w,
                   dot(P.sky_volume_z.xyz, p) + P.sky_volume_z.w);
  vec3 size = vec3(textureSize(sky_volume, 0));
  vec2 here = texture(sky_volume, nubis_volume_coord(unit, size)).rg;
  float column = texture(sky_volume, nubis_volume_coord(vec3(unit.xy, 1.0), size)).r;
  return vec3(here.x, max(column - here.x, 0.0), here.y);
}

/* The optical depths the light of a point reads (sigma included; docs/viewport.md#light-model). */
struct NubisLightDepths {
  float sun;    /* towards the sun until the cloud domain ends, with rain's and storms' absorption */
  float powder; /* the density alone towards the sun near the point, for the powder term */
  float above;  /* the cloud above the point, to the domain's top */
  float below;  /* and below it, to the domain's floor */
  float side;   /* sideways to the open sky (the light volumes only; 0 otherwise) */
  bool column;  /* above and below are known: the light volumes, or the reference march */
};

/* The light's optical depths at p (docs/sources.md#light-march). Real time: towards the sun the march of
 * GPU Pro 7 / S15, samples in a widening cone, then the sun's optical-depth volume for the rest of the
 * layer (docs/viewport.md#light-volumes; without the volumes GPU Pro 7's one long-distance sample);
 * the sky's volume gives the cloud above and below. The cone's taps (offset from the point, and the length each stands for) are the same for
 * every sample of a frame, so Python computes them once (core/march.py) into P.light_taps;
 * P.march_light_samples counts them, the long one last. They read the noise one mip level coarser than
 * the view ray (GPU Pro 7) and switch to cheap samples once the view ray is mostly opaque (S15: "2x
 * faster"; NUBIS_CHEAP_LIGHT_ALPHA); the naive march of the benchmark keeps full samples. The reference permutation marches
 * many fine samples along each direction instead, for measuring the real-time depths. */
NubisLightDepths nubis_light_depths(vec3 p, float view_alpha, float lod, vec2 pixel)
{
  NubisLightDepths l;
  l.sun = 0.0;
  l.powder = 0.0;
  l.above = 0.0;
  l.below = 0.0;
  l.side = 0.0;
  l.column = false;
#if NUBIS_REFERENCE
  float jitter = nubis_reference_jitter(pixel);
  l.sun = nubis_reference_depth(p, P.sun_dir.xyz, NUBIS_REFERENCE_SUN_SAMPLES, jitter, l.powder) * P.density_sigma;
  l.powder *= P.density_sigma;
#  if NUBIS_REFERENCE == 2
  /* The real-time model's column depths, marched: each direction's samples elsewhere in their strata. */
  vec3 up = normalize(p + vec3(0.0, 0.0, P.layer_planet_radius));
  float plain;
  l.above = nubis_reference_depth(p, up, NUBIS_REFERENCE_COLUMN_SAMPLES,
                                  fract(jitter + NUBIS_GOLDEN_RATIO_FRACT), plain) * P.density_sigma;
  l.below = nubis_reference_depth(p, -up, NUBIS_REFERENCE_COLUMN_SAMPLES,
                                  fract(jitter + 2.0 * NUBIS_GOLDEN_RATIO_FRACT), plain) * P.density_sigma;
  l.side = nubis_reference_side_depth(p, fract(jitter + 3.0 * NUBIS_GOLDEN_RATIO_FRACT));
  l.column = true;
#  endif
#else
#  if NUBIS_NAIVE
  bool cheap = false;
#  else
  bool cheap = view_alpha > NUBIS_CHEAP_LIGHT_ALPHA;
#  endif
  float light_lod = min(lod + NUBIS_LIGHT_LOD_OFFSET, NUBIS_LIGHT_COARSEST_LOD);
  int taps = int(P.march_light_samples);
  for (int i = 0; i < taps - 1; i++) {
    vec4 tap = P.light_taps[i];
    vec3 q = p + tap.xyz;
    NubisDensity s = nubis_density(q, cheap, light_lod);
    float w = s.fine * tap.w;
    l.powder += w;
    l.sun += w * nubis_extinction_factor(q, s.precipitation);
  }
  l.sun *= P.density_sigma;
  l.powder *= P.density_sigma;
#  if NUBIS_LIGHT_VOLUME
  /* Beyond the cone, the sun's optical-depth volume: the whole layer towards the sun. The powder term
   * keeps the cone's depth alone: it is the in-scattering probability near the sample, and cloud
   * kilometres further towards the sun must not lighten a sun-facing edge. */
  l.sun += nubis_sun_volume_depth(p + P.sun_dir.xyz * P.light_cone_reach);
  vec3 sky = nubis_sky_volume_depths(p);
  l.above = sky.x;
  l.below = sky.y;
  l.side = sky.z;
  l.column = true;
#  else
  /* GPU Pro 7's long-distance sample at three times the cone's reach. */
  vec4 long_tap = P.light_taps[taps - 1];
  vec3 far_point = p + long_tap.xyz;
  NubisDensity far_sample = nubis_density(far_point, true, light_lod);
  float w = far_sample.coarse * long_tap.w * P.density_sigma;
  l.powder += w;
  l.sun += w * nubis_extinction_factor(far_point, far_sample.precipitation);
#  endif
#endif
  return l;
}

/* The clouds' optical depth towards the sun from a point of the cirrus layer (sigma included): a tower
 * that reaches through the layer shadows it, as it shadows the baked slab in Cycles. The light volume
 * where the real-time march has it (a sun ray that misses the box meets no cloud), the reference march
 * otherwise; without either, none. One fetch per pixel. */
float nubis_layer_sun_depth(vec3 p, vec2 pixel)
{
#if NUBIS_REFERENCE
  float plain;
  return nubis_reference_depth(p, P.sun_dir.xyz, NUBIS_REFERENCE_SUN_SAMPLES, nubis_reference_jitter(pixel), plain) *
         P.density_sigma;
#elif NUBIS_LIGHT_VOLUME
  vec3 unit = nubis_sun_volume_unit(p);
  if (any(lessThan(unit, vec3(0.0))) || any(greaterThan(unit.xy, vec2(1.0)))) {
    return 0.0;
  }
  return nubis_sun_volume_depth(p);
#else
  return 0.0;
#endif
}

/* Light scattered towards the eye per unit of scattering at a point inside the cloud, without the
 * lightning flashes (nubis_flash_energy). `extinction_factor` is nubis_extinction_factor at p: where
 * rain or a storm absorbs, the albedo is its inverse. The model is docs/viewport.md#light-model. */
vec3 nubis_in_scattering(
    vec3 p, vec3 view_dir, NubisDensity d, NubisRayLight ray, float view_alpha, float extinction_factor, float lod, vec2 pixel)
{
  NubisLightDepths l = nubis_light_depths(p, view_alpha, lod, pixel);
  float albedo = 1.0 / max(extinction_factor, 1.0);
  /* Light scatters many times only where there is cloud around to scatter it: what scatters more than
   * once grows with the optical depth of the point's column. */
  float buildup = l.column && P.lighting_ms_buildup > 0.0 ? 1.0 - exp(-P.lighting_ms_buildup * (l.above + l.below)) : 1.0;
  /* NOT from the Guerrilla sources: Wrenninge et al.'s octaves (Oz, 2013; docs/sources.md#multiple-scattering):
   * octave 1 is plain single scattering (Beer-Lambert x phase), each further one sees a thinner cloud
   * and a flatter phase and loses another factor of the albedo where the cloud absorbs (without it the
   * octaves kept rain cores and storms bright that Cycles' absorbing bounces make dark). */
  float direct_energy = 0.0;
  float a = 1.0, b = 1.0;
  float attenuation = P.lighting_ms_attenuation, contribution = P.lighting_ms_contribution;
#if NUBIS_VDB
  /* A VDB cloud's share of the sample takes its own octaves (NUBIS_VDB_MS_ATTENUATION_SCALE). */
  attenuation = mix(attenuation, min(attenuation * NUBIS_VDB_MS_ATTENUATION_SCALE, 1.0), d.vdb);
  contribution = mix(contribution, min(contribution * NUBIS_VDB_MS_CONTRIBUTION_SCALE, 1.0), d.vdb);
#endif
  int octaves = min(int(P.lighting_ms_octaves), NUBIS_MAX_OCTAVES);
  for (int i = 0; i < octaves; i++) {
    float phase = i < 4 ? ray.phase_lo[i] : ray.phase_hi[i - 4];
    direct_energy += b * exp(-a * l.sun) * phase;
    a *= attenuation;
    b *= contribution * albedo * (i == 0 ? buildup : 1.0);
  }
  /* GPU Pro 7's factor 2 restores the energy where the powder term applies. */
  direct_energy *= mix(1.0, NUBIS_POWDER_GAIN * (1.0 - exp(-NUBIS_POWDER_RATE * l.powder)), ray.powder_weight);
#if NUBIS_CIRRUS
  /* High cirrus dims the sun on the clouds below it by its own transmittance, as its baked slab does in
   * Cycles: a separate factor, so it neither hides the powder rim nor thins the octaves. */
  direct_energy *= exp(-nubis_cirrus_optical_depth(p, P.sun_dir.xyz, 0.0));
#endif
  vec3 sun_here = nubis_sun_at(p);
  vec3 direct = sun_here * direct_energy;
#if NUBIS_REFERENCE == 1
  /* Single scattering's reference: the sky's visibility direction by direction. */
  vec3 sky_light = nubis_reference_sky_light(p, view_dir, pixel);
#else
  float overhead = 1.0;
  vec3 from_above = P.ambient.rgb;
#  if NUBIS_CIRRUS
  /* ... and the light from above is what comes through the layer: the sky's, diffusing through it as
   * through the clouds (the light model's weights at its lower face, 2 e / (k tau + 2 e) of the sky's
   * and the rest the ground's, sent back), and the sun's that it scatters down
   * (nubis_slab_diffuse_share). The long tap's model takes the sky's share alone. */
  vec3 up = normalize(p + vec3(0.0, 0.0, P.layer_planet_radius));
  float tau_c = nubis_cirrus_optical_depth(p, up, 0.0);
  overhead = 2.0 * nubis_slab_diffusion(tau_c, 0.0, P.lighting_sky_occlusion, P.lighting_diffusion_edge, 0.0);
  float mu_sun = dot(P.sun_dir.xyz, up);
  from_above = mix(P.ambient_below.rgb, P.ambient.rgb, overhead);
  if (mu_sun > 0.0 && tau_c > 0.0) {
    float mu0 = max(mu_sun, NUBIS_MIN_SLANT_COS);
    from_above += sun_here * (mu0 * nubis_slab_diffuse_share(mu0, tau_c, true) / NUBIS_PI);
  }
#  endif
  vec3 sky_light;
  if (l.column) {
    /* The sky's light from above and the ground's from below, each diffusing through the slab of cloud
     * above and below the point (docs/viewport.md#light-model). This replaces GDC22's ambient
     * probability pow(1 - coarse, 0.5), a local guess at the same occlusion. S15's height gradient
     * stays as art direction. */
    float k = P.lighting_sky_occlusion, e = P.lighting_diffusion_edge;
    /* Diffused light has scattered on its way in: where rain or a storm absorbs, it dies out on the way
     * (the point's own albedo stands for the cloud's around it; docs/viewport.md#light-model). */
    float kappa = nubis_absorbing_decay(albedo, nubis_phase_mean_cosine());
    /* The sky's light also comes in sideways: through the cloud beside the point where that is thinner
     * than the cloud above it (a tower's flank), the shorter path dominating as in diffusion. */
    float above = l.above;
    if (P.lighting_side_light > 0.0 && l.side > 0.0) {
      above = l.above * l.side / (l.side + P.lighting_side_light * l.above);
      /* What comes in through the flank is what an upright surface receives, the horizon's light most
       * (core/sky.py flank_radiance): the flank's share of the light is its share of the inverse depths. */
      from_above = mix(from_above, P.ambient_flank.rgb, 1.0 - above / max(l.above, 1e-6));
    }
    sky_light = from_above * nubis_slab_diffusion(above, l.below, k, e, kappa) +
                P.ambient_below.rgb * nubis_slab_diffusion(l.below, l.above, k, e, kappa);
    sky_light *= mix(P.lighting_ambient_bottom, 1.0, d.h);
  }
  else {
    /* With the long tap: GDC22's ambient probability, growing with height (S15; docs/sources.md#ambient). */
    sky_light = nubis_ambient_light(d.h) * (sqrt(1.0 - clamp01(d.coarse)) * overhead);
  }
#  if NUBIS_VDB
  sky_light *= mix(1.0, NUBIS_VDB_AMBIENT_SCALE, d.vdb);
#  endif
#endif
  sky_light *= nubis_storm_ambient(p, d.h);
  return direct + sky_light + nubis_storm_steady_glow(p, d.fine);
}
