"""GPU textures for the cloud shaders: the noise volumes and the data-field images."""

from __future__ import annotations

import gpu
import numpy as np

from ..core import noise


def _pad_wrap(arr: np.ndarray, spatial_axes: int) -> np.ndarray:
    """Append one wrapped texel per spatial axis: Python textures clamp, and the shaders map
    repeating coordinates onto this padded layout (nubis_tile_uvw)."""
    pad = [(0, 1)] * spatial_axes + [(0, 0)]
    return np.pad(arr, pad, mode="wrap")


def _to_rgba(arr: np.ndarray) -> np.ndarray:
    if arr.shape[-1] == 4:
        return arr
    fill = np.zeros(arr.shape[:-1] + (4 - arr.shape[-1],), arr.dtype)
    return np.concatenate([arr, fill], axis=-1)


def texture_from_array(arr: np.ndarray, fmt: str) -> gpu.types.GPUTexture:
    """(D, H, W, C) or (H, W, C) array, indexed z/y/x, to a 3D or 2D texture; uint8 is normalised."""
    data = _to_rgba(arr)
    data = data.astype(np.float32) / 255.0 if data.dtype == np.uint8 else data.astype(np.float32)
    size = tuple(reversed(data.shape[:-1]))  # (W, H[, D])
    buf = gpu.types.Buffer("FLOAT", data.size, np.ascontiguousarray(data).ravel())
    return gpu.types.GPUTexture(size, format=fmt, data=buf)


class NoiseTextures:
    """The texture set of SPEC 1.4.1 on the GPU: 8 bits per channel, as Guerrilla shipped it."""

    def __init__(self, noise_set: noise.NoiseSet):
        lf_mip1 = noise.downsample2(noise_set.lf.astype(np.float32))
        self.lf = texture_from_array(_pad_wrap(noise_set.lf, 3), "RGBA8")
        self.lf_mip1 = texture_from_array(_pad_wrap(np.round(lf_mip1).astype(np.uint8), 3), "RGBA8")
        self.hf = texture_from_array(_pad_wrap(noise_set.hf, 3), "RGBA8")
        self.curl = texture_from_array(_pad_wrap(noise_set.curl, 2), "RGBA8")
        self.cirrus = texture_from_array(_pad_wrap(noise_set.cirrus, 2), "RGBA8")
        self.seed = noise_set.seed
        self.gpu_bytes = sum(
            int(np.prod(t)) * 4
            for t in (
                np.add(noise_set.lf.shape[:3], 1),
                np.add(lf_mip1.shape[:3], 1),
                np.add(noise_set.hf.shape[:3], 1),
                np.add(noise_set.curl.shape[:2], 1),
                np.add(noise_set.cirrus.shape[:2], 1),
            )
        )


def field_texture(field: np.ndarray) -> gpu.types.GPUTexture:
    """A data-field image (H, W, 4) float, bottom row first, as a float texture."""
    return texture_from_array(np.nan_to_num(field.astype(np.float32), nan=0.0, posinf=0.0, neginf=0.0), "RGBA32F")
