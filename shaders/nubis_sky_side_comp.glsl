/* The sky volume's second channel (core/lightvolume.py, docs/viewport.md#light-volumes): the optical
 * depth sideways from each texel to the open sky, from the depths the first pass filled (`sky_depth`,
 * the depth from the domain's top down to each depth slice, sigma included). The density at a texel
 * is the depth its slice adds. Along 8 horizontal directions, at steps widening away from the point,
 * the depths to the edge of the cloud are summed; the texel stores the harmonic mean of each
 * direction's depth plus one, which the open sides dominate: a point in a tower's wall sees the sky
 * through the wall, where the column above it holds the whole tower. The plus one (a mean free path)
 * keeps the value smooth across a cloud's edge, where a bare depth falls to zero. One invocation
 * walks a column down its slices and keeps each direction's weighted sums of its taps' depths at the
 * last two slices, so every tap costs one fetch per slice (docs/measurements.md#light-volume-fills). */
const int NUBIS_SIDE_STEPS = 9;
const int NUBIS_SIDE_TAPS = 8 * NUBIS_SIDE_STEPS;

/* The offset in texels of step s outwards: 1, 2, 3, 4, 6, 8, 12, 16, 24, fine near the point, where the
 * open side usually is; the last is lightvolume.SIDE_REACH_TEXELS. (A formula rather than an array
 * constructor, which not every shading language Blender translates to takes.) */
int nubis_side_offset(int s)
{
  return s < 2 ? s + 1 : (3 + (s - 2) % 2) << ((s - 2) / 2);
}

void main()
{
  ivec3 size = imageSize(volume_out);
  ivec2 column = ivec2(gl_GlobalInvocationID.xy);
  if (column.x >= size.x || column.y >= size.y) {
    return;
  }
  ivec2 taps[NUBIS_SIDE_TAPS];
  float weights[NUBIS_SIDE_TAPS]; /* the horizontal length each tap stands for, in depth slices; 0 outside */
  /* Per direction, the taps' weighted depths from the top at the slice above and at this slice: a slice's
   * sideways depth is the weighted sum's difference across it (the same sum as the taps' differences). */
  float before[8];
  float here[8];
  for (int d = 0; d < 8; d++) {
    ivec2 dir = ivec2(round(vec2(cos(float(d) * 0.7853982), sin(float(d) * 0.7853982))));
    float step_len = length(vec2(dir) * side_scale.xy) / side_scale.z;
    int last = 0;
    float sum = 0.0;
    for (int s = 0; s < NUBIS_SIDE_STEPS; s++) {
      int i = d * NUBIS_SIDE_STEPS + s;
      taps[i] = column + dir * nubis_side_offset(s);
      bool inside = all(greaterThanEqual(taps[i], ivec2(0))) && all(lessThan(taps[i], size.xy));
      taps[i] = clamp(taps[i], ivec2(0), size.xy - 1);
      weights[i] = inside ? float(nubis_side_offset(s) - last) * step_len : 0.0;
      last = nubis_side_offset(s);
      sum += texelFetch(sky_depth, ivec3(taps[i], 0), 0).r * weights[i];
    }
    before[d] = sum;
    here[d] = sum;
  }
  for (int k = 0; k < size.z; k++) {
    int next_k = min(k + 1, size.z - 1);
    /* the density at slice k: the depth added from the slice above to the slice below, per slice */
    float span = float(max(next_k - max(k - 1, 0), 1));
    float inverse_sum = 0.0;
    for (int d = 0; d < 8; d++) {
      float below = 0.0;
      for (int s = 0; s < NUBIS_SIDE_STEPS; s++) {
        int i = d * NUBIS_SIDE_STEPS + s;
        below += texelFetch(sky_depth, ivec3(taps[i], next_k), 0).r * weights[i];
      }
      float tau = (below - before[d]) / span;
      before[d] = here[d];
      here[d] = below;
      inverse_sum += 1.0 / (tau + 1.0);
    }
    float above = texelFetch(sky_depth, ivec3(column, k), 0).r;
    imageStore(volume_out, ivec3(column, k), vec4(above, 8.0 / inverse_sum, 0.0, 0.0));
  }
}
