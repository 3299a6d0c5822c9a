/* The view-ray march: premultiplied scene-linear radiance and alpha (GDC22's colour and alpha, GPU Pro
 * 7's spherical shell and step counts; docs/sources.md#output-colour), shared by the raymarch and motion
 * stages. Requires the cloud libraries. */

/* Two slants closer than this count as equal in the cirrus's single scattering (its formula divides by
 * their difference). */
const float NUBIS_EQUAL_SLANTS = 1e-3;

/* The view ray's mip level never passes the coarsest base-shape level stored (noise_lf_mip2). */
const float NUBIS_COARSEST_LOD = 2.0;

/* The march's loop bound: far above any step count, only a guard for the compiler. */
const int NUBIS_MAX_ITERATIONS = 4096;
/* The mip dither is the step jitter scrambled by this factor. */
const float NUBIS_DITHER_SCRAMBLE = 7.0;
/* GPU Pro 7: back to the cheap search after six empty fine samples in a row (docs/sources.md#coarse-to-fine). */
const int NUBIS_EMPTY_FINE_SAMPLES = 6;
/* S15 stops at alpha 1: the march stops once this little light gets through (docs/sources.md#early-exit). */
const float NUBIS_OPAQUE_TRANSMITTANCE = 0.005;
/* A ray whose horizontal direction is shorter than this (squared) is vertical: it never leaves the draw
 * radius sideways. */
const float NUBIS_VERTICAL_RAY = 1e-12;
/* A layer's segment takes at least this share of the step count, however little of it its clouds reach. */
const int NUBIS_LEAST_STEP_SHARE = 4;
/* Metres of margin above the highest altitude a layer's clouds reach (nubis_layer_reach). */
const float NUBIS_REACH_MARGIN = 1.0;
/* A split farther than any ray reaches: the whole ray is the near part. */
const float NUBIS_NO_SPLIT = 3.0e38;

/* The single scattering of a thin homogeneous slab of vertical optical depth tau towards the eye, per
 * unit of incoming radiance and phase: with slant factors m = 1 / |cos(zenith)| for the view ray (mu_v,
 * the cosine of its direction to the zenith) and the light (mu_l, the cosine of the direction towards
 * it), light that passes through the slab towards the eye gives
 * m_v / (m_v - m_l) (e^(-tau m_l) - e^(-tau m_v)), light scattered back to the side it came from
 * m_v / (m_v + m_l) (1 - e^(-tau (m_v + m_l))) (docs/sources.md#cirrus-lighting). */
float nubis_slab_scattering(float mu_v, float mu_l, float tau)
{
  float m_v = 1.0 / max(abs(mu_v), NUBIS_MIN_SLANT_COS);
  float m_l = 1.0 / max(abs(mu_l), NUBIS_MIN_SLANT_COS);
  if ((mu_v > 0.0) == (mu_l > 0.0)) {
    float dm = m_v - m_l;
    return abs(dm) < NUBIS_EQUAL_SLANTS ? m_v * tau * exp(-tau * m_v) :
                                          m_v / dm * (exp(-tau * m_l) - exp(-tau * m_v));
  }
  return m_v / (m_v + m_l) * (1.0 - exp(-tau * (m_v + m_l)));
}

/* p = (1 - e^(-2 tau)) / (2 tau): the chance that light scattered in a slab of vertical optical depth
 * `tau` leaves it unscattered (its mean over the depth and the directions, in the two-stream sense). */
float nubis_slab_leave_unscattered(float tau)
{
  return tau < 1e-3 ? 1.0 - tau : (1.0 - exp(-2.0 * tau)) / (2.0 * tau);
}

/* Radiance per unit of the sun's irradiance that a homogeneous slab of vertical optical depth `tau`,
 * scattering without absorbing, sends towards a viewer at cosine `mu_v` after more than one scattering,
 * the sun at cosine `mu_l` (nubis_cirrus; docs/sources.md#cirrus-lighting). The Eddington approximation
 * gives the slab's diffuse reflection and transmission (Shettle and Weinman 1970); of the diffuse light
 * on the viewer's side, the share beyond single scattering (which nubis_slab_scattering gives exactly)
 * is (1 - p), p the chance that light scattered in the slab leaves it unscattered
 * (nubis_slab_leave_unscattered): second order in a thin layer, all of it in a thick one. As if the
 * light left evenly in all directions; nubis_cirrus gives it its angular shape (nubis_slab_exit_shape). */
float nubis_slab_multiple_scattering(float mu_v, float mu_l, float tau)
{
  if (mu_l <= 0.0 || tau <= 0.0) {
    return 0.0;
  }
  float mu0 = max(mu_l, NUBIS_MIN_SLANT_COS);
  float diffuse = nubis_slab_diffuse_share(mu0, tau, mu_v > 0.0);
  return mu0 * diffuse * (1.0 - nubis_slab_leave_unscattered(tau)) / NUBIS_PI;
}

/* The sky's light from above and the ground's from below, diffusing through a homogeneous slab of
 * vertical optical depth `tau` scattering without absorbing, as it reaches a viewer at cosine `mu_v`:
 * the clouds' light model (nubis_slab_diffusion with kappa = 0, `rate` and `edge` its Sky Occlusion and
 * Slab Edge) gives the diffuse light at depth x below the top face the weight (rate (tau - x) + edge) /
 * (rate tau + 2 edge) from above, and the layer between that depth and the viewer lets e^(-m y) of it
 * through (m the view ray's slant factor, y the depth below x). Integrated along the ray in closed form,
 * with a = 1 - e^(-m tau) (the layer's opacity) and b = (a - m tau e^(-m tau)) / m:
 * x: the weight of the light from the face away from the viewer, (rate b + edge a) / (rate tau + 2 edge);
 * y: from the viewer's own face, (rate (tau a - b) + edge a) / (rate tau + 2 edge).
 * Thin, each is half the opacity; thick, the far face's light fades as 1 / tau and the near face's is
 * all sent back. */
vec2 nubis_slab_sky_weights(float mu_v, float tau, float rate, float edge)
{
  float m = 1.0 / max(abs(mu_v), NUBIS_MIN_SLANT_COS);
  float mt = m * tau;
  float a = 1.0 - exp(-mt);
  float b = mt < 1e-3 ? 0.5 * m * tau * tau : (a - mt * exp(-mt)) / m;
  float span = rate * tau + 2.0 * edge;
  return vec2(rate * b + edge * a, rate * (tau * a - b) + edge * a) / span;
}

/* How diffuse light that crosses a slab of vertical optical depth `tau` leaves it towards a viewer at
 * cosine `mu_v`, relative to leaving evenly in all directions (which has the same flux): the light
 * model's linear profile of the diffuse light through the slab (nubis_slab_sky_weights), lit from the face
 * away from the viewer (`far`) or from the viewer's own. A thin layer seen at a grazing angle shows more
 * of its light (a longer path through it), a thick one lit from the far face less (the light near the
 * viewer's face is what is left of it). The flux over the hemisphere by 4-point Gauss-Legendre. */
float nubis_slab_exit_shape(float mu_v, float tau, bool far)
{
  float rate = P.lighting_sky_occlusion, edge = P.lighting_diffusion_edge;
  /* The face's weight over the hemisphere: the four nodes written out (no indexed constant arrays). */
  vec2 w0 = nubis_slab_sky_weights(0.0694318, tau, rate, edge);
  vec2 w1 = nubis_slab_sky_weights(0.3300095, tau, rate, edge);
  vec2 w2 = nubis_slab_sky_weights(0.6699905, tau, rate, edge);
  vec2 w3 = nubis_slab_sky_weights(0.9305682, tau, rate, edge);
  vec4 face = far ? vec4(w0.x, w1.x, w2.x, w3.x) : vec4(w0.y, w1.y, w2.y, w3.y);
  float flux = dot(face, vec4(0.0694318, 0.3300095, 0.6699905, 0.9305682) *
                             vec4(0.1739274, 0.3260726, 0.3260726, 0.1739274));
  vec2 here = nubis_slab_sky_weights(mu_v, tau, rate, edge);
  return flux > 0.0 ? (far ? here.x : here.y) / (2.0 * flux) : 1.0;
}

/* GPU Pro 7, S15: the cirrus layer, sampled once where the ray crosses its sphere
 * (docs/sources.md#cirrus-layer, docs/sources.md#cirrus-lighting), lit as the thin homogeneous slab
 * Cycles renders from the bake (nubis_slab_scattering). The sun's single scattering is exact, the World's
 * is taken in the phase-sampled directions of the reference sky light; beyond single scattering
 * (not in single scattering's reference permutation) the sun's and the World's diffuse light through
 * the slab are added. Premultiplied radiance, alpha. */
vec4 nubis_cirrus(vec3 origin, vec3 dir, vec2 pixel)
{
  float altitude = nubis_altitude(origin, P.layer_planet_radius);
  vec2 ground = nubis_ray_sphere(origin, dir, P.layer_planet_radius, 0.0);
  vec2 hit = nubis_ray_sphere(origin, dir, P.layer_planet_radius, P.cirrus_altitude);
  float t = altitude < P.cirrus_altitude ? hit.y : hit.x;
  bool hits_ground = ground.x <= ground.y && ground.y > 0.0 && ground.x < t;
  if (hits_ground && altitude >= 0.0) {
    return vec4(0.0);
  }
  float tau_view = nubis_cirrus_optical_depth(origin, dir, -1.0);
  if (tau_view <= 0.0) {
    return vec4(0.0);
  }
  vec3 up = normalize(origin + dir * t + vec3(0.0, 0.0, P.layer_planet_radius));
  float mu_v = dot(dir, up);
  float tau = tau_view * max(abs(mu_v), NUBIS_MIN_SLANT_COS);
  float alpha = 1.0 - exp(-tau_view);
  float mu_sun = dot(P.sun_dir.xyz, up);
  vec3 sun = nubis_sun_at(origin + dir * t) * exp(-nubis_layer_sun_depth(origin + dir * t, pixel));
  vec3 light = sun * nubis_phase(dot(dir, P.sun_dir.xyz), 1.0) * nubis_slab_scattering(mu_v, mu_sun, tau);
  /* The World's light scattered once, direction by direction (once per pixel, so the real-time view
   * affords the reference's directions): grazing views of thin cirrus see mostly the bright horizon
   * behind it through the forward lobe. */
  NubisSkyDirections s = nubis_sky_directions(dir, pixel);
  vec3 sky = vec3(0.0);
  for (int i = 0; i < NUBIS_REFERENCE_SKY_DIRECTIONS; i++) {
    float weight;
    vec3 l = nubis_sky_direction(s, i, weight);
    sky += nubis_sky_radiance(l) * (nubis_slab_scattering(mu_v, dot(l, up), tau) * weight);
  }
  light += P.lighting_ambient * sky;
#if NUBIS_REFERENCE != 1
  /* Beyond single scattering, the sky's and the ground's light diffuse through the layer as through the
   * clouds, the share (1 - p) that scatters again: a thick anvil seen from below sends back the ground's
   * light and lets little of the sky's through. */
  vec2 w = nubis_slab_sky_weights(mu_v, tau, P.lighting_sky_occlusion, P.lighting_diffusion_edge) *
           (1.0 - nubis_slab_leave_unscattered(tau));
  bool below = mu_v > 0.0; /* the viewer looks up at the layer */
  light += P.ambient.rgb * (below ? w.x : w.y) + P.ambient_below.rgb * (below ? w.y : w.x);
  /* The sun's light that scatters more than once in the layer: thin cirrus hardly, a thick anvil mostly
   * (a converged path tracer lights its underside white; docs/sources.md#cirrus-lighting). */
  light += sun * (nubis_slab_multiple_scattering(mu_v, mu_sun, tau) *
                  nubis_slab_exit_shape(mu_v, tau, (mu_v > 0.0) == (mu_sun > 0.0)));
#endif
  return vec4(light, alpha);
}

/* The clouds and the cirrus layer together, in the order the camera sees them (GPU Pro 7 and S15 sample
 * the high layer at the end of the march, behind the volume, as seen from the ground): from above
 * the cirrus altitude the layer is in front of the clouds below it, the storm's anvil cirrus too. */
vec4 nubis_with_cirrus(vec4 clouds, vec3 origin, vec3 dir, vec2 pixel, out float behind)
{
  vec4 cirrus = nubis_cirrus(origin, dir, pixel);
  /* `behind`: what the layer lets through of the clouds' own light (their flashes too). */
  if (nubis_altitude(origin, P.layer_planet_radius) > P.cirrus_altitude) {
    behind = 1.0 - cirrus.a;
    return cirrus + behind * clouds;
  }
  behind = 1.0;
  return clouds + (1.0 - clouds.a) * cirrus;
}

/* The mip level of the noise for a view sample at distance t: the pixel's footprint there (P.pixel_angle
 * metres per metre of distance, P.pixel_size for orthographic views) in texels of the base-shape noise,
 * plus the quality's base level (GDC22: PS4 reads MIP 1, PS5 MIP 0). The fractional part is dithered
 * per pixel, so neighbouring levels blend as the passes accumulate. */
/* The level is one late (NUBIS_LOD_BIAS, nubis_density_lib.glsl; docs/sources.md#noise-mip-levels).
 * `lf_period` is the base-shape period of the cloud layer the sample is in. */
float nubis_view_lod(float t, float dither, float lf_period)
{
  float footprint = P.pixel_angle * t + P.pixel_size;
  float level = log2(max(footprint * float(NUBIS_LF_SIZE - 1) / lf_period, 1.0)) - NUBIS_LOD_BIAS + P.march_mip;
  return min(floor(level + dither), NUBIS_COARSEST_LOD);
}

#if NUBIS_VDB
/* The view ray's steps with VDB clouds on it: the march's own steps before and after the clouds' boxes,
 * and steps of about a voxel (P.vdb_step) through them, at most the march's own count (P.march_steps_max)
 * and within the loop limit (P.max_view_steps). */
struct NubisSteps {
  float t0, tv0, tv1;
  float dta, dtv, dtb;
  int na, nv, nb;
};

NubisSteps nubis_vdb_steps(vec3 origin, vec3 dir, float t0, float t1, int steps, float dt)
{
  NubisSteps s;
  s.t0 = t0;
  s.tv0 = t1;
  s.tv1 = t1;
  s.na = steps;
  s.nv = 0;
  s.nb = 0;
  s.dta = dt;
  s.dtv = dt;
  s.dtb = dt;
  vec2 span = nubis_vdb_span(origin, dir);
  float a = clamp(span.x, t0, t1), b = clamp(span.y, t0, t1);
  if (b <= a) {
    return s;
  }
  s.tv0 = a;
  s.tv1 = b;
  s.na = a > t0 ? max(1, int(ceil((a - t0) / dt))) : 0;
  s.nb = t1 > b ? max(1, int(ceil((t1 - b) / dt))) : 0;
  /* At most the march's own step count through the boxes: a VDB the size of the sky (a bake of the whole
   * view) is marched like the field's clouds, not at every voxel. */
  int room = max(1, min(int(P.max_view_steps) - s.na - s.nb, int(P.march_steps_max)));
  s.nv = clamp(int(ceil((b - a) / P.vdb_step)), 1, room);
  s.dta = s.na > 0 ? (a - t0) / float(s.na) : dt;
  s.dtv = (b - a) / float(s.nv);
  s.dtb = s.nb > 0 ? (t1 - b) / float(s.nb) : dt;
  return s;
}

/* Step i's distance along the ray (at its jittered offset) and its length. */
float nubis_step_t(NubisSteps s, int i, float jitter, out float dt)
{
  if (i < s.na) {
    dt = s.dta;
    return s.t0 + (float(i) + jitter) * s.dta;
  }
  if (i < s.na + s.nv) {
    dt = s.dtv;
    return s.tv0 + (float(i - s.na) + jitter) * s.dtv;
  }
  dt = s.dtb;
  return s.tv1 + (float(i - s.na - s.nv) + jitter) * s.dtb;
}
#endif

/* The view-ray march (GPU Pro 7, S15, Hillaire 2016; docs/sources.md#integration): premultiplied radiance and alpha. `cloud_depth` returns the
 * transmittance-weighted distance of what the ray saw (GDC22's cloud distance), 0 where it
 * saw nothing; `flash_mask` each storm's lightning at unit intensity, integrated like the radiance
 * (GDC22's flash mask): the radiance leaves the flashes out, and callers add
 * NUBIS_FLASH_COLOUR * dot(flash_mask, nubis_flash_intensities()) when they show a frame.
 *
 * Coarse to fine (GPU Pro 7, S15, GDC22): through empty sky the march takes cheap samples (the base
 * shape only, one 3D fetch) two steps apart; the first non-zero one steps back one step (S15: "always
 * take a step backward") and fine samples follow on the same grid the naive march uses; six empty
 * fine samples in a row (GPU Pro 7) return to the cheap search. Erosion only removes density, so an
 * empty cheap sample is an empty fine one: the saving costs only slivers thinner than one step. The
 * NUBIS_NAIVE permutation takes the fine sample at every step, for the benchmark. */
/* The two parts of a march split at the distance `split` along the ray (F12's depth composition,
 * docs/sky.md#objects-in-the-clouds): the clouds in front of what the scene holds there, and those behind
 * it, each premultiplied and each with its own flash mask. The step that straddles `split` is divided
 * at it, so the parts compose exactly into the whole: near + (1 - near.a) * far. */
struct NubisParts {
  vec4 near, far;
  vec4 flash_near, flash_far;
  float cloud_depth; /* of the whole ray, as nubis_march gives it */
};

/* Premultiplied light and alpha of one part from its sums, faded into the atmosphere by its own depth. */
vec4 nubis_faded_part(vec3 dir, vec3 radiance, float transmittance, float depth_sum, inout vec4 flash_mask)
{
  float alpha = 1.0 - transmittance;
  /* S15: clouds fade into the atmosphere with the depth of what the ray saw, into the sky's own color
   * along this ray (the World's radiance behind them), not a flat fog color
   * (docs/sources.md#aerial-perspective). */
  if (P.lighting_fade_distance > 0.0 && alpha > 0.0) {
    float fade = exp(-(depth_sum / alpha) / P.lighting_fade_distance);
    radiance = mix(nubis_sky_radiance(dir) * alpha, radiance, fade);
    flash_mask *= fade;
  }
  return vec4(radiance, alpha);
}

/* The segment [t0, t1] of a ray within the spherical shell between altitudes lo and hi (GPU Pro 7,
 * GDC22), cut at the draw radius; false when the ray has none. Rays that meet the ground before the
 * shell see none of it (docs/sources.md#pixel-culling). */
bool nubis_shell_segment(vec3 origin, vec3 dir, float lo, float hi, out float t0, out float t1)
{
  float R = P.layer_planet_radius;
  t0 = 0.0;
  t1 = 0.0;
  vec2 ground = nubis_ray_sphere(origin, dir, R, 0.0);
  vec2 inner = nubis_ray_sphere(origin, dir, R, lo);
  vec2 outer = nubis_ray_sphere(origin, dir, R, hi);
  if (outer.x > outer.y || outer.y <= 0.0) {
    return false;
  }
  float altitude = nubis_altitude(origin, R);
  if (altitude < lo) {
    if (ground.x <= ground.y && ground.y > 0.0 && altitude >= 0.0) {
      return false;
    }
    t0 = inner.y;
    t1 = outer.y;
  }
  else if (altitude <= hi) {
    t0 = 0.0;
    t1 = (inner.x <= inner.y && inner.x > 0.0) ? inner.x : outer.y;
  }
  else {
    t0 = outer.x;
    t1 = (inner.x <= inner.y && inner.x > 0.0) ? inner.x : outer.y;
  }
  t0 = max(t0, 0.0);
  /* Nothing exists beyond the draw radius (the density fades it), so stop the ray there. */
  vec2 dxy = dir.xy;
  vec2 oxy = origin.xy - vec2(P.draw_center_x, P.draw_center_y);
  float a = dot(dxy, dxy);
  if (a > NUBIS_VERTICAL_RAY) {
    float b = dot(oxy, dxy);
    float c = dot(oxy, oxy) - P.layer_draw_radius * P.layer_draw_radius;
    float disc = b * b - a * c;
    if (disc < 0.0) {
      return false;
    }
    t1 = min(t1, (-b + sqrt(disc)) / a);
  }
  return t1 > t0;
}

/* The parts of a ray the view march takes, nearest first: each (t0, t1, the span's thickness, its layer's
 * base-shape period for the noise's mip level), in a struct rather than an `out` array, which not every
 * backend's shader translation takes:
 * each cloud layer's on its own, so the air between layers costs no steps (docs/layers.md). With VDB
 * clouds, which may stand anywhere, one segment through the whole shell. Returns how many. */
struct NubisSegments {
  vec4 part[NUBIS_MAX_CLOUD_LAYERS];
  int count;
  float thickest; /* the thickest drawn layer's thickness, whose steps set the sky's step length */
};

/* The highest altitude layer i's clouds can reach, for the view march (docs/layers.md#step-length): the
 * vertical profile is zero above its top ramp's end, which rises with the top type, between each column's
 * min and max height (nubis_height_fraction); the field's greatest top type, min height and max height
 * (P.cloud_layer_reach) bound it for every column. Above it every sample is empty. A storm's anvil hangs
 * under the extent's top: with storms, the extent. */
float nubis_layer_reach(int i)
{
#if NUBIS_STORMS
  return nubis_layer_extent_top(i);
#else
  vec4 r = nubis_layer_reach_channels(i);
  float e = nubis_top_ramp(r.x).y;
  float bottom = nubis_layer_bottom(i);
  float top = bottom + (nubis_layer_top(i) - bottom) * max(r.y, mix(r.y, r.z, e)) + NUBIS_REACH_MARGIN;
  return clamp(top, nubis_layer_extent_bottom(i) + NUBIS_REACH_MARGIN, nubis_layer_extent_top(i));
#endif
}

NubisSegments nubis_march_segments(vec3 origin, vec3 dir)
{
  NubisSegments segments;
  segments.count = 0;
  segments.thickest = 1.0;
  float t0, t1;
  for (int k = 0; k < NUBIS_MAX_CLOUD_LAYERS; k++) {
    segments.part[k] = vec4(0.0);
  }
#if NUBIS_VDB
  if (nubis_shell_segment(origin, dir, P.shell_bottom, P.shell_top, t0, t1)) {
    segments.part[0] = vec4(t0, t1, P.shell_top - P.shell_bottom, P.noise_lf_period);
    segments.count = 1;
  }
  segments.thickest = P.shell_top - P.shell_bottom;
#else
  for (int i = 0; i < NUBIS_MAX_CLOUD_LAYERS; i++) {
    if (i >= int(P.cloud_layer_count)) {
      break;
    }
    float extent_bottom = nubis_layer_extent_bottom(i);
    segments.thickest = max(segments.thickest, nubis_layer_extent_top(i) - extent_bottom);
    float reach = nubis_layer_reach(i);
    if (!nubis_shell_segment(origin, dir, extent_bottom, reach, t0, t1)) {
      continue;
    }
    /* Insertion by the segment's start: layers share no altitude, so their segments do not overlap. */
    int at = segments.count;
    while (at > 0 && segments.part[at - 1].x > t0) {
      segments.part[at] = segments.part[at - 1];
      at--;
    }
    segments.part[at] = vec4(t0, t1, reach - extent_bottom, nubis_layer_noise(i).x);
    segments.count++;
  }
#endif
  return segments;
}

NubisParts nubis_march_parts(vec3 origin, vec3 dir, vec2 pixel, float split, float stop)
{
  NubisParts parts;
  parts.near = vec4(0.0);
  parts.far = vec4(0.0);
  parts.flash_near = vec4(0.0);
  parts.flash_far = vec4(0.0);
  parts.cloud_depth = 0.0;
  NubisSegments segments = nubis_march_segments(origin, dir);
  int segment_count = segments.count;
  if (segment_count == 0) {
    return parts;
  }

  /* Per-pixel start offset, hiding step banding as fine grain; each accumulation pass (options.z)
   * shifts it by the golden ratio so N passes cover the step evenly. */
  float jitter = P.jitter > 0.5 ? fract(nubis_pixel_hash(pixel) + NUBIS_GOLDEN_RATIO_FRACT * P.jitter_pass) : 0.5;

  /* A second per-pixel value for the mip dither, independent of the step jitter. */
  float dither = P.jitter > 0.5 ? fract(jitter * NUBIS_DITHER_SCRAMBLE + 0.5) : 0.5;
  NubisRayLight ray = nubis_ray_light(dir);

  /* The sums of the part in front of `split` (index 0) and behind it (1); the far part's
   * transmittance starts at 1 where the near part ends. */
  vec3 radiance[2] = vec3[2](vec3(0.0), vec3(0.0));
  float part_t[2] = float[2](1.0, 1.0);
  float depth_sum[2] = float[2](0.0, 0.0);
  vec4 flashes[2] = vec4[2](vec4(0.0), vec4(0.0));
  float transmittance = 1.0;
  for (int segment = 0; segment < NUBIS_MAX_CLOUD_LAYERS; segment++) {
    if (segment >= segment_count || transmittance < NUBIS_OPAQUE_TRANSMITTANCE) {
      break;
    }
    float t0 = segments.part[segment].x;
    /* A ray that only needs what lies in front of a surface (the viewport over the scene's objects) ends
     * there, on the steps the whole ray takes, so its near part is F12's to the sample; the segments come
     * nearest first. */
    if (t0 >= stop) {
      break;
    }
    float t1 = segments.part[segment].y;
    /* GPU Pro 7, S15: 64 steps looking up, up to 128 towards the horizon (P.march.xy), by the segment's
     * length against its layer's thickness (docs/sources.md#view-steps). */
    float seg = t1 - t0;
    float thickness = segments.part[segment].z;
    float k = clamp01((seg - thickness) / max(P.layer_draw_radius - thickness, 1.0));
    int steps = int(mix(P.march_steps_min, P.march_steps_max, k));
    /* One step length for the whole sky, the thickest layer's (docs/layers.md#step-length): a layer takes
     * steps in proportion to the span of it its clouds can reach, so a thin layer, or one whose clouds
     * stop halfway up it, costs that much less; never under a quarter of the count. */
    steps = max(int(ceil(float(steps) * thickness / segments.thickest)), steps / NUBIS_LEAST_STEP_SHARE);
    /* Within the platform's loop limit (core/march.py, max_steps, in P.max_view_steps, shared by the
     * ray's segments; docs/platform-notes.md#shader-loop-limit): longer steps, never a ray cut short. */
    steps = min(steps, int(P.max_view_steps) / segment_count);
    float dt = seg / float(steps);
#if NUBIS_VDB
    NubisSteps plan = nubis_vdb_steps(origin, dir, t0, t1, steps, dt);
    steps = plan.na + plan.nv + plan.nb;
#endif
    int i = 0;                    /* the next step to sample */
    int uncovered = 0;            /* the first step that no empty cheap sample has cleared */
    bool fine = NUBIS_NAIVE != 0; /* taking fine samples (true) or searching with cheap ones */
    int empty_fine = 0;
    for (int iteration = 0; iteration < NUBIS_MAX_ITERATIONS; iteration++) {
      if (i >= steps) {
        break;
      }
#if NUBIS_VDB
      float step_dt;
      float t = nubis_step_t(plan, i, jitter, step_dt);
#else
      float step_dt = dt;
      float t = t0 + (float(i) + jitter) * dt;
#endif
      if (t - 0.5 * step_dt >= stop) {
        break;
      }
      vec3 p = origin + dir * t;
      float lod = nubis_view_lod(t, dither, segments.part[segment].w);
#if NUBIS_FETCH_STATS
      nubis_view_samples++;
#endif
#if !NUBIS_NAIVE
      if (!fine) {
        NubisDensity c = nubis_density(p, true, lod);
        if (c.coarse <= 0.0) {
          uncovered = i + 1;
          i += NUBIS_COARSE_STRIDE;
          continue;
        }
        fine = true;
        empty_fine = 0;
        i = max(i - NUBIS_COARSE_STRIDE + 1, uncovered);
        continue;
      }
#endif
      NubisDensity d = nubis_density(p, false, lod);
      i++;
      /* GPU Pro 7: no light march where there is no cloud. */
      if (d.fine <= 0.0) {
#if !NUBIS_NAIVE
        empty_fine++;
        if (empty_fine >= NUBIS_EMPTY_FINE_SAMPLES) {
          fine = false;
          uncovered = i;
        }
#endif
        continue;
      }
      empty_fine = 0;
      float absorb = nubis_extinction_factor(p, d.precipitation);
      float sigma = d.fine * P.density_sigma * absorb;
      vec3 s = nubis_in_scattering(p, dir, d, ray, 1.0 - transmittance, absorb, lod, pixel);
#if NUBIS_STORMS
      vec4 flash_energy = nubis_flash_energy(p, d.fine);
#endif
      /* The step covers t -+ dt/2: the share of it in front of `split` goes to the near part. */
      float near_share = clamp((split - (t - 0.5 * step_dt)) / step_dt, 0.0, 1.0);
      for (int k = 0; k < 2; k++) {
        float length_k = step_dt * (k == 0 ? near_share : 1.0 - near_share);
        if (length_k <= 0.0) {
          continue;
        }
        float step_t = exp(-sigma * length_k);
        /* Energy-conserving step (Hillaire 2016): the exact integral of constant in-scattering over
         * the step, instead of a Riemann sum that brightens with larger steps; the albedo is 1 but
         * where rain or a storm absorbs. */
        float weight = part_t[k] * ((1.0 - step_t) / absorb);
        radiance[k] += s * weight;
#if NUBIS_STORMS
        flashes[k] += flash_energy * weight;
#endif
        depth_sum[k] += t * part_t[k] * (1.0 - step_t);
        part_t[k] *= step_t;
      }
      transmittance = part_t[0] * part_t[1];
      /* S15: stop once the ray is practically opaque. */
      if (transmittance < NUBIS_OPAQUE_TRANSMITTANCE) {
        break;
      }
    }
  }
  float alpha = 1.0 - transmittance;
  float whole_depth = depth_sum[0] + part_t[0] * depth_sum[1];
  parts.cloud_depth = alpha > 0.0 ? whole_depth / alpha : 0.0;
  parts.near = nubis_faded_part(dir, radiance[0], part_t[0], depth_sum[0], flashes[0]);
  parts.far = nubis_faded_part(dir, radiance[1], part_t[1], depth_sum[1], flashes[1]);
  parts.flash_near = flashes[0];
  parts.flash_far = flashes[1];
  return parts;
}

#if NUBIS_CIRRUS
/* Whether the cirrus layer lies in front of a surface `split` along the ray: the eye or the surface is
 * above its altitude. */
bool nubis_cirrus_in_front(vec3 origin, vec3 dir, float split)
{
  float R = P.layer_planet_radius;
  return nubis_altitude(origin, R) > P.cirrus_altitude || nubis_altitude(origin + dir * split, R) > P.cirrus_altitude;
}
#endif

/* The clouds in front of a surface `split` along the ray, and nothing behind it (the viewport over the scene's
 * objects, as F12's near part; docs/viewport.md#clouds-in-front-of-the-scene): the march ends at the surface.
 * The cirrus layer is in front when the eye or the surface is above its altitude. */
vec4 nubis_march_in_front(vec3 origin, vec3 dir, vec2 pixel, float split, out float cloud_depth, out vec4 flash_mask)
{
  NubisParts parts = nubis_march_parts(origin, dir, pixel, split, split);
  cloud_depth = parts.cloud_depth;
  flash_mask = parts.flash_near;
  vec4 near = parts.near;
#if NUBIS_CIRRUS
  if (nubis_cirrus_in_front(origin, dir, split)) {
    float behind;
    near = nubis_with_cirrus(near, origin, dir, pixel, behind);
    flash_mask *= behind;
  }
#endif
  return near;
}

/* The whole view ray (no split): what the viewport, the panorama and the offline stages march. */
vec4 nubis_march(vec3 origin, vec3 dir, vec2 pixel, out float cloud_depth, out vec4 flash_mask)
{
  NubisParts parts = nubis_march_parts(origin, dir, pixel, NUBIS_NO_SPLIT, NUBIS_NO_SPLIT);
  cloud_depth = parts.cloud_depth;
  flash_mask = parts.flash_near;
  return parts.near;
}

/* One ray as the full-resolution stages show it (the render, the panorama): the march, this frame's
 * lightning flashes, and the cirrus layer in the order the camera sees it. */
vec4 nubis_shade_ray(vec3 origin, vec3 dir, vec2 pixel)
{
  float cloud_depth;
  vec4 flash_mask;
  vec4 clouds = nubis_march(origin, dir, pixel, cloud_depth, flash_mask);
  clouds.rgb += NUBIS_FLASH_COLOUR * dot(flash_mask, nubis_flash_intensities());
#if NUBIS_CIRRUS
  float behind;
  clouds = nubis_with_cirrus(clouds, origin, dir, pixel, behind);
#endif
  return clouds;
}

/* One ray of F12's camera view split at `split`, the scene's first surface along it (`split` is
 * NUBIS_NO_SPLIT where the ray meets none): the near part and, in `far`, what lies behind the surface,
 * each with its flashes. The cirrus layer goes with the part on its side of the surface: in front when
 * the eye or the surface is above its altitude, behind otherwise. */
vec4 nubis_shade_ray_parts(vec3 origin, vec3 dir, vec2 pixel, float split, out vec4 far)
{
  NubisParts parts = nubis_march_parts(origin, dir, pixel, split, NUBIS_NO_SPLIT);
  vec4 near = parts.near;
  far = parts.far;
  near.rgb += NUBIS_FLASH_COLOUR * dot(parts.flash_near, nubis_flash_intensities());
  far.rgb += NUBIS_FLASH_COLOUR * dot(parts.flash_far, nubis_flash_intensities());
#if NUBIS_CIRRUS
  float behind;
  if (split >= NUBIS_NO_SPLIT || nubis_cirrus_in_front(origin, dir, split)) {
    near = nubis_with_cirrus(near, origin, dir, pixel, behind);
  }
  else {
    far = nubis_with_cirrus(far, origin, dir, pixel, behind);
  }
#endif
  return near;
}
