"""Reading an artist's OpenVDB cloud (core/vdbread.py): the grid packed exactly, placed by its transform,
and one sentence for each bad file, before anything large is made."""

from __future__ import annotations

import numpy as np
import pytest
from vdb_helpers import BAD_KINDS, bad_vdb
from vdb_helpers import ball as _ball
from vdb_helpers import write_grid as _write

from nubis_addon.core import bricks, bundled, vdbplacement, vdbread
from nubis_addon.core.errors import NubisError
from nubis_addon.core.sequence import human_bytes


def test_a_rotated_cloud_is_packed_exactly_and_placed_by_its_transform(tmp_path):
    dense = _ball()
    c, s, v = np.cos(0.5), np.sin(0.5), 50.0
    rows = [[v * c, v * s, 0, 0], [-v * s, v * c, 0, 0], [0, 0, v, 0], [1000, 2000, 1500, 1]]
    path = _write(tmp_path / "ball.vdb", dense, rows)
    cloud = vdbread.read_cloud(path, dtype=np.float32)
    assert cloud.grid == "density" and cloud.voxel_size == pytest.approx(50.0)
    assert cloud.active_voxels == int((dense > 0).sum())
    np.testing.assert_allclose(cloud.index_to_world @ (1, 0, 0, 1), (1000 + v * c, 2000 + v * s, 1500, 1))
    back = bricks.unpack(cloud.bricks)
    o = cloud.bricks.leaf_origin
    got = back[-o[2] : -o[2] + 40, -o[1] : -o[1] + 40, -o[0] : -o[0] + 40]
    np.testing.assert_array_equal(got, dense)
    assert back.sum() == pytest.approx(float(dense.sum()), rel=1e-6)
    voxels, least = vdbread.estimate_gpu_bytes(path)
    assert voxels == cloud.active_voxels and 0 < least <= vdbread.read_cloud(path).gpu_bytes


def test_gpu_memory_follows_the_active_voxels_not_the_box(tmp_path):
    """Two puffs at opposite corners of a 160^3 box: the bricks hold a small part of it."""
    dense = np.zeros((160, 160, 160), np.float32)
    dense[:40, :40, :40] = _ball()
    dense[120:, 120:, 120:] = _ball()
    cloud = vdbread.read_cloud(_write(tmp_path / "two.vdb", dense))
    assert cloud.gpu_bytes < 0.05 * dense.nbytes
    assert cloud.bricks.index.size * 4 < 0.01 * dense.nbytes


def test_a_nubis_bake_reads_back_in_its_own_density_scale(tmp_path):
    """A Nubis bake's values are densities; its `nubis_density_scale` turns them into extinction."""
    vdb = bundled.openvdb()
    g = vdb.FloatGrid()
    g.copyFromArray(np.ascontiguousarray(_ball().transpose(2, 1, 0)))
    g.name = "density"
    vdb.write(str(tmp_path / "bake.vdb"), grids=[g], metadata={"nubis_density_scale": 0.08})
    assert vdbread.read_cloud(tmp_path / "bake.vdb").value_scale == pytest.approx(0.08)
    placed = vdbplacement.Placement(vdbread.read_cloud(tmp_path / "bake.vdb"), np.eye(4), 2.0)
    assert placed.extinction_scale == pytest.approx(0.16)
    assert vdbread.read_cloud(_write(tmp_path / "plain.vdb", _ball())).value_scale == 1.0


def test_render_space_scales_extinction_as_cycles_does():
    """Space = World: per metre whatever the scale. Space = Object: one over the length the object's
    transform gives the unit diagonal, so 1/s for a uniform scale, the scales' root mean square for a
    non-uniform one, and a rotation or a translation changes nothing (Cycles' object_volume_density)."""
    turn = np.eye(4)
    turn[:2, :2] = [[np.cos(0.7), -np.sin(0.7)], [np.sin(0.7), np.cos(0.7)]]
    assert vdbplacement.render_space_factor(np.diag([8.0, 8.0, 8.0, 1.0]), "WORLD") == 1.0
    assert vdbplacement.render_space_factor(np.diag([8.0, 8.0, 8.0, 1.0]), "OBJECT") == pytest.approx(1 / 8)
    assert vdbplacement.render_space_factor(np.diag([2.0, 4.0, 8.0, 1.0]), "OBJECT") == pytest.approx(
        1 / np.sqrt((4 + 16 + 64) / 3)
    )
    moved = turn @ np.diag([4.0, 4.0, 4.0, 1.0])
    moved[:3, 3] = (1000.0, -50.0, 3000.0)
    assert vdbplacement.render_space_factor(moved, "OBJECT") == pytest.approx(0.25)
    with pytest.raises(NubisError, match="unknown Volume render space"):
        vdbplacement.render_space_factor(np.eye(4), "VIEW")


def test_the_grid_is_chosen_by_name_density_or_the_only_float_grid(tmp_path):
    vdb = bundled.openvdb()
    vec = vdb.Vec3SGrid()
    vec.name = "velocity"
    path = _write(tmp_path / "smoke.vdb", _ball(), name="smoke", extra=(vec,))
    assert vdbread.choose_grid(path) == "smoke"
    with pytest.raises(NubisError, match="has no float grid 'heat': choose one of 'smoke'"):
        vdbread.choose_grid(path, "heat")


@pytest.mark.parametrize("kind", BAD_KINDS)
def test_a_bad_file_gets_one_sentence(tmp_path, kind):
    path, words = bad_vdb(tmp_path, kind)
    with pytest.raises(NubisError, match=words) as err:
        vdbread.read_cloud(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def _world_mass_and_centre(cloud) -> tuple[float, np.ndarray]:
    """The cloud's values summed over its voxels' volume, and their centre in the world."""
    dense = bricks.unpack(cloud.bricks).astype(np.float64)
    z, y, x = np.nonzero(dense)
    w = dense[z, y, x]
    ijk = np.c_[x, y, z] + np.asarray(cloud.bricks.leaf_origin)
    world = (np.c_[ijk, np.ones(len(ijk))] @ cloud.index_to_world.T)[:, :3]
    return float(w.sum() * cloud.voxel_size**3), (world * w[:, None]).sum(0) / w.sum()


def test_a_cloud_over_the_gpu_budget_is_drawn_at_a_coarser_level(tmp_path):
    """Its voxels averaged 2, 4, ... per side until its bricks fit: the same cloud in the world (its mass
    and centre kept), coarser voxels, and a note that says so. Refused only when even the coarsest level
    does not fit."""
    c, s_, v = np.cos(0.4), np.sin(0.4), 20.0
    rows = [[v * c, v * s_, 0, 0], [-v * s_, v * c, 0, 0], [0, 0, v, 0], [500, -300, 1200, 1]]
    path = _write(tmp_path / "big.vdb", _ball(64), rows)
    fine = vdbread.read_cloud(path)
    assert fine.level == 0 and fine.level_note == ""
    limit = fine.gpu_bytes // 4
    coarse = vdbread.read_cloud(path, limit=limit)
    assert coarse.level >= 1 and coarse.gpu_bytes <= limit < fine.gpu_bytes
    assert coarse.voxel_size == pytest.approx(2**coarse.level * fine.voxel_size)
    assert coarse.active_voxels == fine.active_voxels
    assert f"drawn at level {coarse.level}, {coarse.voxel_size:g} m voxels" in coarse.level_note
    assert f"over the {human_bytes(limit)} budget" in coarse.level_note
    mass, centre = _world_mass_and_centre(fine)
    mass_c, centre_c = _world_mass_and_centre(coarse)
    assert mass_c == pytest.approx(mass, rel=2e-3)  # half floats
    assert np.linalg.norm(centre_c - centre) < 0.01 * fine.voxel_size
    coarsest = r"needs at least [\d.]+ KB on the GPU as bricks, over the 1.0 KB a cloud may take even averaged 16 x 16"
    with pytest.raises(NubisError, match=coarsest):
        vdbread.read_cloud(path, limit=1000)
