/* Full-screen triangle on the far plane: with a LESS_EQUAL depth test the clouds only cover the
 * background, never objects in front of them (GDC22's culling; docs/sources.md#pixel-culling). */
void main()
{
  uv = pos * 0.5 + 0.5;
  gl_Position = vec4(pos, 1.0, 1.0);
}
