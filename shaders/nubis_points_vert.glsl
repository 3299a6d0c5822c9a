/* One point per 4x4 block of the history, on the pixel `points.xy` of the block (`points.zw`: the
 * history's size): the still viewport's resolve touches only the pixels that change. */
void main()
{
  vec2 pixel = pos * 4.0 + points.xy + 0.5;
  uv = pixel / points.zw;
  gl_Position = vec4(uv * 2.0 - 1.0, 0.0, 1.0);
}
