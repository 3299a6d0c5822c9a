"""An OpenVDB cloud, sparse on the GPU: its active leaves packed into a brick atlas.

Nubis³ (Schneider, SIGGRAPH 2023) marches artist-modelled voxel clouds in real time from compressed,
sparse storage with a coarse level above it to skip empty space. Here that storage follows OpenVDB's own
layout: the grid is cut into its 8x8x8 leaf nodes, and only the leaves that hold cloud are kept, each as
a brick in a 3D atlas texture. An index texture, one texel per leaf of the grid's active bounding box,
names each leaf's brick (or none), so GPU memory follows the active voxels, not the bounding box, and
the index is itself the occupancy level the march skips empty leaves by.

Each brick stores its leaf's 8 voxels per side plus the first voxel of the next leaf along each axis
(9 per side): a trilinear sample between voxel centres i and i+1 then reads one brick only, and the
texture's own linear filter interpolates across leaf boundaries exactly as a dense grid would. A leaf is
kept when any of its 9x9x9 voxels holds cloud, so a sample near an empty leaf's far edge still sees the
cloud in the next one.

This module has no Blender and no GPU: it turns dense blocks of a grid (copied out of OpenVDB block by
block where the grid's tree has nodes, core/vdbread.py) into the atlas and index arrays, and back for
the tests.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import NubisError

LEAF = 8  # voxels per side of an OpenVDB leaf node
BRICK = LEAF + 1  # stored per side: the leaf and the first voxel of the next one
EMPTY = -1  # index value of a leaf with no brick
MAX_ATLAS_SIDE = 2048  # texels per side of a 3D texture that every GPU Blender runs on allows
# GPU memory a cloud may take before it is refused (the whole procedural sky is about 50 MB).
DEFAULT_GPU_LIMIT = 1024**3


@dataclass
class Bricks:
    """A grid's active leaves as bricks: `data` (count, 9, 9, 9) of values indexed [z, y, x], `index`
    (lz, ly, lx) int32 brick numbers (EMPTY where no cloud), `leaf_origin` the index coordinate (i, j, k)
    of leaf (0, 0, 0)'s first voxel."""

    data: np.ndarray
    index: np.ndarray
    leaf_origin: tuple[int, int, int]

    @property
    def count(self) -> int:
        return int(self.data.shape[0])

    @property
    def gpu_bytes(self) -> int:
        """The bricks in an atlas of their own and the index, as the GPU holds them."""
        bx, by, bz = atlas_shape(max(self.count, 1))
        return int(bx * by * bz * BRICK**3 * self.data.itemsize + self.index.size * 4)


def atlas_shape(count: int) -> tuple[int, int, int]:
    """Bricks per side (bx, by, bz) of a near-cubic atlas holding `count` bricks within MAX_ATLAS_SIDE
    texels per side."""
    most = MAX_ATLAS_SIDE // BRICK
    if count > most**3:
        raise NubisError(f"{count} bricks do not fit one 3D texture ({most**3} at most)")
    side = max(1, round(count ** (1 / 3)))
    while side**3 < count:
        side += 1
    return side, side, max(1, -(-count // (side * side)))


def gpu_bytes_estimate(bricks: int, leaves: int, bytes_per_value: int = 2) -> int:
    """The atlas (half floats by default) and the index for `bricks` kept out of `leaves`."""
    bx, by, bz = atlas_shape(max(bricks, 1))
    return bx * by * bz * BRICK**3 * bytes_per_value + leaves * 4


def occupied_leaves(dense: np.ndarray, tolerance: float = 0.0) -> np.ndarray:
    """Which leaves of a dense block (z, y, x; each side whole leaves plus one voxel of the next leaf) hold
    a value above `tolerance` in their 9x9x9 voxels: shaped (lz, ly, lx)."""
    if any((s - 1) % LEAF for s in dense.shape):
        raise ValueError(f"block {dense.shape} is not whole leaves plus one voxel")
    hot = dense > tolerance
    # Along each axis in turn, a leaf's last voxel also counts the next leaf's first; done one axis after
    # another, the edges and the corner of the 9x9x9 block are counted too.
    for axis in (2, 1, 0):
        n = hot.shape[axis] - 1
        own = np.take(hot, np.arange(n), axis=axis).copy()
        nxt = np.take(hot, np.arange(LEAF, n + 1, LEAF), axis=axis)
        last = [slice(None)] * 3
        last[axis] = slice(LEAF - 1, None, LEAF)
        own[tuple(last)] |= nxt
        hot = own
    nz, ny, nx = hot.shape
    return hot.reshape(nz // LEAF, LEAF, ny // LEAF, LEAF, nx // LEAF, LEAF).any(axis=(1, 3, 5))


class BrickPacker:
    """Packs a grid block by block: `add(block, leaf0)` takes a dense block (z, y, x) of whole leaves plus
    one voxel per axis whose first leaf is `leaf0` (lz, ly, lx) of the index, and keeps its occupied
    leaves; `finish()` returns the Bricks."""

    def __init__(
        self, leaves: tuple[int, int, int], leaf_origin: tuple[int, int, int], dtype=np.float16, expected: int = 0
    ):
        self.leaves = leaves  # (lz, ly, lx)
        self.leaf_origin = leaf_origin
        self.dtype = np.dtype(dtype)
        self.index = np.full(leaves, EMPTY, np.int32)
        # One array grown by a quarter when full, from the bricks expected (a read's plan knows at least
        # how many): the bricks are never held twice, as stacking a list of them at the end did.
        self._data = np.zeros((max(expected, 16), BRICK, BRICK, BRICK), self.dtype)
        self.count = 0

    @property
    def held_bytes(self) -> int:
        """The bricks packed so far."""
        return self.count * BRICK**3 * self.dtype.itemsize

    def add(self, block: np.ndarray, leaf0: tuple[int, int, int] = (0, 0, 0), tolerance: float = 0.0) -> None:
        occ = occupied_leaves(block, tolerance)
        z0, y0, x0 = leaf0
        kept = np.nonzero(occ)
        need = self.count + len(kept[0])
        if need > self._data.shape[0]:
            grown = np.zeros((max(need, self._data.shape[0] * 5 // 4),) + self._data.shape[1:], self.dtype)
            grown[: self.count] = self._data[: self.count]
            self._data = grown
        for lz, ly, lx in zip(*kept, strict=True):
            z, y, x = lz * LEAF, ly * LEAF, lx * LEAF
            self.index[z0 + lz, y0 + ly, x0 + lx] = self.count
            self._data[self.count] = block[z : z + BRICK, y : y + BRICK, x : x + BRICK]
            self.count += 1

    def finish(self) -> Bricks:
        data = self._data[: self.count]  # a view: the unused end of the last growth is not copied away
        self._data = np.zeros((0, BRICK, BRICK, BRICK), self.dtype)
        return Bricks(data, self.index, self.leaf_origin)


def layout(data: list[np.ndarray], dtype=np.float32, out=None) -> tuple[np.ndarray, tuple[int, int, int], list[int]]:
    """Several clouds' bricks in one atlas texture: the atlas (bz*9, by*9, bx*9) in `dtype` (the GPU upload's
    float32 by default), bricks per side (bx, by, bz), and each cloud's first brick number (its index values
    are offset by it). Brick n sits at (n % bx, n // bx % by, n // (bx * by)). Written one z slab of bricks
    at a time straight from each cloud's bricks: no copy of all of them is made on the way. `out`: a
    contiguous array of the atlas's size to write into (the GPU upload's own buffer), instead of a new one."""
    firsts, n = [], 0
    for d in data:
        firsts.append(n)
        n += d.shape[0]
    bx, by, bz = atlas_shape(max(n, 1))
    shape = (bz, BRICK, by, BRICK, bx, BRICK)
    if out is None:
        atlas = np.zeros(shape, dtype)
    else:
        atlas = out.reshape(shape)  # a view: `out` must be contiguous and of the atlas's size
        atlas.fill(0)
    per_slab = bx * by
    for first, d in zip(firsts, data, strict=True):
        done = 0
        while done < d.shape[0]:
            m = first + done  # the next brick's number
            z, in_slab = divmod(m, per_slab)
            take = min(d.shape[0] - done, per_slab - in_slab)
            chunk = d[done : done + take]
            if in_slab == 0 and take == per_slab:  # a whole slab: one strided copy
                atlas[z] = chunk.reshape(by, bx, BRICK, BRICK, BRICK).transpose(2, 0, 3, 1, 4)
            else:
                for k in range(take):
                    y, x = divmod(in_slab + k, bx)
                    atlas[z, :, y, :, x, :] = chunk[k]
            done += take
    return atlas.reshape(bz * BRICK, by * BRICK, bx * BRICK), (bx, by, bz), firsts


def pack_dense(dense: np.ndarray, origin: tuple[int, int, int] = (0, 0, 0), dtype=np.float16, tolerance=0.0) -> Bricks:
    """A whole dense grid (z, y, x) whose voxel (0, 0, 0) has index coordinate `origin` (i, j, k). One empty
    leaf goes before it along each axis: samples between the grid's first voxels and the outside (its
    background, 0) are read from the brick of that leaf."""
    leaves = tuple(-(-s // LEAF) + 1 for s in dense.shape)
    padded = np.zeros(tuple(n * LEAF + 1 for n in leaves), np.float32)
    padded[LEAF : LEAF + dense.shape[0], LEAF : LEAF + dense.shape[1], LEAF : LEAF + dense.shape[2]] = dense
    packer = BrickPacker(leaves, tuple(int(c) - LEAF for c in origin), dtype)
    packer.add(padded, (0, 0, 0), tolerance)
    return packer.finish()


def unpack(bricks: Bricks) -> np.ndarray:
    """The dense grid (z, y, x) the bricks hold, each leaf's 8 voxels per side, from index coordinate
    `leaf_origin` (the tests' round trip)."""
    lz, ly, lx = bricks.index.shape
    out = np.zeros((lz * LEAF, ly * LEAF, lx * LEAF), np.float32)
    for z, y, x in zip(*np.nonzero(bricks.index >= 0), strict=True):
        brick = bricks.data[int(bricks.index[z, y, x]), :LEAF, :LEAF, :LEAF]
        out[z * LEAF : (z + 1) * LEAF, y * LEAF : (y + 1) * LEAF, x * LEAF : (x + 1) * LEAF] = brick
    return out


def sample(atlas: np.ndarray, bricks_per_side, index: np.ndarray, first: int, ijk: np.ndarray) -> np.ndarray:
    """Trilinear samples at index coordinates `ijk` (..., 3) relative to the leaf origin (voxel centres at
    whole numbers), read as the shader reads them (shaders/nubis_vdb_lib.glsl): the leaf of the lower
    corner, then its brick in the atlas only. The GPU march's reference."""
    rel = np.asarray(ijk, np.float64)
    leaf = np.floor_divide(np.floor(rel).astype(np.int64), LEAF)
    lz, ly, lx = index.shape
    inside = (leaf >= 0).all(-1) & (leaf[..., 0] < lx) & (leaf[..., 1] < ly) & (leaf[..., 2] < lz)
    out = np.zeros(rel.shape[:-1], np.float64)
    if not inside.any():
        return out
    lf = leaf[inside]
    n = index[lf[:, 2], lf[:, 1], lf[:, 0]].astype(np.int64)
    keep = n >= 0
    local = rel[inside][keep] - lf[keep] * LEAF  # in [0, 8)
    n = n[keep] + first
    bx, by, _bz = bricks_per_side
    base = np.stack([n % bx, n // bx % by, n // (bx * by)], -1) * BRICK
    i0 = np.floor(local).astype(np.int64)
    t = local - i0
    vals = np.zeros(len(n))
    a = atlas.astype(np.float64)
    for dz in range(2):
        for dy in range(2):
            for dx in range(2):
                w = (
                    (t[:, 0] if dx else 1 - t[:, 0])
                    * (t[:, 1] if dy else 1 - t[:, 1])
                    * (t[:, 2] if dz else 1 - t[:, 2])
                )
                c = base + i0 + (dx, dy, dz)
                vals += w * a[c[:, 2], c[:, 1], c[:, 0]]
    sub = np.zeros(int(inside.sum()))
    sub[keep] = vals
    out[inside] = sub
    return out
