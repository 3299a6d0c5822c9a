/* Where the clouds seen now were a moment ago (GDC22's motion vectors; docs/sources.md#motion-vectors),
 * for the motion stage and the temporal resolve. Requires nubis_common_lib.glsl and the NubisParams block
 * `P`; no textures. */

/* GDC22's superstorm mask pow(1 - d / radius, 0.1): how far the motion vectors follow the storm's turn. */
const float NUBIS_MOTION_MASK_EXPONENT = 0.1;

/* The rate (radians per second) at which the detail noise at `xy` turns inside storm `i`: the same
 * rings and ring blend as nubis_vortex, differentiated in time, times the share of turned detail. The vortex reads the noise at
 * rotate(p, +angle(t)), so a feature seen at p now was at rotate(p, +rate * dt) dt seconds ago: the
 * visible vortex turns clockwise for a positive spin (docs/sources.md#rotation-sense). */
float nubis_storm_turn_rate(vec2 xy, int i)
{
  vec4 shape = P.storm_shape[i];
  float u = NUBIS_VORTEX_RINGS * distance(xy, shape.xy) / shape.z;
  /* The vortex time runs at the lifecycle fade `grow`, and of the detail only the share `grow` x rim
   * turns (nubis_vortex's `unturned`): what is seen moves at the turned detail's rate times its share. */
  float grow = smoothstep(0.0, NUBIS_VORTEX_GROW_BLEND, shape.w);
  float fade = (1.0 - smoothstep(NUBIS_VORTEX_RINGS - 1.0, NUBIS_VORTEX_RINGS, u)) * grow * grow;
  float spin = P.storm_light[i].x;
  float boundary = floor(u + 0.5);
  float e = u - boundary;
  float rate;
  if (P.storm_jittered_rings < 0.5 && abs(e) < 0.5 * NUBIS_VORTEX_OVERLAP && boundary >= 1.0 &&
      boundary <= NUBIS_VORTEX_RINGS - 1.0)
  {
    float inner = boundary - 1.0;
    float w = smoothstep(-0.5 * NUBIS_VORTEX_OVERLAP, 0.5 * NUBIS_VORTEX_OVERLAP, e);
    rate = spin * mix(1.0 - inner / NUBIS_VORTEX_RINGS, 1.0 - (inner + 1.0) / NUBIS_VORTEX_RINGS, w);
  }
  else {
    rate = spin * (1.0 - min(floor(u), NUBIS_VORTEX_RINGS - 1.0) / NUBIS_VORTEX_RINGS);
  }
  return rate * fade;
}

/* GDC22's motion vectors: where the cloud seen at `world` was `dt` seconds ago. Scrolling clouds came from
 * upwind (the scroll direction times the timestep); inside a superstorm the point is turned back by its
 * ring's rate, blended by GDC22's mask pow(1 - d / radius, 0.1). */
vec3 nubis_previous_position(vec3 world, float dt)
{
  vec3 scrolled = world - vec3(vec2(P.wind_dir_x, P.wind_dir_y), P.wind_upward_bias) * P.wind_speed * dt;
#if NUBIS_STORMS
  int count = min(int(P.storm_count), NUBIS_MAX_STORMS);
  for (int i = 0; i < count; i++) {
    vec4 shape = P.storm_shape[i];
    float dist = distance(world.xy, shape.xy);
    if (shape.w <= 0.0 || dist >= shape.z) {
      continue;
    }
    vec3 turned = vec3(nubis_rotate_about(world.xy, shape.xy, nubis_storm_turn_rate(world.xy, i) * dt), world.z);
    float mask = pow(clamp01(1.0 - dist / shape.z), NUBIS_MOTION_MASK_EXPONENT);
    scrolled = mix(scrolled, turned, mask);
  }
#endif
  return scrolled;
}
