"""Tiling noise textures for the Nubis cloud model, in pure numpy.

The set follows Guerrilla's layout (GPU Pro 7, S15, GDC22):

* ``lf``     128^3 RGBA: R = Perlin-Worley, G/B/A = inverted Worley fBm at increasing frequency.
* ``hf``     32^3 RGB: inverted Worley fBm at increasing frequency.
* ``curl``   128^2 RGB: divergence-free 2D curl noise, R/G = velocity, B = speed.
* ``cirrus`` 512^2 RGB: tiling high-altitude cloudscapes, R = cirrostratus, G = cirrus, B = cirrocumulus.

Every texture tiles in every axis because all lattices (Perlin gradients, Worley feature points) are
periodic in the tile and every neighbour lookup wraps. Everything is deterministic for a seed.

Arrays are indexed ``[z, y, x, channel]`` (3D) and ``[y, x, channel]`` (2D) and stored as ``uint8``.

The 3D generators evaluate the lattice "block-wise": a ``size^3`` volume with ``cells`` lattice cells per
axis is viewed as ``(cells, texels_per_cell)`` per axis, so per-cell quantities (gradients, feature points)
broadcast over the texels of their cell without any gather. That is why 3D sizes must be multiples of the
cell counts; the generator only uses powers of two.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import tempfile
import warnings
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import interrupt
from .errors import NubisError

__all__ = [
    "NOISE_VERSION",
    "FBM_WEIGHTS",
    "NoiseSet",
    "generate_noise_set",
    "load_or_generate",
    "cache_file_name",
    "cache_usage",
    "clear_cache",
    "evict",
    "CacheUsage",
    "CACHE_MAX_SEEDS",
    "CACHE_MAX_BYTES",
    "encode_texels",
    "decode_texels",
    "tiling_perlin_3d",
    "tiling_worley_3d",
    "perlin_fbm_3d",
    "worley_fbm_3d",
    "perlin_worley",
    "tiling_perlin_2d",
    "tiling_worley_2d",
    "perlin_fbm_2d",
    "worley_fbm_2d",
    "curl_2d",
    "encode_curl",
    "cirrus_layers",
    "normalise",
    "to_unorm8",
    "downsample2",
    "mip_chain",
    "mip_chain_nbytes",
]

#: Bump whenever any generator changes its output; cached files of other versions are regenerated.
NOISE_VERSION = 1

#: GPU Pro 7's low_freq_FBM and high_freq_FBM (the Habr implementation agrees): octave weights of every Worley fBm.
FBM_WEIGHTS = (0.625, 0.25, 0.125)

# Guerrilla's resolutions (S15, GPU Pro 7).
LF_SIZE = 128
HF_SIZE = 32
CURL_SIZE = 128
CIRRUS_SIZE = 512

# The sources give no cell counts (docs/sources.md#noise-octaves-and-cells): they double per channel and
# were tuned by eye on slices (connected blobs for R, billows for G/B/A).
LF_PERLIN_CELLS = 4  # lowest Perlin frequency: a few blobs per tile keeps Perlin's connectedness
LF_PERLIN_OCTAVES = 7  # GPU Pro 7 fig 4.5 "seven-octave Perlin"; octaves finer than 2 texels are dropped
LF_PERLIN_WORLEY_CELLS = 8  # the billows on the Perlin rims are a little smaller than the blobs
LF_PERLIN_WORLEY_STRENGTH = 1.5  # how far the billows dilate Perlin: visible cauliflower rims, blobs still dominate
LF_WORLEY_CELLS = (4, 8, 16)  # G, B, A
HF_WORLEY_CELLS = (2, 4, 8)  # R, G, B
CURL_CELLS = 4
CURL_OCTAVES = 3

RngLike = int | np.random.Generator | np.random.SeedSequence | Sequence[int] | None

# Independent random streams per texture/channel, so tuning one never reshuffles the others.
_STREAM_LF_PERLIN = 1
_STREAM_LF_PW_WORLEY = 2
_STREAM_LF_WORLEY = (3, 4, 5)
_STREAM_HF_WORLEY = (6, 7, 8)
_STREAM_CURL = 9
_STREAM_CIRRUS = 10


def _rng(seed: RngLike) -> np.random.Generator:
    if isinstance(seed, np.random.Generator):
        return seed
    return np.random.default_rng(seed)


def _stream(seed: int, stream: int) -> np.random.Generator:
    return np.random.default_rng([seed, stream])


def _fade(t: np.ndarray) -> np.ndarray:
    # Perlin 2002 quintic: C2-continuous, so the cascaded lerps leave no visible lattice creases.
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)


def _lerp2(n00: np.ndarray, n10: np.ndarray, n01: np.ndarray, n11: np.ndarray, u: np.ndarray, v: np.ndarray):
    """The lattice cell's corner values blended bilinearly by the faded offsets u, v."""
    a = n00 + u * (n10 - n00)
    b = n01 + u * (n11 - n01)
    return a + v * (b - a)


def _axes_cells(cells: int | Sequence[int], ndim: int) -> tuple[int, ...]:
    if isinstance(cells, int | np.integer):
        out = (int(cells),) * ndim
    else:
        out = tuple(int(c) for c in cells)
    if len(out) != ndim or any(c < 1 for c in out):
        raise ValueError(f"cells must be a positive integer or {ndim} positive integers, got {cells!r}")
    return out


def _block_layout(size: int, cells: tuple[int, ...]) -> tuple[int, ...]:
    for c in cells:
        if size % c:
            raise ValueError(f"size {size} must be a multiple of the cell count {c} so the lattice tiles exactly")
    return tuple(size // c for c in cells)


def _local(texels_per_cell: int) -> np.ndarray:
    # Texel centres: matches how a GPU samples the texture and never lands exactly on a lattice point.
    return ((np.arange(texels_per_cell, dtype=np.float32) + 0.5) / texels_per_cell).astype(np.float32)


# --------------------------------------------------------------------------------------------------------------
# 3D noise
# --------------------------------------------------------------------------------------------------------------

# Largest |value| of gradient noise with unit gradients in 3D is sqrt(3)/2; dividing by it maps to [0, 1].
_PERLIN3_RANGE = np.float32(np.sqrt(3.0) / 2.0)
_PERLIN2_RANGE = np.float32(np.sqrt(2.0) / 2.0)


def _perlin_3d_signed(size: int, cells: int | Sequence[int], rng: RngLike) -> np.ndarray:
    cz, cy, cx = _axes_cells(cells, 3)
    sz, sy, sx = _block_layout(size, (cz, cy, cx))
    g = _rng(rng).standard_normal((cz, cy, cx, 3)).astype(np.float32)
    g /= np.maximum(np.linalg.norm(g, axis=-1, keepdims=True), np.float32(1e-6))

    # 6D block view (sz, sy, sx, cz, cy, cx): texel-in-cell axes outermost, so the innermost loops run over
    # whole cell grids (long, contiguous) whatever the frequency; per-cell arrays get size-1 texel axes.
    ux = _local(sx).reshape(1, 1, sx, 1, 1, 1)
    uy = _local(sy).reshape(1, sy, 1, 1, 1, 1)
    uz = _local(sz).reshape(sz, 1, 1, 1, 1, 1)
    fx, fy, fz = _fade(ux), _fade(uy), _fade(uz)

    def corner(dz: int, dy: int, dx: int) -> np.ndarray:
        # np.roll by -d gives the gradient of the neighbouring corner, wrapping at the tile edge.
        return np.roll(g, (-dz, -dy, -dx), axis=(0, 1, 2)).reshape(1, 1, 1, cz, cy, cx, 3)

    # Lerp along x, then y, then z. The y and z parts of each corner's dot product do not depend on x, so
    # they are carried as lerped gradient components; only the last step touches full-size arrays.
    along_z = []
    for dz in (0, 1):
        rows, gzs = [], []
        for dy in (0, 1):
            g0, g1 = corner(dz, dy, 0), corner(dz, dy, 1)
            px = g0[..., 0] * ux + fx * (g1[..., 0] * (ux - 1.0) - g0[..., 0] * ux)
            gy = g0[..., 1] + fx * (g1[..., 1] - g0[..., 1])
            gz = g0[..., 2] + fx * (g1[..., 2] - g0[..., 2])
            rows.append(px + gy * (uy - dy))
            gzs.append(gz)
        row = rows[0] + fy * (rows[1] - rows[0])
        gz_row = gzs[0] + fy * (gzs[1] - gzs[0])
        along_z.append(row + gz_row * (uz - dz))
    out = along_z[0] + fz * (along_z[1] - along_z[0])
    return _unblock_3d(out, size)


def _unblock_3d(a: np.ndarray, size: int) -> np.ndarray:
    # (sz, sy, sx, cz, cy, cx) -> (cz, sz, cy, sy, cx, sx) -> [z, y, x]
    return np.ascontiguousarray(a.transpose(3, 0, 4, 1, 5, 2), dtype=np.float32).reshape(size, size, size)


def tiling_perlin_3d(size: int, cells: int | Sequence[int], rng: RngLike = None) -> np.ndarray:
    """Tiling 3D gradient (Perlin) noise, float32 ``(size, size, size)`` in [0, 1], indexed ``[z, y, x]``.

    ``cells`` lattice cells per tile (an int or ``(z, y, x)``); ``size`` must be a multiple of each.
    ``rng`` is a seed or a ``numpy.random.Generator``. The expected value is 0.5.
    """
    n = _perlin_3d_signed(size, cells, rng)
    return np.clip(0.5 + 0.5 * n / _PERLIN3_RANGE, 0.0, 1.0).astype(np.float32, copy=False)


def tiling_worley_3d(size: int, cells: int | Sequence[int], rng: RngLike = None) -> np.ndarray:
    """Tiling 3D Worley F1 noise, float32 ``(size, size, size)``, indexed ``[z, y, x]``.

    One feature point per cell (Worley 1996); the value is the distance to the nearest one in cell units,
    clipped to [0, 1] (distances above 1 cell are very rare). 0 at feature points, high on the cell walls;
    use ``1 - value`` for the billowy "inverted Worley" of GPU Pro 7, S15 and GDC22.
    """
    cz, cy, cx = _axes_cells(cells, 3)
    sz, sy, sx = _block_layout(size, (cz, cy, cx))
    pts = _rng(rng).random((cz, cy, cx, 3), dtype=np.float32)
    # Same block layout as the Perlin generator: (sz, sy, sx, cz, cy, cx).
    ux = _local(sx).reshape(1, 1, sx, 1, 1, 1)
    uy = _local(sy).reshape(1, sy, 1, 1, 1, 1)
    uz = _local(sz).reshape(sz, 1, 1, 1, 1, 1)
    best = np.full((sz, sy, sx, cz, cy, cx), np.inf, dtype=np.float32)
    tmp = np.empty_like(best)
    # With one jittered point per cell the nearest point is always within the 27-cell neighbourhood.
    for oz in (-1, 0, 1):
        for oy in (-1, 0, 1):
            for ox in (-1, 0, 1):
                p = np.roll(pts, (-oz, -oy, -ox), axis=(0, 1, 2))
                dx = ux - (ox + p[..., 0])
                dy = uy - (oy + p[..., 1])
                dz = uz - (oz + p[..., 2])
                # Adding the two smaller partial sums first keeps one full-size add per neighbour.
                np.add(dz * dz + dy * dy, dx * dx, out=tmp)
                np.minimum(best, tmp, out=best)
    del tmp
    np.sqrt(best, out=best)
    np.minimum(best, 1.0, out=best)
    return _unblock_3d(best, size)


def _octave_cells(size: int, base: int | Sequence[int], octaves: int, ndim: int) -> list[tuple[int, ...]]:
    # Octaves finer than 2 texels per cell can only alias into white noise, so they are dropped.
    limit = max(1, size // 2)
    cells = tuple(min(c, limit) for c in _axes_cells(base, ndim))
    out = []
    for o in range(octaves):
        c = tuple(ci * 2**o for ci in cells)
        if o > 0 and max(c) > limit:
            break
        out.append(c)
    return out


def _weights(n: int, gain: float) -> np.ndarray:
    w = np.array([gain**i for i in range(n)], dtype=np.float64)
    return w / w.sum()


def perlin_fbm_3d(
    size: int, cells: int | Sequence[int], octaves: int = 7, rng: RngLike = None, gain: float = 0.5
) -> np.ndarray:
    """Tiling Perlin fBm (GPU Pro 7), float32 in [0, 1] with mean 0.5.

    Octave ``o`` has ``cells * 2**o`` lattice cells and amplitude ``gain**o``; weights are normalised to sum 1.
    Octaves with fewer than 2 texels per cell are dropped.
    """
    gen = _rng(rng)
    cell_list = _octave_cells(size, cells, octaves, 3)
    w = _weights(len(cell_list), gain)
    acc = np.zeros((size, size, size), dtype=np.float32)
    for wi, c in zip(w, cell_list, strict=True):
        acc += np.float32(wi) * _perlin_3d_signed(size, c, gen)
    return np.clip(0.5 + 0.5 * acc / _PERLIN3_RANGE, 0.0, 1.0)


def worley_fbm_3d(
    size: int,
    cells: int | Sequence[int],
    rng: RngLike = None,
    weights: Sequence[float] = FBM_WEIGHTS,
    invert: bool = True,
) -> np.ndarray:
    """Tiling Worley fBm, float32 in [0, 1]: octave ``o`` has ``cells * 2**o`` cells and weight ``weights[o]``.

    With ``invert`` (default) each octave is ``1 - F1``, the billowy form (S15: "If it is inverted...
    it makes tightly packed billow shapes. We layered it like the standard Perlin fBm approach"; GPU Pro 7 alike).
    Octaves finer than 2 texels per cell are dropped and the remaining weights renormalised.
    """
    return _worley_fbm(size, cells, _rng(rng), weights, invert, 3)


def _worley_fbm(size: int, cells, gen, weights: Sequence[float], invert: bool, dims: int) -> np.ndarray:
    """worley_fbm_3d and worley_fbm_2d: the octaves of tiling Worley noise in `dims` dimensions, summed."""
    worley = tiling_worley_3d if dims == 3 else tiling_worley_2d
    cell_list = _octave_cells(size, cells, len(weights), dims)
    w = np.asarray(weights[: len(cell_list)], dtype=np.float64)
    w = w / w.sum()
    acc = np.zeros((size,) * dims, dtype=np.float32)
    for wi, c in zip(w, cell_list, strict=True):
        f1 = worley(size, c, gen)
        acc += np.float32(wi) * ((1.0 - f1) if invert else f1)
    return acc


def perlin_worley(perlin: np.ndarray, inverted_worley: np.ndarray, strength: float = 1.0) -> np.ndarray:
    """Perlin-Worley (docs/sources.md#perlin-worley): Perlin dilated by billowy (inverted) Worley, in [0, 1].

    ``remap(perlin, -strength * inverted_worley, 1, 0, 1)``.
    """
    # GPU Pro 7 / S15 "dilate", GDC22 "subtract the web like shapes of Worley": GPU Pro 7 remaps
    # Perlin with the Worley fBm as the old minimum. Using minus the *inverted* Worley as that minimum lowers
    # the bar exactly at the Worley feature points, so any Perlin iso-surface bulges outward into round
    # billows there while staying where Perlin put it between them: Perlin's connected blobs, cauliflower
    # rims. (The literal "+inverted Worley" minimum dents the rims inward instead.) Where Perlin is 1
    # the result stays 1, so cores keep full density.
    old_min = -np.float32(strength) * inverted_worley
    return np.clip((perlin - old_min) / (1.0 - old_min), 0.0, 1.0).astype(np.float32, copy=False)


# --------------------------------------------------------------------------------------------------------------
# 2D noise
# --------------------------------------------------------------------------------------------------------------


def _perlin_2d_at(x: np.ndarray, y: np.ndarray, grads: np.ndarray) -> np.ndarray:
    # Point evaluation (gather-based) so callers can domain-warp; x, y are in lattice units and wrap.
    cy, cx = grads.shape[:2]
    x = np.asarray(x, dtype=np.float32)
    y = np.asarray(y, dtype=np.float32)
    # Wrap once in float, then index a table padded by one wrapped row/column: the +1 corners need no modulo.
    x = x - np.float32(cx) * np.floor(x / np.float32(cx))
    y = y - np.float32(cy) * np.floor(y / np.float32(cy))
    # Float rounding can land a wrapped coordinate exactly on cx: clamp to the last cell (with t = 1 there,
    # which is the same point).
    ix = np.minimum(x.astype(np.int32), cx - 1)
    iy = np.minimum(y.astype(np.int32), cy - 1)
    tx = x - ix.astype(np.float32)
    ty = y - iy.astype(np.float32)
    padded = np.concatenate([grads, grads[:1]], axis=0)
    padded = np.concatenate([padded, padded[:, :1]], axis=1)
    gx = padded[..., 0].ravel()
    gy = padded[..., 1].ravel()
    k00 = iy * (cx + 1) + ix
    k10 = k00 + 1
    k01 = k00 + (cx + 1)
    k11 = k01 + 1
    tx1 = tx - 1.0
    ty1 = ty - 1.0
    n00 = gx.take(k00) * tx + gy.take(k00) * ty
    n10 = gx.take(k10) * tx1 + gy.take(k10) * ty
    n01 = gx.take(k01) * tx + gy.take(k01) * ty1
    n11 = gx.take(k11) * tx1 + gy.take(k11) * ty1
    return _lerp2(n00, n10, n01, n11, _fade(tx), _fade(ty)).astype(np.float32, copy=False)


def _grid_2d(size: int) -> tuple[np.ndarray, np.ndarray]:
    t = ((np.arange(size, dtype=np.float32) + 0.5) / size).astype(np.float32)
    return t[None, :], t[:, None]


def _perlin_2d_signed(
    size: int, cells: int | Sequence[int], rng: RngLike, warp: tuple[np.ndarray, np.ndarray] | None = None
) -> np.ndarray:
    cy, cx = _axes_cells(cells, 2)
    angle = _rng(rng).random((cy, cx)) * (2.0 * np.pi)
    grads = np.stack([np.cos(angle), np.sin(angle)], axis=-1).astype(np.float32)
    x, y = _grid_2d(size)
    if warp is not None:
        # Displacements are in tile units and must themselves tile, which keeps the result tiling.
        x = x + warp[0]
        y = y + warp[1]
    x, y = np.broadcast_arrays(x * cx, y * cy)
    return _perlin_2d_at(x, y, grads)


def tiling_perlin_2d(
    size: int,
    cells: int | Sequence[int],
    rng: RngLike = None,
    warp: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Tiling 2D gradient noise, float32 ``(size, size)`` in [0, 1], indexed ``[y, x]``.

    ``cells`` is an int or ``(cells_y, cells_x)``; unequal counts stretch the features (anisotropic noise).
    ``warp`` is an optional tiling displacement ``(dx, dy)`` in tile units (arrays broadcastable to
    ``(size, size)``) for domain warping.
    """
    n = _perlin_2d_signed(size, cells, rng, warp)
    return np.clip(0.5 + 0.5 * n / _PERLIN2_RANGE, 0.0, 1.0)


def perlin_fbm_2d(
    size: int,
    cells: int | Sequence[int],
    octaves: int = 6,
    rng: RngLike = None,
    gain: float = 0.5,
    warp: tuple[np.ndarray, np.ndarray] | None = None,
    signed: bool = False,
) -> np.ndarray:
    """Tiling 2D Perlin fBm, float32 ``(size, size)``; in [0, 1] (mean 0.5), or about [-1, 1] if ``signed``.

    Octave ``o`` has ``cells * 2**o`` cells (per axis) and amplitude ``gain**o``; octaves with fewer than 2
    texels per cell are dropped.
    """
    gen = _rng(rng)
    cell_list = _octave_cells(size, cells, octaves, 2)
    w = _weights(len(cell_list), gain)
    acc = np.zeros((size, size), dtype=np.float32)
    for wi, c in zip(w, cell_list, strict=True):
        acc += np.float32(wi) * _perlin_2d_signed(size, c, gen, warp)
    acc /= _PERLIN2_RANGE
    return acc if signed else np.clip(0.5 + 0.5 * acc, 0.0, 1.0)


def tiling_worley_2d(size: int, cells: int | Sequence[int], rng: RngLike = None) -> np.ndarray:
    """Tiling 2D Worley F1 noise, float32 ``(size, size)`` in [0, 1], indexed ``[y, x]``.

    Same conventions as :func:`tiling_worley_3d`; ``cells`` may be ``(cells_y, cells_x)`` and ``size`` must be a
    multiple of each.
    """
    cy, cx = _axes_cells(cells, 2)
    sy, sx = _block_layout(size, (cy, cx))
    pts = _rng(rng).random((cy, cx, 2), dtype=np.float32)
    ux = _local(sx).reshape(1, 1, 1, sx)
    uy = _local(sy).reshape(1, sy, 1, 1)
    best = np.full((cy, sy, cx, sx), np.inf, dtype=np.float32)
    for oy in (-1, 0, 1):
        for ox in (-1, 0, 1):
            p = np.roll(pts, (-oy, -ox), axis=(0, 1))
            dx = ux - (ox + p[..., 0].reshape(cy, 1, cx, 1))
            dy = uy - (oy + p[..., 1].reshape(cy, 1, cx, 1))
            np.minimum(best, dx * dx + dy * dy, out=best)
    return np.minimum(np.sqrt(best), 1.0).reshape(size, size)


def worley_fbm_2d(
    size: int,
    cells: int | Sequence[int],
    rng: RngLike = None,
    weights: Sequence[float] = FBM_WEIGHTS,
    invert: bool = True,
) -> np.ndarray:
    """Tiling 2D Worley fBm in [0, 1]; see :func:`worley_fbm_3d`."""
    return _worley_fbm(size, cells, _rng(rng), weights, invert, 2)


# --------------------------------------------------------------------------------------------------------------
# 2D noise in world space: hash lattices, so any scale and any extent work (the data field's layers)
# --------------------------------------------------------------------------------------------------------------


def _hash(ix: np.ndarray, iy: np.ndarray, seed: int) -> np.ndarray:
    """32-bit integer hash of lattice coordinates (a mix of multiply and xor-shift rounds)."""
    h = ix.astype(np.uint32) * np.uint32(0x27D4EB2D) ^ iy.astype(np.uint32) * np.uint32(0x165667B1)
    h = h + np.uint32((seed * 0x9E3779B9) & 0xFFFFFFFF)
    h = (h ^ (h >> np.uint32(15))) * np.uint32(0x2C1B3C6D)
    h = (h ^ (h >> np.uint32(12))) * np.uint32(0x297A2D39)
    return h ^ (h >> np.uint32(15))


def _unit(h: np.ndarray) -> np.ndarray:
    return (h >> np.uint32(8)).astype(np.float64) / float(1 << 24)


def _lattice(ix: np.ndarray, iy: np.ndarray, seed: int, reach: tuple[int, int]):
    """The hash of every lattice point from `reach[0]` to `reach[1]` cells around the points' own cells, once
    each: (x of its first column, y of its first row, hashes by row), or None when that box holds more
    points than are asked (scattered points: each hashes its own corners then)."""
    if ix.size == 0:
        return None
    lo, hi = reach
    x0, y0 = int(ix.min()) + lo, int(iy.min()) + lo
    w, h = int(ix.max()) + hi - x0 + 1, int(iy.max()) + hi - y0 + 1
    if w * h > ix.size:
        return None
    gy, gx = np.mgrid[y0 : y0 + h, x0 : x0 + w]
    return x0, y0, _hash(gx, gy, seed)


def world_perlin_2d(x: np.ndarray, y: np.ndarray, seed: int) -> np.ndarray:
    """Gradient noise, roughly in [-0.7, 0.7], one lattice cell per unit. A field's points share their
    cells' corners, so each corner's gradient is made once (the same numbers as per point, several times
    faster on a field of many points per cell)."""
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    ix, iy = x0.astype(np.int64), y0.astype(np.int64)
    lattice = _lattice(ix, iy, seed, (0, 1))
    if lattice is not None:
        lx, ly, h = lattice
        angle = _unit(h.ravel()) * (2 * np.pi)
        cos, sin = np.cos(angle), np.sin(angle)
        row = h.shape[1]
        at = (iy - ly) * row + (ix - lx)  # each point's own cell, in the flattened lattice

        def corner(dx: int, dy: int) -> np.ndarray:
            i = at + (dy * row + dx)
            return np.take(cos, i) * (fx - dx) + np.take(sin, i) * (fy - dy)

    else:

        def corner(dx: int, dy: int) -> np.ndarray:
            angle = _unit(_hash(ix + dx, iy + dy, seed)) * (2 * np.pi)
            return np.cos(angle) * (fx - dx) + np.sin(angle) * (fy - dy)

    return _lerp2(corner(0, 0), corner(1, 0), corner(0, 1), corner(1, 1), _fade(fx), _fade(fy))


def world_worley_2d(x: np.ndarray, y: np.ndarray, seed: int) -> np.ndarray:
    """Distance to the nearest of one random feature point per unit cell (F1), about [0, 1]. Feature points
    are made once per cell of the field's lattice, as for the gradient noise."""
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    first, second = _lattice(x0, y0, seed, (-1, 1)), _lattice(x0, y0, seed + 7919, (-1, 1))
    if first is not None:
        lx, ly, h = first
        gy, gx = np.mgrid[ly : ly + h.shape[0], lx : lx + h.shape[1]]
        feature_x, feature_y = (gx + _unit(h)).ravel(), (gy + _unit(second[2])).ravel()
        row = h.shape[1]
        at = (y0 - ly) * row + (x0 - lx)
    best = np.full(x.shape, 4.0)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if first is not None:
                i = at + (dy * row + dx)
                px, py = np.take(feature_x, i), np.take(feature_y, i)
            else:
                px = x0 + dx + _unit(_hash(x0 + dx, y0 + dy, seed))
                py = y0 + dy + _unit(_hash(x0 + dx, y0 + dy, seed + 7919))
            best = np.minimum(best, (x - px) ** 2 + (y - py) ** 2)
    return np.sqrt(best)


def world_fbm_2d(kind: str, x: np.ndarray, y: np.ndarray, octaves: int, seed: int) -> np.ndarray:
    """Octaves of doubling frequency and halving amplitude, normalised to [0, 1]."""
    total = np.zeros(x.shape)
    norm = 0.0
    for o in range(octaves):
        f, a = 2.0**o, 0.5**o
        if kind == "perlin":
            n = np.clip(0.5 + world_perlin_2d(x * f, y * f, seed + o) / 1.4, 0.0, 1.0)
        else:  # inverted Worley: round billows (S15, GDC22 "1 - Worley")
            n = 1.0 - np.clip(world_worley_2d(x * f, y * f, seed + o), 0.0, 1.0)
        total += a * n
        norm += a
    return total / norm


def curl_2d(potential: np.ndarray) -> np.ndarray:
    """Curl of a tiling 2D scalar potential: float32 ``(H, W, 2)`` holding ``(vx, vy) = (dP/dy, -dP/dx)``.

    Central differences with wrap-around, in units of potential per texel. The discrete divergence of the
    result (central differences with wrap) is zero up to rounding, because the difference operators commute.
    """
    p = np.asarray(potential, dtype=np.float32)
    d_dy = 0.5 * (np.roll(p, -1, axis=0) - np.roll(p, 1, axis=0))
    d_dx = 0.5 * (np.roll(p, -1, axis=1) - np.roll(p, 1, axis=1))
    return np.stack([d_dy, -d_dx], axis=-1)


def encode_curl(v: np.ndarray) -> np.ndarray:
    """Encode a curl field ``(H, W, 2)`` as float32 RGB in [0, 1]: ``0.5 + 0.5 * v / max|v|`` and the speed.

    Decode with ``rg * 2 - 1`` (docs/sources.md#curl-noise). Both components share one scale: scaling them
    separately would stretch the field anisotropically and make it divergent again. B is the speed normalised to [0, 1].
    """
    scale = float(np.max(np.abs(v))) or 1.0
    rg = 0.5 + 0.5 * v / scale
    speed = np.sqrt(np.sum(v * v, axis=-1))
    speed /= float(speed.max()) or 1.0
    return np.concatenate([rg, speed[..., None]], axis=-1).astype(np.float32)


# --------------------------------------------------------------------------------------------------------------
# Value helpers
# --------------------------------------------------------------------------------------------------------------


def normalise(a: np.ndarray, low: float = 0.002, high: float = 0.998) -> np.ndarray:
    """Stretch ``a`` so its ``low``/``high`` quantiles map to 0/1, clipped: full use of the 8 bits.

    A monotonic per-value map, so it preserves tiling. Quantiles come from a fixed strided subsample to stay
    fast on 128^3 volumes (deterministic all the same).
    """
    flat = a.reshape(-1)
    step = max(1, flat.size // 262144)
    lo, hi = np.quantile(flat[::step], [low, high])
    if hi - lo < 1e-12:
        return np.zeros_like(a, dtype=np.float32)
    return np.clip((a - lo) / (hi - lo), 0.0, 1.0).astype(np.float32, copy=False)


def to_unorm8(a: np.ndarray) -> np.ndarray:
    """Quantise [0, 1] floats to ``uint8`` with rounding (values outside are clipped)."""
    return np.clip(np.rint(np.asarray(a, dtype=np.float32) * 255.0), 0, 255).astype(np.uint8)


def _remap(v: np.ndarray, lo: float | np.ndarray, hi: float | np.ndarray) -> np.ndarray:
    return np.clip((v - lo) / (hi - lo), 0.0, 1.0)


# --------------------------------------------------------------------------------------------------------------
# Mips
# --------------------------------------------------------------------------------------------------------------


def _half(n: int) -> int:
    return max(1, n // 2)


def downsample2(arr: np.ndarray) -> np.ndarray:
    """Halve every spatial axis of a tiling texture with a 2-texel box filter; the last axis is channels.

    Works for 2D ``(H, W, C)`` and 3D ``(D, H, W, C)`` arrays. Output texel ``i`` averages input texels
    ``2i`` and ``2i + 1`` (wrapping, which only matters for odd sizes); axes of size 1 stay 1. Integer inputs
    are averaged in float and rounded back to the input dtype.
    """
    a = np.asarray(arr)
    if a.ndim < 2:
        raise ValueError("downsample2 needs at least one spatial axis plus a trailing channel axis")
    out = a.astype(np.float32)
    for axis in range(a.ndim - 1):
        n = out.shape[axis]
        m = _half(n)
        even = np.take(out, np.arange(m) * 2 % n, axis=axis)
        odd = np.take(out, (np.arange(m) * 2 + 1) % n, axis=axis)
        out = 0.5 * (even + odd)
    if np.issubdtype(a.dtype, np.integer):
        info = np.iinfo(a.dtype)
        return np.clip(np.rint(out), info.min, info.max).astype(a.dtype)
    return out.astype(a.dtype, copy=False)


def mip_chain(arr: np.ndarray, levels: int | None = None) -> list[np.ndarray]:
    """Mip levels of a tiling texture, level 0 (``arr`` itself) first.

    ``levels`` is the number of arrays returned, level 0 included; ``None`` gives the full chain down to a
    single texel. Each level is :func:`downsample2` of the previous one.
    """
    a = np.asarray(arr)
    full = _full_levels(a.shape[:-1])
    n = full if levels is None else int(levels)
    if n < 1:
        raise ValueError(f"levels must be at least 1, got {levels}")
    n = min(n, full)
    chain = [a]
    for _ in range(n - 1):
        chain.append(downsample2(chain[-1]))
    return chain


def _full_levels(spatial: tuple[int, ...]) -> int:
    levels = 1
    while max(spatial) > 1:
        spatial = tuple(_half(s) for s in spatial)
        levels += 1
    return levels


def mip_chain_nbytes(arr: np.ndarray) -> int:
    """Bytes of the full mip chain of ``arr`` (level 0 included), computed without building it."""
    spatial = tuple(arr.shape[:-1])
    per_texel = arr.shape[-1] * arr.dtype.itemsize
    total = 0
    for _ in range(_full_levels(spatial)):
        total += int(np.prod(spatial)) * per_texel
        spatial = tuple(_half(s) for s in spatial)
    return total


# --------------------------------------------------------------------------------------------------------------
# The set
# --------------------------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class NoiseSet:
    """The four noise textures, ``uint8``, made read-only on construction so the set can be shared safely.

    ``lf``: ``(128, 128, 128, 4)`` ``[z, y, x, c]``; ``hf``: ``(32, 32, 32, 3)``; ``curl``: ``(128, 128, 3)``
    ``[y, x, c]``; ``cirrus``: ``(512, 512, 3)``. ``seed`` is the seed they were generated from.
    """

    lf: np.ndarray
    hf: np.ndarray
    curl: np.ndarray
    cirrus: np.ndarray
    seed: int

    def __post_init__(self) -> None:
        for name in _ARRAY_NAMES:
            a = getattr(self, name)
            if not isinstance(a, np.ndarray) or a.dtype != np.uint8:
                raise TypeError(f"NoiseSet.{name} must be a uint8 numpy array")
            a.setflags(write=False)

    def arrays(self) -> dict[str, np.ndarray]:
        """The textures by name (``lf``, ``hf``, ``curl``, ``cirrus``)."""
        return {name: getattr(self, name) for name in _ARRAY_NAMES}

    @property
    def nbytes(self) -> int:
        """Total bytes of the four textures (level 0 only)."""
        return sum(a.nbytes for a in self.arrays().values())

    @property
    def nbytes_with_mips(self) -> int:
        """Total bytes of the four textures with full mip chains."""
        return sum(mip_chain_nbytes(a) for a in self.arrays().values())


_ARRAY_NAMES = ("lf", "hf", "curl", "cirrus")


def _check_size(name: str, size: int, minimum: int) -> int:
    size = int(size)
    if size < minimum or size & (size - 1):
        raise ValueError(f"{name} must be a power of two of at least {minimum}, got {size}")
    return size


def _cap(cells: int, size: int) -> int:
    return max(1, min(cells, size // 2))


def _make_lf(seed: int, size: int) -> np.ndarray:
    out = np.empty((size, size, size, 4), dtype=np.uint8)
    perlin = perlin_fbm_3d(size, _cap(LF_PERLIN_CELLS, size), LF_PERLIN_OCTAVES, _stream(seed, _STREAM_LF_PERLIN))
    # The Perlin fBm is compressed around 0.5; stretch it first so the dilation sees the full range.
    perlin = normalise(perlin)
    billows = worley_fbm_3d(size, _cap(LF_PERLIN_WORLEY_CELLS, size), _stream(seed, _STREAM_LF_PW_WORLEY))
    billows = normalise(billows)
    out[..., 0] = to_unorm8(normalise(perlin_worley(perlin, billows, LF_PERLIN_WORLEY_STRENGTH)))
    del perlin, billows
    for ch, (cells, stream) in enumerate(zip(LF_WORLEY_CELLS, _STREAM_LF_WORLEY, strict=True), start=1):
        w = worley_fbm_3d(size, _cap(cells, size), _stream(seed, stream))
        out[..., ch] = to_unorm8(normalise(w))
    return out


def _make_hf(seed: int, size: int) -> np.ndarray:
    out = np.empty((size, size, size, 3), dtype=np.uint8)
    for ch, (cells, stream) in enumerate(zip(HF_WORLEY_CELLS, _STREAM_HF_WORLEY, strict=True)):
        w = worley_fbm_3d(size, _cap(cells, size), _stream(seed, stream))
        out[..., ch] = to_unorm8(normalise(w))
    return out


def _make_curl(seed: int, size: int) -> np.ndarray:
    potential = perlin_fbm_2d(
        size, _cap(CURL_CELLS, size), CURL_OCTAVES, _stream(seed, _STREAM_CURL), gain=0.5, signed=True
    )
    return to_unorm8(encode_curl(curl_2d(potential)))


def cirrus_layers(size: int = CIRRUS_SIZE, rng: RngLike = None) -> np.ndarray:
    """The three tiling cirrus-level cloudscapes (GDC22), float32 ``(size, size, 3)`` in [0, 1]; their look
    is the project's own (docs/sources.md#cirrus-textures).

    R = cirrostratus (soft veil with long streaks), G = cirrus (thin fibrous strands), B = cirrocumulus (small
    puffy cells in patches). ``size`` must be a power of two of at least 64.
    """
    gen = _rng(rng)
    s = size / 512.0  # keeps the look the same when tests shrink the texture

    def c(n: float) -> int:
        return max(1, int(round(n * max(s, 1 / 64))))

    # A large-scale warp bends the streaks so they do not look ruled; it tiles, so the layers tile.
    warp = (
        0.03 * perlin_fbm_2d(size, 2, 3, gen, signed=True),
        0.06 * perlin_fbm_2d(size, 3, 3, gen, signed=True),
    )

    # R: cirrostratus, a thin veil: broad soft sheets with faint streaks (Perlin fBm stretched 6:1 along x).
    sheet = perlin_fbm_2d(size, c(3), 5, gen, gain=0.5, warp=warp)
    streaks = perlin_fbm_2d(size, (c(12), c(2)), 6, gen, gain=0.55, warp=warp)
    veil = normalise(0.6 * normalise(sheet) + 0.4 * normalise(streaks))

    # G: cirrus, fibrous strands: ridged (1 - |n|)^p noise stretched 12:1 gives thin bright fibres; a contrasty
    # low-frequency mask gathers them into separate tufts with clear sky between.
    ridge = np.zeros((size, size), dtype=np.float32)
    w = _weights(3, 0.6)
    for o, wi in enumerate(w):
        n = perlin_fbm_2d(size, (c(24) * 2**o, c(2) * 2**o), 1, gen, warp=warp, signed=True)
        ridge += np.float32(wi) * (1.0 - np.minimum(np.abs(n), 1.0)) ** 6
    glow = perlin_fbm_2d(size, (c(8), c(2)), 4, gen, warp=warp)
    mask = normalise(perlin_fbm_2d(size, (c(4), c(2)), 3, gen, warp=warp))
    fibres = (0.7 * normalise(ridge) + 0.3 * normalise(glow)) * _remap(mask, 0.4, 0.9)
    fibres = normalise(fibres)

    # B: cirrocumulus, small puffy cells (inverted Worley) with dark gaps, in ripple rows and
    # patches.
    cells = worley_fbm_2d(size, c(32), gen, weights=(0.75, 0.25))
    puffs = _remap(normalise(cells), 0.15, 1.0) ** 1.2
    rows = 0.55 + 0.45 * perlin_fbm_2d(size, (c(16), c(4)), 2, gen)
    patch = normalise(perlin_fbm_2d(size, c(4), 4, gen, warp=warp))
    puffs = normalise(puffs * rows * _remap(patch, 0.2, 0.7))
    return np.stack([veil, fibres, puffs], axis=-1)


def _make_cirrus(seed: int, size: int) -> np.ndarray:
    return to_unorm8(cirrus_layers(size, _stream(seed, _STREAM_CIRRUS)))


def generate_noise_set(
    seed: int = 0,
    lf_size: int = LF_SIZE,
    hf_size: int = HF_SIZE,
    curl_size: int = CURL_SIZE,
    cirrus_size: int = CIRRUS_SIZE,
) -> NoiseSet:
    """Generate the whole noise set for ``seed`` (a non-negative integer).

    The sizes exist so tests can build tiny sets quickly; they must be powers of two (LF/HF >= 8, curl >= 16,
    cirrus >= 64). Each texture has its own random stream derived from the seed.
    """
    seed = _check_seed(seed)
    lf_size = _check_size("lf_size", lf_size, 8)
    hf_size = _check_size("hf_size", hf_size, 8)
    curl_size = _check_size("curl_size", curl_size, 16)
    cirrus_size = _check_size("cirrus_size", cirrus_size, 64)
    return NoiseSet(
        lf=_make_lf(seed, lf_size),
        hf=_make_hf(seed, hf_size),
        curl=_make_curl(seed, curl_size),
        cirrus=_make_cirrus(seed, cirrus_size),
        seed=seed,
    )


def _check_seed(seed: int) -> int:
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)


# --------------------------------------------------------------------------------------------------------------
# Cache
# --------------------------------------------------------------------------------------------------------------

#: The cache keeps at most this many noise sets (seeds) ...
CACHE_MAX_SEEDS = 8
#: ... and at most this many bytes of them; the least recently used sets are deleted first. A compressed set
#: is about 5.4 MB, so the byte bound (64 MiB) only bites when sets of another format or size are around.
CACHE_MAX_BYTES = 64 * 2**20

# How the arrays are stored: each channel as a plane, every texel replaced by its residual from the 3D
# Lorenzo predictor (the sum of its already-decoded neighbours' differences, i.e. successive differences
# along every axis, wrapping modulo 256), then deflated in the .npz. Smooth noise leaves small residuals
# that deflate to about 60% of the raw bytes, where deflating the raw bytes saves only 5%. Lossless: the
# digest is taken of the decoded arrays.
_ENCODING = "planar-lorenzo-1"
_DEFLATE_LEVEL = 1

_EXPECTED = {
    "lf": (LF_SIZE, LF_SIZE, LF_SIZE, 4),
    "hf": (HF_SIZE, HF_SIZE, HF_SIZE, 3),
    "curl": (CURL_SIZE, CURL_SIZE, 3),
    "cirrus": (CIRRUS_SIZE, CIRRUS_SIZE, 3),
}
# Exactly the names this module writes (any version, any seed), so eviction and Clear Cache never touch a
# file of the user's that only looks alike ("noise_vs_signal_study.npz"). Temporary files are mkstemp's:
# ".<cache name stem>-<8 of [a-z0-9_]>.tmp".
_CACHE_NAME = re.compile(r"noise_v\d+_s\d+\.npz")
_TEMP_NAME = re.compile(r"\.noise_v\d+_s\d+-[a-z0-9_]{8}\.tmp")


def cache_file_name(seed: int = 0) -> str:
    """File name of the cached set for ``seed`` (the current :data:`NOISE_VERSION` is part of it)."""
    return f"noise_v{NOISE_VERSION}_s{_check_seed(seed)}.npz"


def _digest(arrays: dict[str, np.ndarray], seed: int) -> str:
    # zip CRCs are not always checked by np.load, so a content hash catches silent corruption too.
    h = hashlib.sha256(f"nubis-noise v{NOISE_VERSION} s{seed}".encode())
    for name in _ARRAY_NAMES:
        a = np.ascontiguousarray(arrays[name])
        h.update(f"{name}{a.shape}{a.dtype.str}".encode())
        h.update(a.data)
    return h.hexdigest()


def encode_texels(a: np.ndarray) -> np.ndarray:
    """``[..., channel]`` uint8 texels as channel planes of Lorenzo residuals (exactly undone by
    :func:`decode_texels`)."""
    p = np.ascontiguousarray(np.moveaxis(a, -1, 0))
    for axis in range(1, p.ndim):
        p = np.diff(p, axis=axis, prepend=np.zeros_like(np.take(p, [0], axis=axis)))
    return p


def decode_texels(p: np.ndarray) -> np.ndarray:
    """The texels :func:`encode_texels` encoded: running sums along every axis, modulo 256."""
    for axis in range(1, p.ndim):
        p = np.cumsum(p, axis=axis, dtype=np.uint8)
    return np.ascontiguousarray(np.moveaxis(p, 0, -1))


def _read_cache(path: Path, seed: int) -> tuple[NoiseSet | None, bool]:
    """The set in ``path`` if it is whole and right, and whether it is in the old uncompressed format."""
    try:
        with np.load(path, allow_pickle=False) as z:
            if int(z["version"]) != NOISE_VERSION or int(z["seed"]) != seed:
                return None, False
            encoded = "encoding" in z.files
            if encoded and str(z["encoding"]) != _ENCODING:
                return None, False
            arrays = {}
            for name, shape in _EXPECTED.items():
                a = z[name]
                if a.dtype != np.uint8 or a.shape != ((shape[-1], *shape[:-1]) if encoded else shape):
                    return None, False
                arrays[name] = decode_texels(a) if encoded else a
            if str(z["digest"]) != _digest(arrays, seed):
                return None, False
    except Exception:  # missing, unreadable or corrupt (zip, header, digest): all just mean "regenerate"
        return None, False
    return NoiseSet(seed=seed, **arrays), not encoded


def _savez_fast(f, **arrays: np.ndarray) -> None:
    """An ``.npz`` as np.load reads it, deflated at zlib's fastest level: three times faster to write
    than np.savez_compressed's default level, for 4% more bytes on the noise."""
    with zipfile.ZipFile(f, "w", zipfile.ZIP_DEFLATED, compresslevel=_DEFLATE_LEVEL) as zf:
        for name, a in arrays.items():
            with zf.open(f"{name}.npy", "w", force_zip64=True) as member:
                np.lib.format.write_array(member, np.asanyarray(a), allow_pickle=False)


def _write_cache(path: Path, ns: NoiseSet) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with interrupt.deferred():  # made and registered together: an interrupted run leaves no partial file
        fd, tmp_name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}-", suffix=".tmp")
        tmp = Path(tmp_name)
        interrupt.register(tmp)
    try:
        arrays = ns.arrays()
        with os.fdopen(fd, "wb") as f:
            _savez_fast(
                f,
                version=np.int64(NOISE_VERSION),
                seed=np.int64(ns.seed),
                encoding=np.array(_ENCODING),
                digest=np.array(_digest(arrays, ns.seed)),
                **{name: encode_texels(a) for name, a in arrays.items()},
            )
            f.flush()
            os.fsync(f.fileno())
        # mkstemp makes 0600 files; the cache holds nothing private. (A fixed mode, because reading the umask
        # means briefly changing it for the whole process, Blender's other threads included.)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink()
        interrupt.unregister(tmp)


def _named(folder: Path, pattern: re.Pattern) -> list[Path]:
    """The files in `folder` whose whole name matches `pattern` (none for a missing folder)."""
    try:
        return [folder / n for n in os.listdir(folder) if pattern.fullmatch(n)]
    except OSError:
        return []


def _cache_files(folder: Path) -> list[tuple[Path, os.stat_result]]:
    out = []
    for p in _named(folder, _CACHE_NAME):
        with contextlib.suppress(OSError):  # another process may delete it meanwhile
            out.append((p, p.stat()))
    return out


@dataclass(frozen=True)
class CacheUsage:
    """What the noise cache holds: ``sets`` files of ``nbytes`` bytes in ``folder``."""

    folder: Path
    sets: int
    nbytes: int


def cache_usage(cache_dir: str | os.PathLike) -> CacheUsage:
    """How many noise sets the cache folder holds and their bytes on disk (0 and 0 for a missing folder)."""
    folder = Path(cache_dir).expanduser()
    files = _cache_files(folder)
    return CacheUsage(folder, len(files), sum(st.st_size for _p, st in files))


def clear_cache(cache_dir: str | os.PathLike) -> CacheUsage:
    """Delete every cached noise set (of any version) and any temporary file an interrupted write left;
    returns what was freed. Nothing else in the folder is touched. A set in use stays valid: it is in memory."""
    folder = Path(cache_dir).expanduser()
    freed = 0
    count = 0
    for p, st in _cache_files(folder) + [(p, None) for p in _named(folder, _TEMP_NAME)]:
        try:
            p.unlink()
        except FileNotFoundError:
            continue
        except OSError as err:
            raise NubisError(
                f"cannot delete the cached noise '{p}' ({err.strerror}): check the folder's permissions"
            ) from None
        if st is not None:
            freed += st.st_size
            count += 1
    return CacheUsage(folder, count, freed)


def evict(cache_dir: str | os.PathLike, max_sets: int = CACHE_MAX_SEEDS, max_bytes: int = CACHE_MAX_BYTES) -> None:
    """Hold the cache to ``max_sets`` files and ``max_bytes``: the most recently used sets stay (a read
    or a write marks a set used by its modification time), the others are deleted."""
    files = sorted(_cache_files(Path(cache_dir).expanduser()), key=lambda f: f[1].st_mtime_ns, reverse=True)
    kept = total = 0
    for p, st in files:
        if kept < max_sets and total + st.st_size <= max_bytes:
            kept += 1
            total += st.st_size
            continue
        with contextlib.suppress(OSError):  # gone already, or in use on a system that refuses
            p.unlink()


def _touch(path: Path) -> None:
    with contextlib.suppress(OSError):  # a read-only cache still serves its sets
        os.utime(path)


def load_or_generate(
    cache_dir: str | os.PathLike,
    seed: int = 0,
    max_sets: int = CACHE_MAX_SEEDS,
    max_bytes: int = CACHE_MAX_BYTES,
) -> NoiseSet:
    """Load the full-size set for ``seed`` from ``cache_dir``, or generate it and cache it there.

    The cache is one compressed ``.npz`` per seed, named by :func:`cache_file_name`, and holds at most
    ``max_sets`` sets and ``max_bytes`` (:data:`CACHE_MAX_SEEDS`, :data:`CACHE_MAX_BYTES`): writing a new
    set deletes the least recently used beyond that. A missing, unreadable, corrupt, wrong-shaped or
    other-version file is regenerated and replaced atomically (temporary file in the same folder, then
    ``os.replace``), so readers never see a partial file; a set in the earlier uncompressed format is read
    and rewritten compressed. If the folder cannot be written, the generated set is still returned and a
    warning explains why the cache was skipped.
    """
    seed = _check_seed(seed)
    path = Path(cache_dir).expanduser() / cache_file_name(seed)
    cached, old_format = _read_cache(path, seed)
    if cached is not None and not old_format:
        _touch(path)
        return cached
    ns = cached if cached is not None else generate_noise_set(seed)
    try:
        _write_cache(path, ns)
        evict(path.parent, max_sets, max_bytes)
    except OSError as err:
        reason = err.strerror or str(err)
        warnings.warn(
            f"Nubis could not write the noise cache '{path}' ({reason}); the noise textures will be "
            "regenerated next time. Choose a writable cache folder to avoid this.",
            RuntimeWarning,
            stacklevel=2,
        )
    return ns


def fbm_mean(texture: np.ndarray) -> float:
    """The mean of a uint8 noise texture's fBm (its first three channels weighted by FBM_WEIGHTS), in [0, 1]."""
    channels = np.asarray(texture[..., :3], np.float64).reshape(-1, 3).mean(axis=0) / 255.0
    return float(channels @ np.asarray(FBM_WEIGHTS))
