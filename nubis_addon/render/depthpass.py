"""The depth pre-pass of F12's depth composition: the scene's surfaces drawn from the render camera into
a float image holding, per pixel, the world position of the first surface (w = 1 where one was drawn).
The split march (shaders/nubis_split_frag.glsl) divides each ray's clouds there (docs/sky.md#objects-in-the-clouds)."""

from __future__ import annotations

from collections.abc import Iterable
from contextlib import contextmanager

import gpu
import numpy as np
from gpu.types import GPUShaderCreateInfo, GPUStageInterfaceInfo
from gpu_extras.batch import batch_for_shader

from . import offscreens
from .gpu_context import release_at_exit

_VERTEX = """
void main()
{
  world = pos;
  gl_Position = view_proj * vec4(pos, 1.0);
}
"""
_FRAGMENT = """
void main()
{
  hit = vec4(world, 1.0);
}
"""
_shader: list[gpu.types.GPUShader] = []
release_at_exit(_shader.clear)


def _hit_shader() -> gpu.types.GPUShader:
    if not _shader:
        iface = GPUStageInterfaceInfo("nubis_depth_iface")
        iface.smooth("VEC3", "world")
        info = GPUShaderCreateInfo()
        info.push_constant("MAT4", "view_proj")
        info.vertex_in(0, "VEC3", "pos")
        info.vertex_out(iface)
        info.fragment_out(0, "VEC4", "hit")
        info.vertex_source(_VERTEX)
        info.fragment_source(_FRAGMENT)
        _shader.append(gpu.shader.create_from_info(info))
    return _shader[0]


@contextmanager
def scene_hits(surfaces: Iterable[tuple[np.ndarray, np.ndarray]], view_proj, width: int, height: int):
    """Each pixel's first surface among `surfaces` (world-space vertices (N, 3) and triangle indices
    (M, 3), one mesh at a time so a large scene is never held whole), seen through `view_proj` (the
    camera's own projection, its clipping planes included). Yields the GPU texture the split march reads
    and its pixels: (height, width, 4) float32, bottom row first, xyz the world position at the pixel's
    centre and w 1 where a surface was drawn, all 0 elsewhere. The texture lives until the block ends."""
    sh = _hit_shader()
    offscreen = offscreens.new_offscreen(width, height)
    matrix = np.asarray(view_proj, dtype=np.float64).reshape(4, 4)
    try:
        with offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
            gpu.state.depth_test_set("LESS_EQUAL")
            gpu.state.depth_mask_set(True)
            gpu.state.blend_set("NONE")
            gpu.state.face_culling_set("NONE")
            sh.bind()
            # GLSL reads columns; the matrix is row-major.
            sh.uniform_float("view_proj", matrix.T.astype(np.float32).ravel().tolist())
            for vertices, triangles in surfaces:
                if len(triangles) == 0:
                    continue
                pos = np.ascontiguousarray(vertices, dtype=np.float32)
                tris = np.ascontiguousarray(triangles, dtype=np.int32)
                batch_for_shader(sh, "TRIS", {"pos": pos}, indices=tris).draw(sh)
            pixels = offscreens.read_pixels(fb, width, height)
            gpu.state.depth_test_set("NONE")
            gpu.state.depth_mask_set(False)
        yield offscreen.texture_color, pixels
    finally:
        offscreen.free()
