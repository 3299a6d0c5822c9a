/* The cloud density: the one function the viewport, the headless render and the VDB bake all call.
 * Requires: nubis_common_lib.glsl, the NubisParams block `P`, and the samplers
 * field_a (coverage, precipitation, top type, bottom type) and field_b (storm coverage, min height,
 * max height, density multiplier), array textures with one slice per cloud layer (docs/layers.md),
 * field_c (cirrus coverage, cirrus type), the noise volumes with their
 * mip levels as separate textures (noise_lf, noise_lf_mip1, noise_lf_mip2, noise_hf, noise_hf_mip1: Python
 * uploads no mip chain), noise_curl, and noise_cirrus, whose mip chain is packed into one atlas. */

#if NUBIS_FETCH_STATS
/* Benchmark permutation only: 3D texture fetches of this fragment (docs/viewport.md). */
int nubis_fetches_3d = 0;
int nubis_density_calls = 0;
int nubis_view_samples = 0;
#  define NUBIS_COUNT_3D(n) nubis_fetches_3d += (n)
#else
#  define NUBIS_COUNT_3D(n)
#endif

/* GPU Pro 7: the weights of the pre-built Worley fBm (low_freq_FBM, high_freq_FBM). */
const vec3 NUBIS_FBM_WEIGHTS = vec3(0.625, 0.25, 0.125);

/* The vertical profile's trapezoids (docs/sources.md#vertical-profile): the height fractions over which
 * the top ramp falls from 1 to 0 for stratus (type 0), stratocumulus (0.5) and cumulus (1, GPU Pro 7's
 * type scale), and where the bottom ramp reaches 1 for bottom type 0 (a crisp flat base) and 1 (relaxed,
 * GDC22). */
const vec2 NUBIS_PROFILE_TOP_STRATUS = vec2(0.10, 0.20);
const vec2 NUBIS_PROFILE_TOP_STRATOCUMULUS = vec2(0.40, 0.60);
const vec2 NUBIS_PROFILE_TOP_CUMULUS = vec2(0.70, 1.00);
const float NUBIS_PROFILE_BASE_CRISP = 0.05;
const float NUBIS_PROFILE_BASE_RELAXED = 0.35;

/* The phase skew of successive vortex rings, in radians: an irrational step, so no two rings line up
 * (docs/sources.md#vortex-rings). */
const float NUBIS_VORTEX_RING_SKEW = 1.913;

/* The anvil (GDC22's flipped profile; docs/sources.md#anvil): its band under the shell's top, as a
 * share of the span from the layer base to that top; the cloud type of its flipped profile; its
 * coverage relative to the storm coverage; how much further inside a storm the noise leans downwind
 * (times the cloud-top offset, growing with height); the range of profile difference over which it
 * takes over from the column; and the height fraction its detail is shaped as (billows, not wisps). */
const float NUBIS_ANVIL_BAND = 0.22;
const float NUBIS_ANVIL_TYPE = 0.3;
const float NUBIS_ANVIL_COVERAGE = 0.85;
const float NUBIS_ANVIL_LEAN = 4.0;
const float NUBIS_ANVIL_TAKEOVER = 0.1;
const float NUBIS_ANVIL_DETAIL_HEIGHT = 0.9;

/* GPU Pro 7 turns the eroding Worley from wisps to billows over the lowest tenth of the layer,
 * saturate(h * 10); a rising bottom type slows that to the lowest half, so ragged undersides keep their
 * wisps (GDC22; docs/sources.md#wispy-and-billowy-detail). */
const float NUBIS_BILLOW_RATE = 10.0;
const float NUBIS_BILLOW_RATE_RAGGED = 2.0;

/* The draft quality's per-position hashes (the common sine one-liner; the constants only scatter):
 * one jitters the ring boundary, the other picks turned or unturned detail
 * (docs/sources.md#jittered-ring-boundary). */
const vec2 NUBIS_RING_HASH_DIR = vec2(12.9898, 78.233);
const float NUBIS_RING_HASH_SCALE = 43758.5453;
const vec2 NUBIS_TURN_HASH_DIR = vec2(39.3468, 11.135);
const float NUBIS_TURN_HASH_SCALE = 24634.6345;

/* A grazing ray's slant through a thin layer is capped at 1 / this cosine (docs/sources.md#cirrus-lighting). */
const float NUBIS_MIN_SLANT_COS = 0.05;

/* NubisLayer (declared with the uniform block), its accessors nubis_layer_<field>(i) and nubis_layer(i):
 * generated from render/uniforms.py's _LAYER_ROWS, where each field's place in the block is stated once.
 * Layers share no altitude, so a point of the sky is in one layer at most (nubis_layer_at). */
NUBIS_GENERATED(nubis_layer)

/* The layer whose clouds can reach this altitude, or -1 (between layers, above or under them all).
 * Unrolled: no loop iterations against the platform's loop limit (core/march.py). */
bool nubis_in_layer(int i, float altitude)
{
  return int(P.cloud_layer_count) > i && altitude >= nubis_layer_extent_bottom(i) &&
         altitude <= nubis_layer_extent_top(i);
}

int nubis_layer_at(float altitude)
{
  if (nubis_in_layer(0, altitude)) {
    return 0;
  }
  if (nubis_in_layer(1, altitude)) {
    return 1;
  }
  if (nubis_in_layer(2, altitude)) {
    return 2;
  }
  if (nubis_in_layer(3, altitude)) {
    return 3;
  }
  return -1;
}

struct NubisFieldSample {
  vec4 a;
  vec4 b;
  float inside; /* 1 inside the field and the draw radius, fading to 0 at their edges */
};

/* How much of a column exists at world xy: 1 inside the field and the draw radius, fading to 0 at
 * their edges, and 0 outside a comparison's clip box. Shared by the volume and the cirrus. */
float nubis_inside(vec2 xy, vec2 uv)
{
  /* Nothing outside the painted field: repeating it would invent clouds nobody authored
   * (docs/sources.md#field-extent). */
  vec2 edge = min(uv, 1.0 - uv) * P.field_size;
  float in_field = clamp01(min(edge.x, edge.y) / max(P.draw_fade, 1.0));
  /* S15: clouds are drawn within the draw radius; the fade lives in the density itself so that the
   * bake holds exactly what the viewport shows (docs/sources.md#draw-radius-fade). */
  float in_radius = clamp01((P.layer_draw_radius - length(xy - vec2(P.draw_center_x, P.draw_center_y))) / max(P.draw_fade, 1.0));
  if (P.clip_box.z >= P.clip_box.x && (any(lessThan(xy, P.clip_box.xy)) || any(greaterThan(xy, P.clip_box.zw)))) {
    return 0.0;
  }
  return in_field * in_radius;
}

NubisFieldSample nubis_sample_field(vec2 xy, int slice)
{
  NubisFieldSample f;
  vec2 uv = (xy - vec2(P.field_origin_x, P.field_origin_y)) * P.field_inv_size + 0.5;
  f.a = textureLod(field_a, vec3(clamp(uv, 0.0, 1.0), float(slice)), 0.0);
  f.b = textureLod(field_b, vec3(clamp(uv, 0.0, 1.0), float(slice)), 0.0);
  f.inside = nubis_inside(xy, uv);
  return f;
}

/* The height fractions over which the top ramp falls from 1 to 0 for this top type: above its end the
 * profile is zero (the view march's reach, nubis_layer_reach, reads it too). */
vec2 nubis_top_ramp(float top_type)
{
  float t = clamp01(top_type);
  return t < 0.5 ? mix(NUBIS_PROFILE_TOP_STRATUS, NUBIS_PROFILE_TOP_STRATOCUMULUS, t * 2.0) :
                   mix(NUBIS_PROFILE_TOP_STRATOCUMULUS, NUBIS_PROFILE_TOP_CUMULUS, t * 2.0 - 1.0);
}

/* Vertical profile. The sources show the curves only as figures; these are trapezoids of our own
 * (docs/sources.md#vertical-profile). Horizon Forbidden West's split (GDC22): the top ramp follows the
 * top type (0 stratus, 0.5 stratocumulus, 1 cumulus), the bottom ramp follows the bottom type and
 * relaxes as it rises, and the two lookups multiply. Bottom type 0 is the crisp flat base of
 * fair-weather clouds. */
float nubis_vertical_profile(float h, float top_type, float bottom_type)
{
  vec2 top_ramp = nubis_top_ramp(top_type);
  float bottom_end = mix(NUBIS_PROFILE_BASE_CRISP, NUBIS_PROFILE_BASE_RELAXED, clamp01(bottom_type));
  float bottom = clamp01(h / bottom_end);
  float top = clamp01(remap(h, top_ramp.x, top_ramp.y, 1.0, 0.0));
  return bottom * top;
}

/* Height fraction in the column's own layer: GPU Pro 7's height fraction on the spherical shell, between
 * the min and max height of GDC22's field (docs/sources.md#spherical-height-fraction). */
float nubis_height_fraction(float altitude, vec4 field_b_sample, NubisLayer L)
{
  float thickness = L.top - L.bottom;
  float lo = L.bottom + field_b_sample.g * thickness;
  float hi = L.bottom + field_b_sample.b * thickness;
  return (altitude - lo) / max(hi - lo, 1.0);
}

/* ---- superstorm vortex (GDC22; sine/cosine rotation after Matthew D. Roach) ------------------------ */

/* Angle of ring `ring` (0 = innermost of 6) at ring coordinate u = 6 * dist / radius: speeds fall
 * ring by ring from the centre, each ring has its own phase (skew), and rings outside faster ones are
 * twisted with the radius for the spiral tendrils of a boundary layer (docs/sources.md#vortex-rings). */
float nubis_ring_angle(int ring, float u, float spin, float time)
{
  float speed = spin * (1.0 - float(ring) / NUBIS_VORTEX_RINGS);
  float skew = float(ring) * NUBIS_VORTEX_RING_SKEW;
  float twist = ring > 0 ? P.storm_twist * (float(ring) + 1.0 - u) : 0.0;
  return time * speed + skew + twist;
}

/* Detail-noise sample position after every storm's vortex; `second` and `weight` return the
 * position in the neighbouring ring where two rings overlap (weight 0: one sample suffices).
 * The time is each storm's vortex time (render/uniforms.py): the lifecycle fade integrated over the
 * animation, so a growing storm turns ever faster up to its spin and never sweeps an accumulated
 * angle in. The angles are not faded, so they stay whole turns apart across the vortex time's wrap:
 * instead `unturned` returns how much of the detail is not turned by any storm. The rotation dies out
 * over each storm's outer rim, so its edge has no seam, and grows in with the lifecycle blend (GDC22:
 * the storm transitions seamlessly from cloud); the caller blends turned and unturned detail by it. */
vec2 nubis_vortex(vec2 xy, out vec2 second, out float weight, out float unturned)
{
  second = xy;
  weight = 0.0;
  float turned_share = 0.0;
#if NUBIS_STORMS
  int count = min(int(P.storm_count), NUBIS_MAX_STORMS);
  for (int i = 0; i < count; i++) {
    vec4 shape = P.storm_shape[i];
    float dist = distance(xy, shape.xy);
    if (shape.w <= 0.0 || dist >= shape.z) {
      continue;
    }
    float u = NUBIS_VORTEX_RINGS * dist / shape.z;
    /* The rotation dies out over the outermost ring and grows in with the blend factor. */
    turned_share = max(turned_share, (1.0 - smoothstep(NUBIS_VORTEX_RINGS - 1.0, NUBIS_VORTEX_RINGS, u)) *
                                         smoothstep(0.0, NUBIS_VORTEX_GROW_BLEND, shape.w));
    float spin = P.storm_light[i].x;
    float time = P.storm_flash[i].w;
    float boundary = floor(u + 0.5);
    float e = u - boundary;
    int ring = int(floor(u));
    if (P.storm_jittered_rings > 0.5) {
      /* PS4 quality (GDC22): one sample, the ring boundary jittered instead of blended. */
      float jitter = fract(sin(dot(xy, NUBIS_RING_HASH_DIR)) * NUBIS_RING_HASH_SCALE) - 0.5;
      ring = clamp(int(floor(u + jitter * NUBIS_VORTEX_OVERLAP)), 0, int(NUBIS_VORTEX_RINGS) - 1);
      float angle = nubis_ring_angle(ring, u, spin, time);
      xy = nubis_rotate_about(xy, shape.xy, angle);
      second = nubis_rotate_about(second, shape.xy, angle); /* an earlier storm's second sample turns too */
    }
    else if (abs(e) < 0.5 * NUBIS_VORTEX_OVERLAP && boundary >= 1.0 && boundary <= NUBIS_VORTEX_RINGS - 1.0) {
      int inner = int(boundary) - 1;
      weight = smoothstep(-0.5 * NUBIS_VORTEX_OVERLAP, 0.5 * NUBIS_VORTEX_OVERLAP, e);
      second = nubis_rotate_about(xy, shape.xy, nubis_ring_angle(inner + 1, u, spin, time));
      xy = nubis_rotate_about(xy, shape.xy, nubis_ring_angle(inner, u, spin, time));
    }
    else {
      float angle = nubis_ring_angle(ring, u, spin, time);
      xy = nubis_rotate_about(xy, shape.xy, angle);
      second = nubis_rotate_about(second, shape.xy, angle);
    }
  }
#endif
  /* Outside every storm nothing turned, and the turned sample is the unturned one. */
  unturned = turned_share > 0.0 ? 1.0 - turned_share : 0.0;
  return xy;
}

/* Detail fBm at a (wind-moved) position, with the curl twist at the base. */
float nubis_detail_fbm(vec3 p_hf, float h, int level, vec4 periods)
{
  vec2 curl_uv = nubis_tile_uv(p_hf.xy / periods.z, vec2(NUBIS_CURL_SIZE));
  vec2 curl = textureLod(noise_curl, curl_uv, 0.0).xy * 2.0 - 1.0;
  p_hf.xy += curl * (1.0 - h) * periods.w;
  vec3 uvw = p_hf / periods.y;
  NUBIS_COUNT_3D(1);
  /* Branches, not a conditional expression: compilers may evaluate both sides of ?: and fetch twice. */
  vec3 hf;
  if (level < 1) {
    hf = textureLod(noise_hf, nubis_tile_uvw(uvw, vec3(NUBIS_HF_SIZE)), 0.0).rgb;
  }
  else {
    hf = textureLod(noise_hf_mip1, nubis_tile_uvw(uvw, vec3(NUBIS_HF1_SIZE)), 0.0).rgb;
  }
  return dot(hf, NUBIS_FBM_WEIGHTS);
}

struct NubisDensity {
  float fine;   /* the full sample, detail erosion included (a cheap sample's: eroded by the detail's mean) */
  float coarse; /* the base shape, uneroded: never below `fine` (erosion only removes density, GPU Pro 7, S15) */
  float h;      /* height fraction */
  float precipitation;
  float vdb;    /* the artists' VDB clouds' share of `fine` (0 to 1; nubis_vdb_lib.glsl) */
};

/* The density, in GPU Pro 7's order (docs/sources.md#density-order): base shape, profile, coverage,
 * then detail erosion. `cheap` stops after the coverage step (GPU Pro 7's cheap sample: one 3D fetch;
 * docs/sources.md#coarse-sample). `lod` is a whole mip level: 0 reads the full-resolution noise, 1 the half-resolution
 * copies, 2 the quarter-resolution base shape (the detail noise has two levels). */
NubisDensity nubis_field_density(vec3 p, bool cheap, float lod)
{
#if NUBIS_FETCH_STATS
  nubis_density_calls++;
#endif
  NubisDensity d;
  d.fine = 0.0;
  d.coarse = 0.0;
  d.h = 0.0;
  d.precipitation = 0.0;
  d.vdb = 0.0;

  /* The early returns below skip work where the result is already known to be zero: S15's isosurface
   * ("we only need to do the high detail noise where the low detail sample returns a non zero
   * result"). The benchmark's naive march (NUBIS_NAIVE) takes the full sample at every step instead;
   * the values are the same. */
  float altitude = nubis_altitude(p, P.layer_planet_radius);
  /* Outside every layer there is no cloud (the naive march too: it has no layer to read). */
  int layer = nubis_layer_at(altitude);
  if (layer < 0) {
    return d;
  }
  NubisLayer L = nubis_layer(layer);
  NubisFieldSample f = nubis_sample_field(p.xy, L.slice);
  float h = nubis_height_fraction(altitude, f.b, L);
  d.h = clamp01(h);
  d.precipitation = f.a.g;
  float coverage = clamp01(f.a.r * L.coverage) * f.inside;
  float profile = (h > 0.0 && h < 1.0) ? nubis_vertical_profile(h, f.a.b, f.a.a) : 0.0;
  /* GDC22: where storm coverage is non-zero, the flipped vertical profile joins the normal one to
   * spread the top into an anvil (docs/sources.md#anvil). We place the flipped lookup in a band under the
   * shell's top (the storm's tropopause), so the anvil is flat and reaches across the whole stencil,
   * with the storm coverage as its coverage. max() leaves storm-free clouds exactly as they were. */
  float storm = clamp01(f.b.r) * f.inside;
  /* The anvil's own profile and coverage: it is a second shape beside the column's, and the density
   * is the larger of the two (below), which has no step where one takes over from the other. */
  float anvil = 0.0;
  float anvil_coverage = 0.0;
#if NUBIS_STORMS
  float band = NUBIS_ANVIL_BAND * (L.extent_top - L.bottom);
  float anvil_h = (altitude - (L.extent_top - band)) / band;
  if (P.storm_count > 0.0 && anvil_h > 0.0 && anvil_h < 1.0) {
    /* The anvil "flattens out and spreads in the wind direction" (GDC22): its storm coverage is read
     * upwind, further the higher the sample, so the top streams downwind of the column. */
    vec2 upwind = p.xy - L.wind_dir * (P.storm_anvil_shift * anvil_h);
    vec2 upwind_uv = (upwind - vec2(P.field_origin_x, P.field_origin_y)) * P.field_inv_size + 0.5;
    float anvil_storm = clamp01(textureLod(field_b, vec3(clamp(upwind_uv, 0.0, 1.0), float(L.slice)), 0.0).r) *
                        f.inside;
    anvil = nubis_vertical_profile(1.0 - anvil_h, NUBIS_ANVIL_TYPE, 0.0) * anvil_storm;
    anvil_coverage = max(coverage, NUBIS_ANVIL_COVERAGE * anvil_storm);
  }
#endif
#if !NUBIS_NAIVE
  if ((profile <= 0.0 || coverage <= 0.0) && (anvil <= 0.0 || anvil_coverage <= 0.0)) {
    return d;
  }
#endif

  /* GPU Pro 7: tops skew downwind and both noises drift with the wind and slightly upward, each at its
   * own speed. We subtract the offsets (GDC22) and put the upward bias on z, so features move downwind
   * and rise (docs/sources.md#wind-direction-and-sign); the coverage/type field itself never moves
   * (GDC22). */
  vec3 wind_dir = vec3(L.wind_dir, 0.0);
  vec3 drift = (wind_dir + vec3(0.0, 0.0, L.upward_bias)) * L.wind_distance;
  /* The anvil also leans downwind (GDC22: noises rotated and skewed for a wind-swept look), from the
   * column's own height and storm coverage, which are smooth where the anvil takes over. */
  vec3 skewed = p - h * wind_dir * (L.top_offset + storm * h * NUBIS_ANVIL_LEAN * L.top_offset);
  vec3 p_lf = skewed - drift;

  vec3 lf_uvw = p_lf / L.noise.x;
  NUBIS_COUNT_3D(1);
  vec4 lf;
  if (lod < 0.5) {
    lf = textureLod(noise_lf, nubis_tile_uvw(lf_uvw, vec3(NUBIS_LF_SIZE)), 0.0);
  }
  else if (lod < 1.5) {
    lf = textureLod(noise_lf_mip1, nubis_tile_uvw(lf_uvw, vec3(NUBIS_LF1_SIZE)), 0.0);
  }
  else {
    lf = textureLod(noise_lf_mip2, nubis_tile_uvw(lf_uvw, vec3(NUBIS_LF2_SIZE)), 0.0);
  }
  float lf_fbm = dot(lf.gba, NUBIS_FBM_WEIGHTS);
  /* GPU Pro 7: the Worley fBm dilates the Perlin-Worley base shape (docs/sources.md#perlin-worley). */
  float shape = remap(lf.r, -(1.0 - lf_fbm), 1.0, 0.0, 1.0);
  /* GDC22's 1 - coverage, so clouds inflate as coverage rises; GPU Pro 7's "smaller clouds are
   * lighter" multiply is the option in the layer's multiply_coverage (docs/sources.md#coverage-erosion). */
  float with_coverage = clamp01(remap(shape * profile, 1.0 - coverage, 1.0, 0.0, 1.0));
  with_coverage *= mix(1.0, coverage, L.multiply_coverage);
  /* The height the detail noise is shaped by: where the anvil is the larger shape its detail turns
   * to billows (not the wisps of a cloud base), in proportion, so nothing jumps. */
  float detail_h = h;
#if NUBIS_STORMS
  float anvil_density = clamp01(remap(shape * anvil, 1.0 - anvil_coverage, 1.0, 0.0, 1.0));
  /* Only where the anvil's profile reaches past the column's, as GDC22's max of the two profiles,
   * faded in over a short range of profile instead of switched. */
  anvil_density *= mix(1.0, anvil_coverage, L.multiply_coverage) *
                   smoothstep(-NUBIS_ANVIL_TAKEOVER, NUBIS_ANVIL_TAKEOVER, anvil - profile);
  if (anvil_density > 0.0) {
    detail_h = mix(h, max(h, NUBIS_ANVIL_DETAIL_HEIGHT), anvil_density / (anvil_density + with_coverage));
    with_coverage = max(with_coverage, anvil_density);
  }
#endif
  /* The layer's own sigma travels in the density, so every optical depth (light model, bake) that
   * multiplies by P.density_sigma gets it (docs/layers.md). */
  float multiplier = max(f.b.a, 0.0) * L.sigma_scale;
  d.coarse = with_coverage * multiplier;
  /* GPU Pro 7: a wispy base eroded by the detail, billows carved above it; a rising bottom type keeps
   * the wisps higher up the cloud, for ragged undersides (GDC22; docs/sources.md#wispy-and-billowy-detail). */
  float billow = clamp01(detail_h * mix(NUBIS_BILLOW_RATE, NUBIS_BILLOW_RATE_RAGGED, clamp01(f.a.a)));
#if NUBIS_NAIVE
  if (cheap) {
#else
  if (cheap || with_coverage <= 0.0) {
#endif
    /* A cheap sample skips the detail noise (S15): it erodes by the detail's mean instead, so that on
     * average it removes what the full sample removes (uneroded, the light's cheap samples read 3 %
     * darker than full ones; docs/viewport.md#light-model). */
    float mean_modifier = mix(NUBIS_HF_FBM_MEAN, 1.0 - NUBIS_HF_FBM_MEAN, billow);
    d.fine = clamp01(remap(with_coverage, mean_modifier * L.erosion, 1.0, 0.0, 1.0)) * multiplier;
    return d;
  }

  /* GPU Pro 7: animated curl noise twists the detail at the base, fading to none at the top
   * (docs/sources.md#curl-noise). Inside a superstorm the detail turns with the vortex; two rings
   * overlap -> two samples (GDC22). */
  vec3 p_hf = skewed - drift * L.detail_speed;
  /* The rings are decided by where the sample is, not by where the wind has carried its noise, so
   * nothing outside a storm's radius ever turns. */
  vec2 second;
  float ring_weight, unturned;
  vec2 turned = nubis_vortex(p.xy, second, ring_weight, unturned);
  int hf_level = int(lod + 0.5);
  float hf_fbm = nubis_detail_fbm(vec3(p_hf.xy + (turned - p.xy), p_hf.z), detail_h, hf_level, L.noise);
  if (ring_weight > 0.0) {
    hf_fbm = mix(hf_fbm,
                 nubis_detail_fbm(vec3(p_hf.xy + (second - p.xy), p_hf.z), detail_h, hf_level, L.noise),
                 ring_weight);
  }
#if NUBIS_STORMS
  if (unturned > 0.0) {
    if (P.storm_jittered_rings < 0.5) {
      hf_fbm = mix(hf_fbm, nubis_detail_fbm(p_hf, detail_h, hf_level, L.noise), unturned);
    }
    else if (fract(sin(dot(p.xy, NUBIS_TURN_HASH_DIR)) * NUBIS_TURN_HASH_SCALE) < unturned) {
      /* PS4 quality: one sample, the turned or the unturned detail by a hashed choice. */
      hf_fbm = nubis_detail_fbm(p_hf, detail_h, hf_level, L.noise);
    }
  }
#endif
  /* GPU Pro 7: the stored (inverted) Worley fBm erodes the base into wisps, and flipped back it carves
   * billows above the lowest 10 % (`billow`, above). */
  float hf_modifier = mix(hf_fbm, 1.0 - hf_fbm, billow);
  /* GPU Pro 7: erosion strength 0.2 (the layer's erosion); the remap never raises a value, so fine <= coarse. */
  float eroded = clamp01(remap(with_coverage, hf_modifier * L.erosion, 1.0, 0.0, 1.0));
  d.fine = eroded * multiplier;
  return d;
}

/* The clouds' density at p: the data field's, and the artists' VDB clouds added to it (their extinctions
 * add; nubis_vdb_lib.glsl). A VDB cloud's sample is as cheap as a cheap sample, so the coarse value holds
 * it too, and the coarse-to-fine march finds it as it finds the field's clouds. */
NubisDensity nubis_density(vec3 p, bool cheap, float lod)
{
  NubisDensity d = nubis_field_density(p, cheap, lod);
#if NUBIS_VDB
  float h;
  float v = nubis_vdb_density(p, h);
  if (v > 0.0) {
    if (d.coarse <= 0.0) {
      d.h = h;
    }
    /* An artist's cloud holds no rain: the field's precipitation darkens the field's share only. */
    d.precipitation *= d.fine / (d.fine + v);
    d.vdb = v / (d.fine + v);
    d.fine += v;
    d.coarse += v;
  }
#endif
  return d;
}

/* GDC22: the cirrus layer is 2D: three tiling cloudscapes from wispy cirrostratus (type 0) through
 * cirrus (0.5) to billowy cirrocumulus (1), blended by type and eroded by the inverse of coverage; it
 * scrolls with its own wind (GPU Pro 7, S15; docs/sources.md#cirrus-layer). Returns the density at
 * world xy. */
/* One level of the cirrus texture's mip atlas (render/textures.py): level 0 at the left, the smaller
 * levels stacked in a column to its right, each with its own wrapped edge texel. */
vec3 nubis_cirrus_level(vec2 uv, int level)
{
  float n = float(NUBIS_CIRRUS_SIZE >> level);
  vec2 origin = vec2(0.0);
  if (level > 0) {
    origin.x = float(NUBIS_CIRRUS_SIZE + 1);
    for (int k = 1; k < level; k++) {
      origin.y += float((NUBIS_CIRRUS_SIZE >> k) + 1);
    }
  }
  vec2 texel = origin + fract(uv) * n + 0.5;
  return textureLod(noise_cirrus, texel / vec2(NUBIS_CIRRUS_ATLAS), 0.0).rgb;
}

/* Averaging the noise before the erosion's non-linear remap flattens the detail, so a level is only
 * dropped once a pixel covers two texels of it: measured against 8x supersampling, blurring sooner
 * cost more than the aliasing it removed (docs/viewport.md#mip-levels). Used by the view ray's noise
 * level (nubis_view_lod) and the cirrus's. */
#define NUBIS_LOD_BIAS 1.0

/* `lod` is the mip level as a fraction (the texels one pixel covers, log2): two levels are blended, so
 * distant cirrus seen at a grazing angle filters instead of aliasing into streaks. */
float nubis_cirrus_density(vec2 xy, float lod)
{
  vec2 uv = (xy - vec2(P.field_origin_x, P.field_origin_y)) * P.field_inv_size + 0.5;
  vec4 c = textureLod(field_c, clamp(uv, 0.0, 1.0), 0.0);
  float coverage = clamp01(c.r * P.cirrus_coverage) * nubis_inside(xy, uv);
  if (coverage <= 0.0) {
    return 0.0;
  }
  vec2 tex_uv = (xy - vec2(P.cirrus_offset_x, P.cirrus_offset_y)) * P.cirrus_inv_period;
  float level = clamp(lod, 0.0, float(NUBIS_CIRRUS_LEVELS - 1));
  int l0 = int(floor(level));
  vec3 layers = nubis_cirrus_level(tex_uv, l0);
  if (level > float(l0) && l0 + 1 < NUBIS_CIRRUS_LEVELS) {
    layers = mix(layers, nubis_cirrus_level(tex_uv, l0 + 1), level - float(l0));
  }
  float t = clamp01(c.g);
  float v = t < 0.5 ? mix(layers.r, layers.g, t * 2.0) : mix(layers.g, layers.b, t * 2.0 - 1.0);
  return clamp01(remap(v, 1.0 - coverage, 1.0, 0.0, 1.0));
}

/* Optical depth of the cirrus layer along a ray from p, where the ray crosses the layer's sphere
 * ahead of it: a thin layer's slant path grows with 1 / cos of the zenith angle. The same value
 * darkens the view ray (its alpha) and the light reaching the clouds below (its shadow), which is
 * what the baked slab gives Cycles. */
float nubis_cirrus_optical_depth(vec3 p, vec3 dir, float lod)
{
  if (P.cirrus_coverage <= 0.0 || P.cirrus_opacity <= 0.0) {
    return 0.0;
  }
  float altitude = nubis_altitude(p, P.layer_planet_radius);
  vec2 hit = nubis_ray_sphere(p, dir, P.layer_planet_radius, P.cirrus_altitude);
  if (hit.x > hit.y) {
    return 0.0;
  }
  float t = altitude < P.cirrus_altitude ? hit.y : hit.x;
  if (t <= 0.0) {
    return 0.0;
  }
  vec3 q = p + dir * t;
  vec3 up = normalize(q + vec3(0.0, 0.0, P.layer_planet_radius));
  float slant = 1.0 / max(abs(dot(dir, up)), NUBIS_MIN_SLANT_COS);
  /* lod >= 0 is the caller's fixed level; lod < 0 asks for the view's own: the pixel's footprint on
   * the layer (P.view: metres per metre of distance, plus a constant for orthographic views),
   * stretched by the slant, in texels, one level late as for the 3D noise (nubis_view_lod). */
  float level = lod;
  if (lod < 0.0) {
    float footprint = (P.pixel_angle * t + P.pixel_size) * slant;
    level = max(log2(max(footprint * P.cirrus_inv_period * float(NUBIS_CIRRUS_SIZE), 1.0)) - NUBIS_LOD_BIAS, 0.0);
  }
  float density = nubis_cirrus_density(q.xy, level);
  return density * P.cirrus_opacity * slant;
}
