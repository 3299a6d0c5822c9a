"""The VDB bake on the GPU: the viewport's own density shader, evaluated one Z slice at a time."""

from __future__ import annotations

from collections.abc import Callable

import gpu
import numpy as np

from ..core.bakeplan import BakePlan
from .engine import CloudGPU, fullscreen_batch, read_pixels, shader


def bake_density(
    gpu_inputs: CloudGPU, plan: BakePlan, progress: Callable[[float], None] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fine density, storm glow emission and rain absorption at every voxel centre, each shaped (z, y, x)."""
    nx, ny, nz = plan.dims
    vol = np.empty((nz, ny, nx), np.float32)
    glow = np.empty((nz, ny, nx), np.float32)
    absorption = np.empty((nz, ny, nx), np.float32)
    defines = gpu_inputs.defines()
    sh = shader("bake", defines)
    batch = fullscreen_batch("bake", defines)
    offscreen = gpu.types.GPUOffScreen(nx, ny, format="RGBA32F")
    try:
        with offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            gpu.state.blend_set("NONE")
            for k in range(nz):
                gpu_inputs.bind(sh)
                sh.uniform_float("bake_origin", (*plan.origin, float(k)))
                sh.uniform_float("bake_voxel", (plan.voxel_size, 0.0, 0.0, 0.0))
                batch.draw(sh)
                px = read_pixels(fb, nx, ny)
                vol[k] = px[..., 0]
                glow[k] = px[..., 1]
                absorption[k] = px[..., 2]
                if progress:
                    progress((k + 1) / nz)
    finally:
        offscreen.free()
    return vol, glow, absorption
