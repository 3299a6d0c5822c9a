/* Small pure helpers shared by the Nubis stages. Texture sizes (NUBIS_*_SIZE, the padded sizes of
 * render/textures.py) and the permutation switches (NUBIS_STORMS, NUBIS_REFERENCE, NUBIS_NAIVE,
 * NUBIS_CIRRUS, NUBIS_FETCH_STATS) are compile-time defines set by render/engine.py. */

#define NUBIS_PI 3.14159265358979

/* Named constants used by more than one stage live here: the libraries are concatenated into each
 * stage's source (render/sources.py), so each name is defined in exactly one file. */

/* The colour of a lightning flash: GDC22 gives none; a cold white (docs/sources.md#lightning-flashes). */
const vec3 NUBIS_FLASH_COLOUR = vec3(0.85, 0.9, 1.0);
/* The flash mask is a radiance per unit flash intensity, far below half float's normal range (which
 * GPUs flush to zero): the temporal buffers store it scaled by this (docs/sources.md#flash-mask). */
const float NUBIS_FLASH_MASK_SCALE = 4096.0;

/* Temporal upscaling (S15, GDC22): one pixel of every NUBIS_BLOCK x NUBIS_BLOCK block is marched per
 * redraw, so a full image takes NUBIS_BLOCK_PIXELS redraws. */
const int NUBIS_BLOCK = 4;
const int NUBIS_BLOCK_PIXELS = 16;

/* The superstorm vortex (GDC22: "6 rings"), shared by the density and the motion vectors; the ring
 * layout is the project's (docs/sources.md#vortex-rings). Rings are equally wide, radius / rings. */
const float NUBIS_VORTEX_RINGS = 6.0;
/* Neighbouring rings overlap by this many ring widths, where both are sampled and blended. */
const float NUBIS_VORTEX_OVERLAP = 0.3;
/* The rotation grows in with the storm's blend factor, fully from this blend on (GDC22: the storm
 * forms seamlessly from cloud; docs/sources.md#vortex-time). */
const float NUBIS_VORTEX_GROW_BLEND = 0.25;

vec2 nubis_rotate_about(vec2 xy, vec2 centre, float angle)
{
  vec2 d = xy - centre;
  float s = sin(angle), c = cos(angle);
  return centre + vec2(c * d.x - s * d.y, s * d.x + c * d.y); /* counter-clockwise for angle > 0 */
}

/* The order in which the 16 pixels of a 4x4 block are marched by the temporal upscaler (S15: one pixel
 * of every 4x4 block per frame): the 4x4 Bayer matrix (Bayer 1973; docs/sources.md#temporal-upscaling),
 * so consecutive redraws land far apart in the block and a partly converged image is evenly spread. */
int nubis_bayer4(ivec2 pixel)
{
  /* The matrix 0 8 2 10 / 12 4 14 6 / 3 11 1 9 / 15 7 13 5 by its bits (no array constructor, which
   * not every backend's translation accepts). */
  int x = pixel.x & 3, y = pixel.y & 3, a = x ^ y;
  return ((a & 1) << 3) | ((y & 1) << 2) | (a & 2) | ((y & 2) >> 1);
}

float clamp01(float x)
{
  return clamp(x, 0.0, 1.0);
}

/* Input ranges narrower than this count as empty in remap(). */
const float NUBIS_REMAP_EMPTY_SPAN = 1e-8;

/* GPU Pro 7's and GDC22's remap (the Habr implementation agrees): unclamped; a zero-width input range
 * maps to new_min. */
float remap(float value, float old_min, float old_max, float new_min, float new_max)
{
  float span = old_max - old_min;
  if (abs(span) < NUBIS_REMAP_EMPTY_SPAN) {
    return new_min;
  }
  return new_min + (value - old_min) / span * (new_max - new_min);
}

/* The PCG hash (Jarzynski and Olano 2020, after O'Neill's PCG; docs/sources.md#numerical-methods):
 * PCG's LCG multiplier and increment mix the two coordinates, then PCG's RXS-M-XS output permutation
 * (its shifts 28, 4, 22 and multiplier) scrambles the bits. */
const uint NUBIS_PCG_MULTIPLIER = 747796405u;
const uint NUBIS_PCG_INCREMENT = 2891336453u;
const uint NUBIS_PCG_RXS_M_XS_MULTIPLIER = 277803737u;
/* 2^24: the hash's top 24 bits, the most a float's mantissa holds exactly, scaled to [0, 1). */
const float NUBIS_HASH_24_BITS = 16777216.0;

/* Each accumulation pass shifts the step jitter by the golden ratio's fractional part, so N passes cover
 * the step evenly (docs/sources.md#step-jitter). */
const float NUBIS_GOLDEN_RATIO_FRACT = 0.61803399;

/* A per-pixel value in [0, 1) from an integer hash (PCG-style): white noise, so undersampled steps
 * show as grain rather than the diagonal hatching of interleaved gradient noise. */
float nubis_pixel_hash(vec2 pixel)
{
  uvec2 q = uvec2(ivec2(pixel));
  uint h = q.x * NUBIS_PCG_MULTIPLIER + q.y * NUBIS_PCG_INCREMENT;
  h = ((h >> ((h >> 28u) + 4u)) ^ h) * NUBIS_PCG_RXS_M_XS_MULTIPLIER;
  h = (h >> 22u) ^ h;
  return float(h >> 8u) / NUBIS_HASH_24_BITS;
}

/* Below this the quadratic's root (in metres) counts as zero: the ray starts on the sphere and is
 * tangent to it. */
const float NUBIS_RAY_DEGENERATE = 1e-12;

/* Ray against a sphere centred on the planet, for rays starting near sea level (GPU Pro 7, GDC22:
 * the march's segment comes from sphere intersections; docs/sources.md#spherical-height-fraction).
 * `oc` is the ray origin relative to the planet centre minus (0, 0, R) (i.e. the world position),
 * so that |oc|^2 - r^2 is formed without the catastrophic cancellation of 6.4e6^2 in float.
 * Returns the two distances (near, far); near > far when the sphere is missed. */
vec2 nubis_ray_sphere(vec3 origin, vec3 dir, float planet_radius, float altitude)
{
  /* |o - c|^2 - r^2 with c = (0, 0, -R), r = R + altitude, expanded to keep precision. */
  float c = dot(origin.xy, origin.xy) + (origin.z - altitude) * (origin.z + altitude) +
            2.0 * planet_radius * (origin.z - altitude);
  float b = dot(origin + vec3(0.0, 0.0, planet_radius), dir);
  float disc = b * b - c;
  if (disc < 0.0) {
    return vec2(1.0, -1.0);
  }
  /* Stable quadratic roots (Numerical Recipes 5.6; docs/sources.md#numerical-methods). */
  float q = -(b + (b >= 0.0 ? 1.0 : -1.0) * sqrt(disc)); /* sign(0) would be 0: a perpendicular ray */
  if (abs(q) < NUBIS_RAY_DEGENERATE) {
    return vec2(0.0, 0.0);
  }
  float t0 = q;
  float t1 = c / q;
  return vec2(min(t0, t1), max(t0, t1));
}

/* Altitude above the sphere of radius R centred at (0, 0, -R), precise to millimetres near the surface. */
float nubis_altitude(vec3 p, float planet_radius)
{
  float len = length(p + vec3(0.0, 0.0, planet_radius));
  return (dot(p, p) + 2.0 * planet_radius * p.z) / (len + planet_radius);
}

/* The noise textures are stored with one extra wrapped texel per axis because Blender's Python
 * textures clamp at the edge (docs/platform-notes.md#python-made-textures); this maps a repeating coordinate onto that padded layout so the
 * hardware's linear filter blends across the seam exactly as a REPEAT sampler would. */
vec3 nubis_tile_uvw(vec3 uvw, vec3 padded_size)
{
  vec3 n = padded_size - 1.0;
  return (fract(uvw) * n + 0.5) / padded_size;
}

vec2 nubis_tile_uv(vec2 uv, vec2 padded_size)
{
  vec2 n = padded_size - 1.0;
  return (fract(uv) * n + 0.5) / padded_size;
}

/* The scene's depth in the viewport (docs/viewport.md#clouds-in-front-of-the-scene). `depth_map` is the view's
 * projection of view-space z, (A, B, 1 = perspective, -): z_ndc = (A z + B) / -z in perspective, A z + B
 * orthographic, as Blender's window matrix has it. Returns how far in front of the camera, along its axis,
 * the surface drawn at window depth `d` (0-1) stands, and 0 where nothing was drawn (d = 1). */
float nubis_axial_depth(float d, vec4 depth_map)
{
  if (d >= 1.0) {
    return 0.0;
  }
  float z_ndc = 2.0 * d - 1.0;
  float z = depth_map.z > 0.5 ? -depth_map.y / min(z_ndc + depth_map.x, -1e-12) : (z_ndc - depth_map.y) / depth_map.x;
  return max(-z, 1e-3);
}

/* How far along the view ray (origin, dir) a point at axial distance `axial` lies; `axis` is the view's
 * forward direction and the axial distance's offset: axial(p) = dot(p, axis.xyz) - axis.w. */
float nubis_axial_to_ray(float axial, vec3 origin, vec3 dir, vec4 axis)
{
  float along = max(dot(dir, axis.xyz), 1e-6);
  return max((axial - (dot(origin, axis.xyz) - axis.w)) / along, 0.0);
}

/* Whether two surface distances along the view's axis (0 = the sky) are the same surface: both sky, or
 * both surfaces within 5 % of each other (the viewport's history and upscale). */
bool nubis_same_surface(float a, float b)
{
  if (a <= 0.0 || b <= 0.0) {
    return a <= 0.0 && b <= 0.0;
  }
  return abs(a - b) <= 0.05 * max(a, b);
}

/* The world-space ray through a screen position (uv in [0, 1]). A perspective view passes its eye
 * (eye.w = 1): unprojecting the near plane through a frustum kilometres deep loses metres to float
 * cancellation, which shifts every ray sideways and moves cloud edges. Orthographic views (eye.w = 0)
 * start on the near plane. */
void nubis_view_ray(vec2 screen_uv, mat4 inverse_view_projection, vec4 eye, out vec3 origin, out vec3 dir)
{
  vec2 ndc = screen_uv * 2.0 - 1.0;
  vec4 far_h = inverse_view_projection * vec4(ndc, 1.0, 1.0);
  vec3 far_point = far_h.xyz / far_h.w;
  if (eye.w > 0.5) {
    origin = eye.xyz;
  }
  else {
    vec4 near_h = inverse_view_projection * vec4(ndc, -1.0, 1.0);
    origin = near_h.xyz / near_h.w;
  }
  dir = normalize(far_point - origin);
}
