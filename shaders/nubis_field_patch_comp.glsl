/* Writes a rectangle of new field texels into a field texture in place (render/engine.py,
 * CloudGPU.patch_field): a brush stroke changes a few hundred texels of a field that may hold millions,
 * so only the stroke's rectangle travels to the GPU (docs/painting.md#live). */
void main()
{
  ivec2 texel = ivec2(gl_GlobalInvocationID.xy);
  if (texel.x >= patch_size.x || texel.y >= patch_size.y) {
    return;
  }
#if NUBIS_PATCH_LAYERED
  /* The cloud layers' fields are one array texture, a slice a layer (docs/layers.md). */
  imageStore(field_out, ivec3(patch_offset + texel, patch_layer), texelFetch(patch_texels, texel, 0));
#else
  imageStore(field_out, patch_offset + texel, texelFetch(patch_texels, texel, 0));
#endif
}
