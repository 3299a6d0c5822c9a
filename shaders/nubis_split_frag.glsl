/* F12's camera view with the scene's objects in the clouds (docs/sky.md#objects-in-the-clouds). Each
 * pixel's ray is split at the scene's first surface, which the depth pre-pass left in `scene_hit`
 * (world position, w = 1 where a surface was drawn): `near` holds the clouds in front of it, which the
 * veil the engine renders lays over the objects; `far` those behind it, which the World shows where a
 * surface lets the sky through (an edge's sky samples). A pixel whose centre sees the sky takes its
 * nearest neighbour's surface: an edge's samples that meet it are veiled as far as it, not by the
 * clouds behind it. */
float nubis_scene_split(vec3 origin, vec3 dir)
{
  ivec2 px = ivec2(gl_FragCoord.xy);
  vec4 own = texelFetch(scene_hit, px, 0);
  if (own.w > 0.5) {
    return max(dot(own.xyz - origin, dir), 0.0);
  }
  ivec2 last = textureSize(scene_hit, 0) - 1;
  float split = NUBIS_NO_SPLIT;
  for (int y = -1; y <= 1; y++) {
    for (int x = -1; x <= 1; x++) {
      vec4 hit = texelFetch(scene_hit, clamp(px + ivec2(x, y), ivec2(0), last), 0);
      if (hit.w > 0.5) {
        split = min(split, max(dot(hit.xyz - origin, dir), 0.0));
      }
    }
  }
  return split;
}

void main()
{
  vec3 origin, dir;
  nubis_view_ray(uv, inv_view_proj, eye, origin, dir);
  near = nubis_shade_ray_parts(origin, dir, gl_FragCoord.xy, nubis_scene_split(origin, dir), far);
}
