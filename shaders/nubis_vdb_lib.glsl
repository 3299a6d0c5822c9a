/* Artists' OpenVDB clouds (core/vdbread.py), sparse on the GPU as Nubis³ keeps its voxel clouds
 * (Schneider, SIGGRAPH 2023): each cloud's active leaves are bricks of 9x9x9 values in one 3D atlas
 * (vdb_atlas), and an index texture (vdb_index) names the brick of every leaf of its box, or -1 for
 * an empty one, which is also the level the march skips empty space by (core/bricks.py). Compiled in
 * with NUBIS_VDB only; the uniform block holds each cloud's placement (render/uniforms.py). */

#if NUBIS_VDB
/* Voxels per side of a leaf, and of a brick (the leaf and the next leaf's first voxel). */
const float NUBIS_VDB_LEAF = 8.0;
const float NUBIS_VDB_BRICK = 9.0;

/* Cloud c's density at p, in the clouds' own unit (extinction / P.density_sigma): 0 outside its box and
 * in its empty leaves. The sample between two voxel centres is the atlas' own trilinear filter inside one
 * brick, as a dense grid's would be. */
float nubis_vdb_cloud(int c, vec3 p)
{
  vec4 lo = P.vdb_box_lo[c];
  vec4 hi = P.vdb_box_hi[c];
  if (any(lessThan(p, lo.xyz)) || any(greaterThan(p, hi.xyz))) {
    return 0.0;
  }
  vec4 q = vec4(p, 1.0);
  vec3 ijk = vec3(dot(P.vdb_index_x[c], q), dot(P.vdb_index_y[c], q), dot(P.vdb_index_z[c], q));
  vec4 leaves = P.vdb_leaves[c];
  vec3 leaf = floor(floor(ijk) / NUBIS_VDB_LEAF);
  if (any(lessThan(leaf, vec3(0.0))) || any(greaterThanEqual(leaf, leaves.xyz))) {
    return 0.0;
  }
  float n = texelFetch(vdb_index, ivec3(leaf) + ivec3(0, 0, int(leaves.w)), 0).r;
  if (n < 0.0) {
    return 0.0;
  }
  n += hi.w; /* the cloud's first brick in the shared atlas */
  vec3 per_side = P.vdb_atlas.xyz;
  vec3 slot = vec3(mod(n, per_side.x), mod(floor(n / per_side.x), per_side.y), floor(n / (per_side.x * per_side.y)));
  vec3 uvw = (slot * NUBIS_VDB_BRICK + (ijk - leaf * NUBIS_VDB_LEAF) + 0.5) / (per_side * NUBIS_VDB_BRICK);
  return textureLod(vdb_atlas, uvw, 0.0).r * lo.w;
}

/* Every VDB cloud's density at p; `h` the height fraction in the box of the last cloud found there (the
 * light model's ambient and powder read it as they read the layer's). */
float nubis_vdb_density(vec3 p, out float h)
{
  float sum = 0.0;
  h = 0.0;
  for (int c = 0; c < NUBIS_MAX_VDB; c++) {
    if (float(c) >= P.vdb_count) {
      break;
    }
    float v = nubis_vdb_cloud(c, p);
    if (v > 0.0) {
      sum += v;
      h = clamp01((p.z - P.vdb_box_lo[c].z) / max(P.vdb_box_hi[c].z - P.vdb_box_lo[c].z, 1.0));
    }
  }
  return sum;
}

/* The part of the ray (origin + t dir) inside any VDB cloud's box: (t in, t out), in > out for none. */
vec2 nubis_vdb_span(vec3 origin, vec3 dir)
{
  vec2 span = vec2(1e30, -1e30);
  vec3 inv = 1.0 / dir;
  for (int c = 0; c < NUBIS_MAX_VDB; c++) {
    if (float(c) >= P.vdb_count) {
      break;
    }
    vec3 a = (P.vdb_box_lo[c].xyz - origin) * inv;
    vec3 b = (P.vdb_box_hi[c].xyz - origin) * inv;
    vec3 near = min(a, b), far = max(a, b);
    float t0 = max(max(near.x, near.y), near.z);
    float t1 = min(min(far.x, far.y), far.z);
    if (t0 <= t1 && t1 > 0.0) {
      span = vec2(min(span.x, max(t0, 0.0)), max(span.y, t1));
    }
  }
  return span;
}
#endif
