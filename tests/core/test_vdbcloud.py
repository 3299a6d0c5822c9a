"""Reading an artist's OpenVDB cloud (core/vdbcloud.py): the grid packed exactly, placed by its transform,
and one sentence for each bad file, before anything large is made."""

from __future__ import annotations

import numpy as np
import pytest
from vdb_helpers import BAD_KINDS, bad_vdb
from vdb_helpers import ball as _ball
from vdb_helpers import write_grid as _write

from nubis_addon.core import bricks, bundled, vdbcloud
from nubis_addon.core.errors import NubisError


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


def test_a_nubis_bake_reads_back_in_its_own_density_scale(tmp_path):
    """A Nubis bake's values are densities; its `nubis_density_scale` turns them into extinction."""
    vdb = bundled.openvdb()
    g = vdb.FloatGrid()
    g.copyFromArray(np.ascontiguousarray(_ball().transpose(2, 1, 0)))
    g.name = "density"
    vdb.write(str(tmp_path / "bake.vdb"), grids=[g], metadata={"nubis_density_scale": 0.08})
    assert vdbcloud.read_cloud(tmp_path / "bake.vdb").value_scale == pytest.approx(0.08)
    placed = vdbcloud.Placement(vdbcloud.read_cloud(tmp_path / "bake.vdb"), np.eye(4), 2.0)
    assert placed.extinction_scale == pytest.approx(0.16)
    assert vdbcloud.read_cloud(_write(tmp_path / "plain.vdb", _ball())).value_scale == 1.0


def test_the_grid_is_chosen_by_name_density_or_the_only_float_grid(tmp_path):
    vdb = bundled.openvdb()
    vec = vdb.Vec3SGrid()
    vec.name = "velocity"
    path = _write(tmp_path / "smoke.vdb", _ball(), name="smoke", extra=(vec,))
    assert vdbcloud.choose_grid(path) == "smoke"
    with pytest.raises(NubisError, match="has no float grid 'heat': choose one of 'smoke'"):
        vdbcloud.choose_grid(path, "heat")


@pytest.mark.parametrize("kind", BAD_KINDS)
def test_a_bad_file_gets_one_sentence(tmp_path, kind):
    path, words = bad_vdb(tmp_path, kind)
    with pytest.raises(NubisError, match=words) as err:
        vdbcloud.read_cloud(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_a_cloud_over_the_gpu_budget_is_refused_with_what_it_needs(tmp_path):
    path = _write(tmp_path / "big.vdb", _ball(64))
    with pytest.raises(NubisError, match=r"needs at least [\d.]+ KB on the GPU as bricks, over the 10.0 KB"):
        vdbcloud.read_cloud(path, limit=10_000)
