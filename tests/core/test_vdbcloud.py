"""Reading an artist's OpenVDB cloud (core/vdbcloud.py): the grid packed exactly, placed by its transform,
and one sentence for each bad file, before anything large is made."""

from __future__ import annotations

import numpy as np
import pytest

from nubis_addon.core import bricks, bundled, vdbcloud
from nubis_addon.core.errors import NubisError


def _ball(n=40, value=0.02) -> np.ndarray:
    z, y, x = np.mgrid[0:n, 0:n, 0:n]
    r = np.sqrt((x - n / 2) ** 2 + (y - n / 2) ** 2 + (z - n / 2) ** 2)
    return (np.clip((n * 0.35 - r) / 4, 0, 1) * value).astype(np.float32)


def _write(path, dense_zyx, rows=None, name="density", extra=(), nan_at=None):
    vdb = bundled.openvdb()
    g = vdb.FloatGrid()
    g.copyFromArray(np.ascontiguousarray(dense_zyx.transpose(2, 1, 0)), tolerance=0.0)
    if nan_at is not None:  # copyFromArray drops NaN (it compares values with the background)
        g.getAccessor().setValueOn(nan_at, float("nan"))
    g.name = name
    g.transform = vdb.createLinearTransform(rows or [[50, 0, 0, 0], [0, 50, 0, 0], [0, 0, 50, 0], [0, 0, 0, 1]])
    vdb.write(str(path), grids=[g, *extra])
    return path


def test_a_rotated_cloud_is_packed_exactly_and_placed_by_its_transform(tmp_path):
    dense = _ball()
    c, s, v = np.cos(0.5), np.sin(0.5), 50.0
    rows = [[v * c, v * s, 0, 0], [-v * s, v * c, 0, 0], [0, 0, v, 0], [1000, 2000, 1500, 1]]
    path = _write(tmp_path / "ball.vdb", dense, rows)
    cloud = vdbcloud.read_cloud(path, dtype=np.float32)
    assert cloud.grid == "density" and cloud.voxel_size == pytest.approx(50.0)
    assert cloud.active_voxels == int((dense > 0).sum())
    np.testing.assert_allclose(cloud.index_to_world @ (1, 0, 0, 1), (1000 + v * c, 2000 + v * s, 1500, 1))
    back = bricks.unpack(cloud.bricks)
    o = cloud.bricks.leaf_origin
    got = back[-o[2] : -o[2] + 40, -o[1] : -o[1] + 40, -o[0] : -o[0] + 40]
    np.testing.assert_array_equal(got, dense)
    assert back.sum() == pytest.approx(float(dense.sum()), rel=1e-6)
    voxels, least = vdbcloud.estimate_gpu_bytes(path)
    assert voxels == cloud.active_voxels and 0 < least <= vdbcloud.read_cloud(path).gpu_bytes


def test_gpu_memory_follows_the_active_voxels_not_the_box(tmp_path):
    """Two puffs at opposite corners of a 160^3 box: the bricks hold a small part of it."""
    dense = np.zeros((160, 160, 160), np.float32)
    dense[:40, :40, :40] = _ball()
    dense[120:, 120:, 120:] = _ball()
    cloud = vdbcloud.read_cloud(_write(tmp_path / "two.vdb", dense))
    assert cloud.gpu_bytes < 0.05 * dense.nbytes
    assert cloud.bricks.index.size * 4 < 0.01 * dense.nbytes


def test_the_grid_is_chosen_by_name_density_or_the_only_float_grid(tmp_path):
    vdb = bundled.openvdb()
    vec = vdb.Vec3SGrid()
    vec.name = "velocity"
    path = _write(tmp_path / "smoke.vdb", _ball(), name="smoke", extra=(vec,))
    assert vdbcloud.choose_grid(path) == "smoke"
    with pytest.raises(NubisError, match="has no float grid 'heat': choose one of smoke"):
        vdbcloud.choose_grid(path, "heat")


def _bad(tmp_path, kind):
    dense = _ball()
    if kind == "not a vdb":
        p = tmp_path / "cloud.vdb"
        p.write_text("this is a text file, not a VDB\n")
        return p, "is not an OpenVDB file this Blender reads"
    if kind == "missing":
        return tmp_path / "gone.vdb", "is not there"
    if kind == "no float grid":
        vdb = bundled.openvdb()
        vec = vdb.Vec3SGrid()
        vec.name = "velocity"
        vec.copyFromArray(np.ones((4, 4, 4, 3), np.float32))
        p = tmp_path / "vec.vdb"
        vdb.write(str(p), grids=[vec])
        return p, "has no float grid to draw as a cloud"
    if kind == "empty":
        return _write(tmp_path / "empty.vdb", np.zeros((8, 8, 8), np.float32)), "is empty"
    if kind == "negative":
        dense[20, 20, 20] = -0.5
        return _write(tmp_path / "neg.vdb", dense), "negative values"
    if kind == "nan":
        return _write(tmp_path / "nan.vdb", dense, nan_at=(20, 20, 20)), "NaN or infinite"
    if kind == "non-uniform":
        rows = [[50, 0, 0, 0], [0, 50, 0, 0], [0, 0, 80, 0], [0, 0, 0, 1]]
        return _write(tmp_path / "stretch.vdb", dense, rows), "non-uniform voxels"
    if kind == "sheared":
        rows = [[50, 0, 0, 0], [30, 40, 0, 0], [0, 0, 50, 0], [0, 0, 0, 1]]  # equal lengths, not square
        return _write(tmp_path / "shear.vdb", dense, rows), "sheared transform"
    raise AssertionError(kind)


@pytest.mark.parametrize(
    "kind", ["not a vdb", "missing", "no float grid", "empty", "negative", "nan", "non-uniform", "sheared"]
)
def test_a_bad_file_gets_one_sentence(tmp_path, kind):
    path, words = _bad(tmp_path, kind)
    with pytest.raises(NubisError, match=words) as err:
        vdbcloud.read_cloud(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_a_cloud_over_the_gpu_budget_is_refused_with_what_it_needs(tmp_path):
    path = _write(tmp_path / "big.vdb", _ball(64))
    with pytest.raises(NubisError, match=r"needs at least [\d.]+ KB on the GPU as bricks, over the 10.0 KB"):
        vdbcloud.read_cloud(path, limit=10_000)
