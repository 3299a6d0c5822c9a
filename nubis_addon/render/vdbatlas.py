"""The VDB clouds on the GPU: every cloud's bricks in one 3D atlas, every cloud's leaf index in one 3D
index texture (core/bricks.py, shaders/nubis_vdb_lib.glsl).

The textures hold the clouds' voxels only; where each cloud stands (its object's transform, its density
multiplier) travels in the uniform block (render/uniforms.py), so moving a cloud uploads nothing. The
textures are made again only when the set of clouds or their bricks change (a file reloaded, a grid
chosen), which the identity of their brick arrays tells exactly.
"""

from __future__ import annotations

import gpu
import numpy as np

from ..core import bricks, vdbplacement
from ..core.errors import NubisError
from ..core.sequence import human_bytes

ATLAS_FORMAT = "R16F"  # half floats: a density needs no more (Nubis³ compresses further)
INDEX_FORMAT = "R32F"  # brick numbers, exact up to 2^24


def _check_size(size, fmt: str) -> None:
    if max(size) > bricks.MAX_ATLAS_SIDE:
        raise NubisError(
            f"a VDB cloud's {'index' if fmt == INDEX_FORMAT else 'atlas'} would be {size[0]}x{size[1]}x{size[2]} "
            f"texels, over the {bricks.MAX_ATLAS_SIDE} per side a GPU texture may have: use fewer or coarser clouds"
        )


def _texture(arr: np.ndarray, fmt: str) -> gpu.types.GPUTexture:
    data = np.ascontiguousarray(arr, np.float32)
    size = tuple(reversed(data.shape))  # (W, H, D)
    _check_size(size, fmt)
    buf = gpu.types.Buffer("FLOAT", data.size, data.ravel())
    return gpu.types.GPUTexture(size, format=fmt, data=buf)


def _atlas_texture(placements) -> gpu.types.GPUTexture:
    """The bricks written straight into the upload's own float buffer (a numpy view of it): the atlas is
    never held twice on the host (docs/measurements.md#vdb-import)."""
    bx, by, bz = vdbplacement.gpu_layout(placements).per_side
    size = (bx * bricks.BRICK, by * bricks.BRICK, bz * bricks.BRICK)
    _check_size(size, ATLAS_FORMAT)
    buf = gpu.types.Buffer("FLOAT", size[0] * size[1] * size[2])
    bricks.layout([p.cloud.bricks.data for p in placements], out=np.asarray(buf))
    return gpu.types.GPUTexture(size, format=ATLAS_FORMAT, data=buf)


def combined_index(placements, layout: vdbplacement.GpuLayout) -> np.ndarray:
    """Every cloud's leaf index at its first slice of the shared index texture, brick numbers as they are
    within each cloud (the shader adds the cloud's first brick), -1 where a leaf is empty."""
    out = np.full(layout.index_shape, -1.0, np.float32)
    for p, z in zip(placements, layout.first_slice, strict=True):
        lz, ly, lx = p.cloud.bricks.index.shape
        out[z : z + lz, :ly, :lx] = p.cloud.bricks.index
    return out


def gpu_bytes(placements) -> int:
    """What the clouds' textures take on the GPU (half-float atlas, float index)."""
    return vdbplacement.shared_gpu_bytes(placements)


class VdbTextures:
    """The clouds' atlas and index textures, made again when the clouds' bricks change."""

    def __init__(self) -> None:
        self.key: tuple = ()
        self.atlas = None
        self.index = None
        self.bytes = 0

    def update(self, placements, limit: int = bricks.DEFAULT_GPU_LIMIT) -> None:
        key = tuple(id(p.cloud.bricks) for p in placements)
        if key == self.key and (self.atlas is not None or not placements):
            return
        # Nothing bound until both textures are made: a refusal leaves no clouds, never half of them.
        self.atlas = self.index = None
        self.bytes = 0
        self.key = ()
        if not placements:
            self.key = key
            return
        need = gpu_bytes(placements)
        if need > limit:
            raise NubisError(
                f"the VDB clouds need {human_bytes(need)} on the GPU together, over the {human_bytes(limit)} they "
                "may take: draw fewer of them, or coarser ones, or raise the budget in the preferences"
            )
        atlas_texture = _atlas_texture(placements)
        index_texture = _texture(combined_index(placements, vdbplacement.gpu_layout(placements)), INDEX_FORMAT)
        self.atlas, self.index, self.bytes, self.key = atlas_texture, index_texture, need, key
