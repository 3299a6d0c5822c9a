/* One triangle covering the viewport; `uv` spans [0, 1] over the visible part. */
void main()
{
  uv = pos * 0.5 + 0.5;
  gl_Position = vec4(pos, 0.0, 1.0);
}
