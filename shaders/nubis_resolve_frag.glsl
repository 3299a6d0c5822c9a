/* Temporal upscaling, step 2 (S15, GDC22; docs/viewport.md, docs/sources.md#temporal-upscaling): the full-resolution history of this
 * redraw, from the working buffer just marched and the history of the previous redraw.
 *   - The pixel marched now takes the new sample; once every pixel has one (16 redraws after a
 *     change), later passes average into it with weight T.frame.z.
 *   - Every other pixel keeps its history while nothing changes: it was marched or reprojected since.
 *   - On the redraw after a change, every other pixel is reprojected: its cloud (at the distance the
 *     new march saw nearby, else the one it had) is moved back by the clouds' own motion (wind scroll,
 *     storm rotation) and projected with the previous camera; the history there is clamped to the
 *     new samples around it, which removes ghosts. Pixels that come from off screen, or whose history
 *     is not valid, take the working buffer upscaled (S15: "substitute the result from one of the low
 *     res buffers"), so a pan shows no black or stale edges.
 *   - Where the scene's depth is bound (T.scene.x), a pixel holds the clouds in front of its surface, or the
 *     whole sky where there is none, and remembers that surface's distance along the view's axis: history
 *     is reprojected from the surface itself, and only from a pixel that saw the same surface (or the sky,
 *     for a pixel of sky), so no veil is left behind at a silhouette when the view or an object moves
 *     (docs/viewport.md#clouds-in-front-of-the-scene); the neighbourhood and the fill take only the new
 *     samples of the same kind.
 * Outputs: colour, (cloud distance, the surface's axial distance or 0, -, -), flash mask, as the march's. */

/* A reprojected pixel that saw no cloud is reprojected as a direction this far away (metres). */
const float NUBIS_FAR_DEPTH = 1e6;

/* Where history pixel centre `p` falls in the working buffer, in texels: texel (i, j) holds the pixel
 * 4 (i, j) + the offset marched this redraw (T.flags.zw). */
vec2 nubis_work_position(vec2 p)
{
  return (p - (T.flags.zw + 0.5)) / float(NUBIS_BLOCK);
}

/* The last working-buffer texel in each axis that holds a marched pixel (sizes need not be multiples of
 * 4: beyond it the buffer holds nothing). */
vec2 nubis_work_last()
{
  return floor((T.size.xy - 1.0 - T.flags.zw) / float(NUBIS_BLOCK));
}

vec4 nubis_work_bilinear(sampler2D tex, vec2 history_pixel)
{
  vec2 at = clamp(nubis_work_position(history_pixel), vec2(0.0), nubis_work_last());
  return textureLod(tex, (at + 0.5) / T.size.zw, 0.0);
}

/* The history at `uv` through a Catmull-Rom filter: a pan resamples the history every redraw, and the
 * bilinear filter's blur would pile up over the frames. Five bilinear taps (the corner taps of the full
 * 4x4 kernel carry little weight and are left out, then the weights renormalised). The polynomials are
 * the Catmull-Rom basis (Catmull and Rom 1974; docs/sources.md#numerical-methods). */
vec4 nubis_history_cubic(sampler2D tex, vec2 uv, vec2 size)
{
  vec2 p = uv * size - 0.5;
  vec2 f = fract(p);
  vec2 centre = floor(p) + 0.5;
  vec2 w0 = f * (-0.5 + f * (1.0 - 0.5 * f));
  vec2 w1 = 1.0 + f * f * (-2.5 + 1.5 * f);
  vec2 w2 = f * (0.5 + f * (2.0 - 1.5 * f));
  vec2 w3 = f * f * (-0.5 + 0.5 * f);
  vec2 w12 = w1 + w2;
  vec2 t0 = (centre - 1.0) / size;
  vec2 t3 = (centre + 2.0) / size;
  vec2 t12 = (centre + w2 / w12) / size;
  vec4 c = textureLod(tex, vec2(t12.x, t0.y), 0.0) * (w12.x * w0.y) +
           textureLod(tex, vec2(t0.x, t12.y), 0.0) * (w0.x * w12.y) +
           textureLod(tex, t12, 0.0) * (w12.x * w12.y) +
           textureLod(tex, vec2(t3.x, t12.y), 0.0) * (w3.x * w12.y) +
           textureLod(tex, vec2(t12.x, t3.y), 0.0) * (w12.x * w3.y);
  float weight = w12.x * w0.y + w0.x * w12.y + w12.x * w12.y + w3.x * w12.y + w12.x * w3.y;
  return c / weight;
}

/* The scene's surface at history pixel q (its axial distance, 0 = the sky or no depth bound). */
float nubis_surface_at(ivec2 q)
{
  if (T.scene.x < 0.5) {
    return 0.0;
  }
  return nubis_axial_depth(texelFetch(scene_depth, ivec2(vec2(q) * T.scene.yz), 0).r, T.depth_map);
}

void main()
{
  ivec2 q = ivec2(gl_FragCoord.xy);
  ivec2 block = q / NUBIS_BLOCK;
  /* redraws since this pixel was marched */
  int age = (int(T.frame.x) - nubis_bayer4(q) + NUBIS_BLOCK_PIXELS) & (NUBIS_BLOCK_PIXELS - 1);
  int since_change = int(T.frame.y);
  bool valid = T.flags.x > 0.5;
  vec4 hist_c = texelFetch(hist_color, q, 0);
  vec4 hist_a = texelFetch(hist_attr, q, 0);
  vec4 hist_f = texelFetch(hist_flash, q, 0);
  if (age == 0) {
    vec4 new_c = texelFetch(work_color, block, 0);
    vec4 new_a = texelFetch(work_attr, block, 0);
    vec4 new_f = texelFetch(work_flash, block, 0);
    float w = (valid && since_change >= NUBIS_BLOCK_PIXELS) ? T.frame.z : 1.0;
    color = mix(hist_c, new_c, w);
    flash = mix(hist_f, new_f, w);
    attr = vec4(new_a.x, new_a.y, 0.0, 0.0);
    return;
  }
  if (valid && since_change > 0) {
    color = hist_c;
    attr = hist_a;
    flash = hist_f;
    return;
  }
  float surface = nubis_surface_at(q);
  /* Reproject. The neighbourhood: the 3x3 new samples nearest this pixel (centred on it, so the
   * clamp changes from pixel to pixel rather than block by block), of the same surface as this pixel
   * (all of them where none is). */
  vec4 lo = vec4(1e30), hi = vec4(-1e30);
  vec4 lo_f = vec4(1e30), hi_f = vec4(-1e30);
  vec4 same_c = vec4(0.0), same_f = vec4(0.0), wide_c = vec4(0.0), wide_f = vec4(0.0);
  float same_w = 0.0, wide_w = 0.0;
  bool mixed = false; /* some sample nearby saw another surface: this pixel is at a silhouette */
  float near_depth = 0.0;
  ivec2 last = ivec2(nubis_work_last());
  vec2 at = nubis_work_position(vec2(q) + 0.5);
  ivec2 nearest = ivec2(floor(at + 0.5));
  vec2 at_clamped = clamp(at, vec2(0.0), vec2(last));
  for (int pass = 0; pass < 2 && wide_w <= 0.0; pass++) {
    for (int dy = -1; dy <= 1; dy++) {
      for (int dx = -1; dx <= 1; dx++) {
        ivec2 b = clamp(nearest + ivec2(dx, dy), ivec2(0), last);
        vec4 a = texelFetch(work_attr, b, 0);
        if (pass == 0 && !nubis_same_surface(a.y, surface)) {
          mixed = true;
          continue;
        }
        vec4 c = texelFetch(work_color, b, 0);
        vec4 f = texelFetch(work_flash, b, 0);
        lo = min(lo, c);
        hi = max(hi, c);
        lo_f = min(lo_f, f);
        hi_f = max(hi_f, f);
        /* The fill: the bilinear weights of the new samples of this surface (the bilinear fill itself
         * where all are), or, where none of the four nearest is, the nearest weighing most. */
        vec2 off = vec2(b) - at_clamped;
        float tent = max(1.0 - abs(off.x), 0.0) * max(1.0 - abs(off.y), 0.0);
        same_c += c * tent;
        same_f += f * tent;
        same_w += tent;
        float w = 1.0 / (1.0 + dot(off, off));
        wide_c += c * w;
        wide_f += f * w;
        wide_w += w;
        if (a.x > 0.0 && (near_depth <= 0.0 || (dx == 0 && dy == 0))) {
          near_depth = a.x;
        }
      }
    }
  }
  vec2 centre = vec2(q) + 0.5;
  vec4 fill_c = nubis_work_bilinear(work_color, centre);
  vec4 fill_f = nubis_work_bilinear(work_flash, centre);
  if (mixed) {
    /* At a silhouette the bilinear fill would mix the two sides: this side's samples instead. */
    fill_c = same_w > 1e-4 ? same_c / same_w : wide_c / wide_w;
    fill_f = same_w > 1e-4 ? same_f / same_w : wide_f / wide_w;
  }
  if (!valid) {
    color = fill_c;
    flash = fill_f;
    attr = vec4(0.0, surface, 0.0, 0.0);
    return;
  }
  vec3 origin, dir;
  nubis_view_ray(centre / T.size.xy, T.inv_view_proj, T.eye, origin, dir);
  float depth = near_depth > 0.0 ? near_depth : hist_a.x;
  if (surface > 0.0) {
    /* A surface's pixel moves with the surface. */
    depth = nubis_axial_to_ray(surface, origin, dir, T.view_axis);
  }
  else if (depth <= 0.0) {
    /* No cloud seen here: reproject at the middle of the cloud layer, or as a direction far away. */
    vec2 mid = nubis_ray_sphere(origin, dir, P.layer_planet_radius, 0.5 * (P.shell_bottom + P.shell_top));
    depth = mid.y > 0.0 ? (mid.x > 0.0 ? mid.x : mid.y) : NUBIS_FAR_DEPTH;
  }
  vec3 world = origin + dir * depth;
  vec4 before = T.prev_view_proj * vec4(nubis_previous_position(world, T.frame.w), 1.0);
  vec2 prev_uv = before.xy / before.w * 0.5 + 0.5;
  bool outside = before.w <= 0.0 || any(lessThan(prev_uv, vec2(0.0))) || any(greaterThan(prev_uv, vec2(1.0)));
  if (!outside && T.scene.x > 0.5) {
    /* History only from a pixel that saw this surface then (its axial distance from the previous camera),
     * or the sky for a pixel of sky. */
    float then = texelFetch(hist_attr, ivec2(prev_uv * T.size.xy), 0).y;
    float expected = surface > 0.0 ? dot(world, T.prev_axis.xyz) - T.prev_axis.w : 0.0;
    outside = !nubis_same_surface(then, expected);
  }
  if (outside) {
    color = fill_c;
    flash = fill_f;
    attr = vec4(depth, surface, 0.0, 0.0);
    return;
  }
  /* At a silhouette the cubic filter's taps would reach across it: the one history texel instead. */
  vec4 prev_c = mixed ? texelFetch(hist_color, ivec2(prev_uv * T.size.xy), 0) : nubis_history_cubic(hist_color, prev_uv, T.size.xy);
  vec4 prev_f = mixed ? texelFetch(hist_flash, ivec2(prev_uv * T.size.xy), 0) : nubis_history_cubic(hist_flash, prev_uv, T.size.xy);
  color = clamp(prev_c, lo, hi);
  flash = clamp(prev_f, lo_f, hi_f);
  attr = vec4(depth, surface, 0.0, 0.0);
}
