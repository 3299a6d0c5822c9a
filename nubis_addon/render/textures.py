"""GPU textures for the cloud shaders: the noise volumes with their mip levels, and the data-field images.

Blender's Python API uploads no mip chains, so every level the march reads is a texture of its own
(3D noise), or a region of one atlas texture (the 2D cirrus, which needs its whole chain).
"""

from __future__ import annotations

import gpu
import numpy as np

from ..core import noise

# Mip levels built for the 3D noise the march reads at a distance (GPU Pro 7, GDC22: "MIP level 1").
LF_LEVELS = 3
HF_LEVELS = 2
CIRRUS_MIN_SIZE = 8  # the smallest cirrus mip level, in texels


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


def cirrus_atlas(cirrus: np.ndarray) -> np.ndarray:
    """The cirrus texture's mip chain in one 2D array (H, W, C): level 0 (padded by one wrapped texel)
    at the left, levels 1.. stacked upwards in a column to its right, each padded the same way. The
    layout is what nubis_cirrus_level in shaders/nubis_density_lib.glsl reads."""
    size = cirrus.shape[0]
    if cirrus.shape[1] != size or size & (size - 1):
        raise ValueError(f"the cirrus texture must be square with a power-of-two size, not {cirrus.shape[:2]}")
    levels = noise.mip_chain(cirrus, cirrus_levels(size))
    atlas = np.zeros((size + 1, size + 1 + size // 2 + 1, cirrus.shape[2]), cirrus.dtype)
    atlas[: size + 1, : size + 1] = _pad_wrap(levels[0], 2)
    y = 0
    for level in levels[1:]:
        n = level.shape[0] + 1
        atlas[y : y + n, size + 1 : size + 1 + n] = _pad_wrap(level, 2)
        y += n
    return atlas


def cirrus_levels(size: int) -> int:
    return int(np.log2(size // CIRRUS_MIN_SIZE)) + 1


class NoiseTextures:
    """The noise texture set (S15, GPU Pro 7) on the GPU: 8 bits per channel, as Guerrilla shipped it, with the
    mip levels the march reads at a distance."""

    def __init__(self, noise_set: noise.NoiseSet):
        lf = noise.mip_chain(noise_set.lf, LF_LEVELS)
        hf = noise.mip_chain(noise_set.hf, HF_LEVELS)
        atlas = cirrus_atlas(noise_set.cirrus)
        padded = {
            "lf": _pad_wrap(lf[0], 3),
            "lf_mip1": _pad_wrap(lf[1], 3),
            "lf_mip2": _pad_wrap(lf[2], 3),
            "hf": _pad_wrap(hf[0], 3),
            "hf_mip1": _pad_wrap(hf[1], 3),
            "curl": _pad_wrap(noise_set.curl, 2),
        }
        self.textures = {name: texture_from_array(a, "RGBA8") for name, a in padded.items()}
        self.textures["cirrus"] = texture_from_array(atlas, "RGBA8")
        for name, tex in self.textures.items():
            setattr(self, name, tex)
        self.seed = noise_set.seed
        # Texture sizes are compile-time constants of the shaders, not textureSize() queries.
        cirrus_size = noise_set.cirrus.shape[0]
        self.defines = {
            "NUBIS_LF_SIZE": padded["lf"].shape[0],
            "NUBIS_LF1_SIZE": padded["lf_mip1"].shape[0],
            "NUBIS_LF2_SIZE": padded["lf_mip2"].shape[0],
            "NUBIS_HF_SIZE": padded["hf"].shape[0],
            "NUBIS_HF1_SIZE": padded["hf_mip1"].shape[0],
            "NUBIS_CURL_SIZE": padded["curl"].shape[0],
            "NUBIS_CIRRUS_SIZE": cirrus_size,
            "NUBIS_CIRRUS_LEVELS": cirrus_levels(cirrus_size),
            "NUBIS_CIRRUS_ATLAS": f"ivec2({atlas.shape[1]}, {atlas.shape[0]})",
            # The detail fBm's mean, which a cheap sample erodes by in place of the detail noise.
            "NUBIS_HF_FBM_MEAN": f"{noise.fbm_mean(noise_set.hf):.6f}",
        }
        # Four 8-bit channels per texel on the GPU.
        self.gpu_bytes = sum(int(np.prod(a.shape[:-1])) * 4 for a in (*padded.values(), atlas))


def field_texture(field: np.ndarray) -> gpu.types.GPUTexture:
    """A data-field image (H, W, 4) float, bottom row first, as a float texture."""
    return texture_from_array(np.nan_to_num(field.astype(np.float32), nan=0.0, posinf=0.0, neginf=0.0), "RGBA32F")


def field_stack_texture(fields: list[np.ndarray]) -> gpu.types.GPUTexture:
    """The cloud layers' data-field images (each (H, W, 4) float, bottom row first, all one size) as one 2D
    array texture, a slice per layer (docs/layers.md): one sampler for up to four layers. No layer: one
    empty slice, so the sampler is always bound."""
    if not fields:
        fields = [np.zeros((1, 1, 4), np.float32)]
    stack = np.stack([np.nan_to_num(f.astype(np.float32), nan=0.0, posinf=0.0, neginf=0.0) for f in fields])
    n, h, w = stack.shape[:3]
    buf = gpu.types.Buffer("FLOAT", stack.size, np.ascontiguousarray(stack).ravel())
    return gpu.types.GPUTexture((w, h), layers=n, format="RGBA32F", data=buf)


def sky_texture(env: np.ndarray) -> gpu.types.GPUTexture:
    """An equirectangular environment (H, W, 3) float, bottom row first (core/sky.py), as a float texture."""
    return texture_from_array(np.nan_to_num(np.asarray(env, np.float32)[..., :3], nan=0.0, posinf=0.0), "RGBA32F")
