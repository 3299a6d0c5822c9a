"""Live painting's upload: a rectangle of a field array written into its GPU texture in place
(shaders/nubis_field_patch_comp.glsl), so a brush dab costs its rectangle, not the field (docs/painting.md#live)."""

from __future__ import annotations

import gpu
import numpy as np
from gpu.types import GPUShaderCreateInfo

from .gpu_context import release_at_exit
from .sources import read_shader

GROUP = 8
_shader: list = []
release_at_exit(_shader.clear)


def _patch_shader(layered: bool) -> gpu.types.GPUShader:
    """The patch shader for a 2D texture (the cirrus) or a 2D array texture (the cloud layers' fields)."""
    if not _shader:
        for kind in ("FLOAT_2D", "FLOAT_2D_ARRAY"):
            info = GPUShaderCreateInfo()
            info.define("NUBIS_PATCH_LAYERED", "1" if kind.endswith("ARRAY") else "0")
            info.sampler(0, "FLOAT_2D", "patch_texels")
            info.image(0, "RGBA32F", kind, "field_out", qualifiers={"WRITE"})
            info.push_constant("IVEC2", "patch_offset")
            info.push_constant("IVEC2", "patch_size")
            info.push_constant("INT", "patch_layer")
            info.local_group_size(GROUP, GROUP, 1)
            info.compute_source(read_shader("nubis_field_patch_comp.glsl"))
            _shader.append(gpu.shader.create_from_info(info))
    return _shader[int(layered)]


def patch(texture: gpu.types.GPUTexture, array: np.ndarray, rect: tuple[int, int, int, int], layer: int = -1) -> int:
    """Write `array[r0:r1, c0:c1]` ((H, W, 4) float32, bottom row first, as the texture was made from)
    into `texture` at the same texels, of its slice `layer` for an array texture (-1: a 2D texture);
    returns the bytes uploaded."""
    r0, r1, c0, c1 = rect
    block = np.ascontiguousarray(array[r0:r1, c0:c1], np.float32)
    h, w = block.shape[:2]
    if not (h and w):
        return 0
    src = gpu.types.GPUTexture((w, h), format="RGBA32F", data=gpu.types.Buffer("FLOAT", block.size, block.ravel()))
    sh = _patch_shader(layer >= 0)
    sh.bind()
    sh.uniform_sampler("patch_texels", src)
    sh.image("field_out", texture)
    sh.uniform_int("patch_offset", (c0, r0))
    sh.uniform_int("patch_size", (w, h))
    sh.uniform_int("patch_layer", max(layer, 0))
    gpu.compute.dispatch(sh, -(-w // GROUP), -(-h // GROUP), 1)
    return block.nbytes
