/* One triangle covering the viewport; `uv` spans [0, 1] over the visible part. Stages drawn behind the
 * scene's objects put it on the far plane (NUBIS_FULLSCREEN_DEPTH 1.0, render/engine.py), where a
 * LESS_EQUAL depth test lets the clouds cover only the background. */
void main()
{
  uv = pos * 0.5 + 0.5;
  gl_Position = vec4(pos, NUBIS_FULLSCREEN_DEPTH, 1.0);
}
