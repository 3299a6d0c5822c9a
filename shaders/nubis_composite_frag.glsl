/* Upscale the low-resolution cloud buffer onto the viewport, premultiplied. */
void main()
{
  color = textureLod(cloud_buffer, uv, 0.0);
}
