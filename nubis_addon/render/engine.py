"""The GPU side of Nubis: one set of shaders and inputs, three consumers (viewport, offscreen render, bake)."""

from __future__ import annotations

from collections.abc import Callable

import gpu
import numpy as np
from gpu.types import GPUShaderCreateInfo, GPUStageInterfaceInfo
from gpu_extras.batch import batch_for_shader

from ..core import noise
from ..core.state import CloudState
from . import uniforms
from .sources import CLOUD_LIBS, assemble, read_shader
from .textures import NoiseTextures, field_texture

CLOUD_SAMPLERS = (
    ("FLOAT_2D", "field_a"),
    ("FLOAT_2D", "field_b"),
    ("FLOAT_2D", "field_c"),
    ("FLOAT_3D", "noise_lf"),
    ("FLOAT_3D", "noise_lf_mip1"),
    ("FLOAT_3D", "noise_hf"),
    ("FLOAT_2D", "noise_curl"),
    ("FLOAT_2D", "noise_cirrus"),
)
_shaders: dict[str, gpu.types.GPUShader] = {}
_batches: dict[str, gpu.types.GPUBatch] = {}


def _create_info(
    stage: str,
    push_constants: tuple[tuple[str, str], ...],
    extra_samplers: tuple[tuple[str, str], ...] = (),
    storms: bool = False,
) -> GPUShaderCreateInfo:
    iface = GPUStageInterfaceInfo(f"nubis_{stage}_iface")
    iface.smooth("VEC2", "uv")
    info = GPUShaderCreateInfo()
    # Two permutations: the superstorm terms cost a software rasterizer ~40 % even with no storm in the
    # scene, so skies without storms compile them out.
    info.define("NUBIS_STORMS", "1" if storms else "0")
    info.typedef_source(read_shader("nubis_params.glsl"))
    info.uniform_buf(0, "NubisParams", "P")
    if stage == "motion":
        info.uniform_buf(1, "NubisMotionCameras", "C")
    for slot, (kind, name) in enumerate(CLOUD_SAMPLERS + extra_samplers):
        info.sampler(slot, kind, name)
    for kind, name in push_constants:
        info.push_constant(kind, name)
    info.vertex_in(0, "VEC2", "pos")
    info.vertex_out(iface)
    info.fragment_out(0, "VEC4", "color")
    info.vertex_source(read_shader("nubis_fullscreen_vert.glsl"))
    info.fragment_source(assemble(*CLOUD_LIBS, f"nubis_{stage}_frag.glsl"))
    return info


# Each stage: its push constants and any samplers beyond the cloud inputs. Fragment source is
# shaders/nubis_<stage>_frag.glsl, compiled after the cloud libraries.
# The bake reads the lighting library too, for the glow grid.
STAGES: dict[str, tuple[tuple[tuple[str, str], ...], tuple[tuple[str, str], ...]]] = {
    "raymarch": ((("MAT4", "inv_view_proj"), ("VEC4", "eye")), ()),
    "bake": ((("VEC4", "bake_origin"), ("VEC4", "bake_voxel")), ()),
    "motion": ((("MAT4", "inv_view_proj"), ("VEC4", "eye")), ()),
}


def shader(stage: str, storms: bool = False) -> gpu.types.GPUShader:
    key = f"{stage}:{int(storms)}"
    if key not in _shaders:
        push_constants, extra_samplers = STAGES[stage]
        _shaders[key] = gpu.shader.create_from_info(_create_info(stage, push_constants, extra_samplers, storms))
    return _shaders[key]


def fullscreen_batch(stage: str, storms: bool = False) -> gpu.types.GPUBatch:
    key = f"{stage}:{int(storms)}"
    if key not in _batches:
        _batches[key] = batch_for_shader(shader(stage, storms), "TRIS", {"pos": ((-1, -1), (3, -1), (-1, 3))})
    return _batches[key]


class CloudGPU:
    """GPU inputs of the cloud shaders, updated from a CloudState."""

    def __init__(self, noise_set: noise.NoiseSet):
        self.noise = NoiseTextures(noise_set)
        self._field_arrays: tuple = ()
        self.field_a = self.field_b = self.field_c = None
        self.storms = False
        self.ubo = None

    def update(self, state: CloudState) -> None:
        # Fields are replaced, never edited in place, by everything that changes them: holding the
        # arrays and comparing identity is exact, and costs nothing per redraw.
        arrays = (state.field_a, state.field_b, state.field_c)
        if len(self._field_arrays) != 3 or any(a is not b for a, b in zip(arrays, self._field_arrays, strict=True)):
            self.field_a, self.field_b, self.field_c = (field_texture(a) for a in arrays)
            self._field_arrays = arrays
        self.ubo = gpu.types.GPUUniformBuf(uniforms.pack(state).tobytes())
        self.storms = bool(state.storms)

    def bind(self, sh: gpu.types.GPUShader) -> None:
        sh.bind()
        sh.uniform_block("P", self.ubo)
        textures = {
            "field_a": self.field_a,
            "field_b": self.field_b,
            "field_c": self.field_c,
            "noise_lf": self.noise.lf,
            "noise_lf_mip1": self.noise.lf_mip1,
            "noise_hf": self.noise.hf,
            "noise_curl": self.noise.curl,
            "noise_cirrus": self.noise.cirrus,
        }
        for _kind, name in CLOUD_SAMPLERS:
            sh.uniform_sampler(name, textures[name])


def draw_clouds(gpu_inputs: CloudGPU, inv_view_proj, eye) -> None:
    """Draw the clouds into the bound framebuffer (premultiplied radiance, alpha). `eye` is the
    perspective camera's position with w = 1, or w = 0 for an orthographic view."""
    draw_stage("raymarch", gpu_inputs, {"inv_view_proj": inv_view_proj, "eye": tuple(eye)})


def draw_offscreen(width: int, height: int, draw: Callable[[], None]) -> np.ndarray:
    """Run `draw` into a cleared float offscreen of this size; its pixels, bottom row first."""
    offscreen = gpu.types.GPUOffScreen(width, height, format="RGBA32F")
    try:
        with offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=(0.0, 0.0, 0.0, 0.0))
            gpu.state.blend_set("NONE")
            draw()
            return read_pixels(fb, width, height)
    finally:
        offscreen.free()


def draw_stage(
    stage: str,
    gpu_inputs: CloudGPU,
    uniforms: dict | None = None,
    blocks: dict | None = None,
    samplers: dict | None = None,
) -> None:
    """One full-screen draw of a cloud stage with the cloud inputs bound plus the stage's own."""
    sh = shader(stage, gpu_inputs.storms)
    gpu_inputs.bind(sh)
    for name, value in (uniforms or {}).items():
        sh.uniform_float(name, value)
    for name, value in (blocks or {}).items():
        sh.uniform_block(name, value)
    for name, value in (samplers or {}).items():
        sh.uniform_sampler(name, value)
    fullscreen_batch(stage, gpu_inputs.storms).draw(sh)


def render_motion(gpu_inputs: CloudGPU, inv_view_proj, eye, prev_view_proj, width: int, height: int) -> np.ndarray:
    """Per-pixel motion vectors (dx, dy in pixels per timestep), cloud distance and alpha, top row first.
    `prev_view_proj` is the camera one timestep earlier (the same matrix for a still camera)."""
    # mathutils matrices are row-major; GLSL reads columns.
    cams = np.array([np.array(inv_view_proj.inverted()).T, np.array(prev_view_proj).T], np.float32)
    cameras = gpu.types.GPUUniformBuf(cams.tobytes())
    px = draw_offscreen(
        width,
        height,
        lambda: draw_stage("motion", gpu_inputs, {"inv_view_proj": inv_view_proj, "eye": tuple(eye)}, {"C": cameras}),
    )
    # Rows run top-down in the result, so a motion up the screen becomes negative y, as in image space.
    out = px[::-1].copy()
    out[..., 1] *= -1.0
    return out


def render_offscreen(gpu_inputs: CloudGPU, inv_view_proj, eye, width: int, height: int, tile: int = 256) -> np.ndarray:
    """Scene-linear premultiplied RGBA, shape (height, width, 4), top row first.

    The frame is drawn in tiles so that one huge draw call never stalls a software rasterizer.
    """

    def tiles() -> None:
        for y in range(0, height, tile):
            for x in range(0, width, tile):
                gpu.state.scissor_test_set(True)
                gpu.state.scissor_set(x, y, min(tile, width - x), min(tile, height - y))
                draw_clouds(gpu_inputs, inv_view_proj, eye)
        gpu.state.scissor_test_set(False)

    return draw_offscreen(width, height, tiles)[::-1].copy()


def read_pixels(fb, width: int, height: int) -> np.ndarray:
    """Float RGBA of the framebuffer, (height, width, 4), bottom row first.

    Blender's Buffer exports its memory with reversed strides to the buffer protocol (seen in 5.0.1),
    so we view the C-ordered memory with the strides it really has instead of trusting them.
    """
    view = np.asarray(fb.read_color(0, 0, width, height, 4, 0, "FLOAT"))
    if view.dtype != np.float32 or view.size != width * height * 4:
        raise RuntimeError(f"unexpected framebuffer read-back {view.dtype} {view.shape}")
    if view.flags.c_contiguous and view.shape == (height, width, 4):
        return view.copy()
    strides = (width * 16, 16, 4)
    return np.lib.stride_tricks.as_strided(view, shape=(height, width, 4), strides=strides).copy()
