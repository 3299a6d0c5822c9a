/* One Z slice of the VDB bake: the same density the march uses, at voxel centres, full detail. */
void main()
{
  vec2 ij = floor(gl_FragCoord.xy);
  vec3 p = bake_origin.xyz + vec3(ij, bake_origin.w) * bake_voxel.x;
  NubisDensity d = nubis_density(p, false, 0.0);
  color = vec4(d.fine, d.coarse, 0.0, 1.0);
}
