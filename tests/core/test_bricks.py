"""The brick atlas of an OpenVDB cloud (core/bricks.py): exact round trip of the active voxels, the leaves
kept (a leaf whose far edge reads the next leaf's cloud included), samples equal to a dense grid's
trilinear interpolation, and the atlas' size."""

from __future__ import annotations

import numpy as np
import pytest
from vdb_helpers import trilinear

from nubis_addon.core import bricks
from nubis_addon.core.errors import NubisError


def _sparse(shape, fill=0.02, seed=3):
    rng = np.random.default_rng(seed)
    dense = np.zeros(shape, np.float32)
    hot = rng.random(shape) < fill
    dense[hot] = rng.random(int(hot.sum())).astype(np.float32) + 0.01
    return dense


def test_the_active_voxels_round_trip_exactly():
    dense = _sparse((37, 21, 50))
    packed = bricks.pack_dense(dense, origin=(-7, 3, 100), dtype=np.float32)
    back = bricks.unpack(packed)[8:, 8:, 8:]  # one empty leaf before the grid along each axis
    np.testing.assert_array_equal(back[:37, :21, :50], dense)
    assert not back[37:].any() and not back[:, 21:].any() and not back[:, :, 50:].any()
    assert packed.leaf_origin == (-15, -5, 92) and packed.index.shape == (6, 4, 8)
    # Half floats, as the GPU stores them: within half precision.
    half = bricks.unpack(bricks.pack_dense(dense))[8:45, 8:29, 8:58]
    np.testing.assert_allclose(half, dense, rtol=1e-3, atol=1e-7)


def test_only_leaves_with_cloud_are_kept():
    dense = np.zeros((64, 64, 64), np.float32)
    dense[10, 10, 10] = 1.0  # in leaf (1, 1, 1) of the grid, (2, 2, 2) of the index
    packed = bricks.pack_dense(dense, dtype=np.float32)
    assert packed.count == 1 and packed.index[2, 2, 2] == 0
    assert (packed.index == bricks.EMPTY).sum() == 9**3 - 1
    # GPU memory follows the voxels: one 9^3 brick and the index, not the 64^3 box.
    assert packed.gpu_bytes == 9**3 * 4 + 9**3 * 4
    atlas, per_side, firsts = bricks.layout([packed.data, packed.data])
    assert per_side == (2, 2, 1) and firsts == [0, 1] and atlas.shape == (9, 18, 18)


@pytest.mark.parametrize("voxel", [(16, 3, 3), (3, 16, 3), (3, 3, 16), (16, 16, 3), (16, 16, 16)])
def test_a_leaf_is_kept_when_its_far_edge_reads_the_next_leafs_cloud(voxel):
    """A voxel at the first plane, edge or corner of leaf 2 along some axes is read by the trilinear
    samples in the last cell of the leaves before it: they are kept too."""
    dense = np.zeros((40, 40, 40), np.float32)
    z, y, x = voxel
    dense[z, y, x] = 1.0
    occ = bricks.occupied_leaves(np.pad(dense, ((0, 1), (0, 1), (0, 1))))
    want = set()
    for lz in {z // 8, (z - 1) // 8} if z % 8 == 0 else {z // 8}:
        for ly in {y // 8, (y - 1) // 8} if y % 8 == 0 else {y // 8}:
            for lx in {x // 8, (x - 1) // 8} if x % 8 == 0 else {x // 8}:
                want.add((lz, ly, lx))
    assert {tuple(int(c) for c in p) for p in zip(*np.nonzero(occ), strict=True)} == want


def test_samples_equal_the_dense_grids_trilinear_interpolation():
    dense = _sparse((30, 26, 33), fill=0.05, seed=9)
    packed = bricks.pack_dense(dense, origin=(4, -2, 0), dtype=np.float32)
    rng = np.random.default_rng(1)
    ijk = rng.uniform(-1.0, 34.0, (20000, 3))
    atlas, per_side, firsts = bricks.layout([np.zeros((3, 9, 9, 9), np.float32), packed.data])
    leaf_rel = ijk + 8.0  # the leaf origin is one leaf before the grid's first voxel
    got = bricks.sample(atlas, per_side, packed.index, firsts[1], leaf_rel)
    want = trilinear(dense, ijk)
    inside = (ijk >= -1).all(-1) & (ijk[:, 0] < 32) & (ijk[:, 1] < 25) & (ijk[:, 2] < 29)
    np.testing.assert_allclose(got[inside], want[inside], atol=1e-6)


def test_the_atlas_is_near_cubic_and_refuses_what_no_texture_holds():
    assert bricks.atlas_shape(1) == (1, 1, 1)
    bx, by, bz = bricks.atlas_shape(1000)
    assert bx * by * bz >= 1000 and max(bx, by, bz) * 9 <= bricks.MAX_ATLAS_SIDE and max(bx, by, bz) <= 11
    most = bricks.MAX_ATLAS_SIDE // 9
    with pytest.raises(NubisError, match="do not fit one 3D texture"):
        bricks.atlas_shape(most**3 + 1)
    assert bricks.gpu_bytes_estimate(1000, 4096) == 10 * 10 * 10 * 729 * 2 + 4096 * 4
