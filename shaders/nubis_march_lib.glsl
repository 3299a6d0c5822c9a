/* The view-ray march: premultiplied scene-linear radiance and alpha (SPEC 2.12, 3.1, 3.3), shared by
 * the raymarch and motion stages. Requires the cloud libraries. */

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

/* SPEC 3.7: the cirrus layer, sampled once where the ray crosses its sphere. Its light is the exact
 * single scattering of a thin homogeneous slab (the layer Cycles renders from the bake): with slant
 * factors m = 1 / cos(zenith) for the view and the sun and vertical optical depth tau, sunlight
 * that passes through the slab towards the eye gives m_v / (m_v - m_s) (e^(-tau m_s) - e^(-tau m_v)),
 * sunlight scattered back to the side it came from m_v / (m_v + m_s) (1 - e^(-tau (m_v + m_s))).
 * Sky light is taken as scattered in proportion to the layer's opacity. Premultiplied radiance, alpha. */
vec4 nubis_cirrus(vec3 origin, vec3 dir)
{
  float altitude = nubis_altitude(origin, P.layer.x);
  vec2 ground = nubis_ray_sphere(origin, dir, P.layer.x, 0.0);
  vec2 hit = nubis_ray_sphere(origin, dir, P.layer.x, P.cirrus.x);
  float t = altitude < P.cirrus.x ? hit.y : hit.x;
  bool hits_ground = ground.x <= ground.y && ground.y > 0.0 && ground.x < t;
  if (hits_ground && altitude >= 0.0) {
    return vec4(0.0);
  }
  float tau_view = nubis_cirrus_optical_depth(origin, dir);
  if (tau_view <= 0.0) {
    return vec4(0.0);
  }
  vec3 up = normalize(origin + dir * t + vec3(0.0, 0.0, P.layer.x));
  float mu_v = dot(dir, up);
  float mu_s = dot(P.sun_dir.xyz, up);
  float m_v = 1.0 / max(abs(mu_v), 0.05);
  float m_s = 1.0 / max(abs(mu_s), 0.05);
  float tau = tau_view / m_v;
  float sun_fraction;
  if ((mu_v > 0.0) == (mu_s > 0.0)) {
    float dm = m_v - m_s;
    sun_fraction = abs(dm) < 1e-3 ? m_v * tau * exp(-tau * m_v) :
                                    m_v / dm * (exp(-tau * m_s) - exp(-tau * m_v));
  }
  else {
    sun_fraction = m_v / (m_v + m_s) * (1.0 - exp(-tau * (m_v + m_s)));
  }
  float alpha = 1.0 - exp(-tau_view);
  vec3 light = P.sun_rad.rgb * nubis_phase(dot(dir, P.sun_dir.xyz), 1.0) * sun_fraction + P.ambient.rgb * alpha;
  return vec4(light, alpha);
}

/* `cloud_depth` returns the transmittance-weighted distance of what the ray saw (GDC22's cloud distance,
 * SPEC 3.8), 0 where it saw nothing. */
vec4 nubis_march(vec3 origin, vec3 dir, vec2 pixel, out float cloud_depth)
{
  cloud_depth = 0.0;
  float R = P.layer.x;
  /* SPEC 3.1: segment between the shell's spheres; rays that meet the ground see no clouds. */
  vec2 ground = nubis_ray_sphere(origin, dir, R, 0.0);
  vec2 inner = nubis_ray_sphere(origin, dir, R, P.shell.x);
  vec2 outer = nubis_ray_sphere(origin, dir, R, P.shell.y);
  if (outer.x > outer.y || outer.y <= 0.0) {
    return vec4(0.0);
  }
  float altitude = nubis_altitude(origin, R);
  float t0, t1;
  if (altitude < P.shell.x) {
    if (ground.x <= ground.y && ground.y > 0.0 && altitude >= 0.0) {
      return vec4(0.0);
    }
    t0 = inner.y;
    t1 = outer.y;
  }
  else if (altitude <= P.shell.y) {
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
  vec2 oxy = origin.xy - P.draw.xy;
  float a = dot(dxy, dxy);
  if (a > 1e-12) {
    float b = dot(oxy, dxy);
    float c = dot(oxy, oxy) - P.layer.w * P.layer.w;
    float disc = b * b - a * c;
    if (disc < 0.0) {
      return vec4(0.0);
    }
    t1 = min(t1, (-b + sqrt(disc)) / a);
  }
  if (t1 <= t0) {
    return vec4(0.0);
  }

  /* SPEC 3.3, GPU Pro 7: 64 steps looking up, up to 128 towards the horizon. */
  float seg = t1 - t0;
  float thickness = P.shell.y - P.shell.x;
  float k = clamp01((seg - thickness) / max(P.layer.w - thickness, 1.0));
  int steps = int(mix(P.march.x, P.march.y, k));
  float dt = seg / float(steps);
  /* Per-pixel start offset, hiding step banding as fine grain; each accumulation pass (options.z)
   * shifts it by the golden ratio so N passes cover the step evenly. */
  float jitter = P.options.x > 0.5 ? fract(nubis_pixel_hash(pixel) + 0.61803399 * P.options.z) : 0.5;

  vec3 radiance = vec3(0.0);
  float transmittance = 1.0;
  float depth_sum = 0.0;
  for (int i = 0; i < steps; i++) {
    float t = t0 + (float(i) + jitter) * dt;
    vec3 p = origin + dir * t;
    NubisDensity d = nubis_density(p, false, 0.0);
    /* SPEC 2.8, GPU Pro 7: no light march where there is no cloud. */
    if (d.fine > 0.0) {
      float absorb = nubis_extinction_factor(p, d.precipitation);
      float sigma = d.fine * P.density.x * absorb;
      float step_t = exp(-sigma * dt);
      vec3 s = nubis_in_scattering(p, dir, d, 1.0 - transmittance, absorb);
      /* Energy-conserving step (Hillaire 2016): the exact integral of constant in-scattering over
       * the step, instead of a Riemann sum that brightens with larger steps; the albedo is 1 but
       * where rain or a storm absorbs. */
      radiance += transmittance * s * ((1.0 - step_t) / absorb);
      depth_sum += t * transmittance * (1.0 - step_t);
      transmittance *= step_t;
      /* SPEC 3.5: stop once the ray is practically opaque. */
      if (transmittance < 0.005) {
        break;
      }
    }
  }
  float alpha = 1.0 - transmittance;
  cloud_depth = alpha > 0.0 ? depth_sum / alpha : 0.0;
  /* SPEC 2.11 (S15): clouds fade into the atmosphere with the depth of what the ray saw. */
  if (P.scatter2.y > 0.0 && alpha > 0.0) {
    float fade = exp(-(depth_sum / alpha) / P.scatter2.y);
    radiance = mix(P.ambient.rgb * alpha, radiance, fade);
  }
  return vec4(radiance, alpha);
}


/* SPEC 3.9.4 (GDC22): where the cloud seen at `world` was `dt` seconds ago. Scrolling clouds came from
 * upwind (the scroll direction times the timestep); inside a superstorm the point is turned back by its
 * ring's speed, blended by GDC22's mask pow(1 - d / radius, 0.1). */
vec3 nubis_previous_position(vec3 world, float dt)
{
  vec3 scrolled = world - vec3(P.wind.xy, P.wind2.y) * P.motion.y * dt;
#if NUBIS_STORMS
  int count = min(int(P.storm_info.x), NUBIS_MAX_STORMS);
  for (int i = 0; i < count; i++) {
    vec4 shape = P.storm_shape[i];
    float dist = distance(world.xy, shape.xy);
    if (shape.w <= 0.0 || dist >= shape.z) {
      continue;
    }
    int ring = min(int(floor(6.0 * dist / shape.z)), 5);
    float speed = P.storm_light[i].x * (1.0 - float(ring) / 6.0);
    vec3 turned = vec3(nubis_rotate_about(world.xy, shape.xy, -speed * dt), world.z);
    float mask = pow(clamp01(1.0 - dist / shape.z), 0.1);
    scrolled = mix(scrolled, turned, mask);
  }
#endif
  return scrolled;
}
