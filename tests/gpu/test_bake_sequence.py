"""Bake sequences (`--frames A-B`, `#` padding), the velocity grid against the motion vectors, and
distributed bakes on Dask workers (identical grids, a clear message without Dask)."""

import sys

import numpy as np
import pytest

from nubis_addon.core.jobs import BakeOptions


def test_sequence_names_follow_blenders_padding(tmp_path):
    from nubis_addon.core import sequence
    from nubis_addon.core.errors import NubisError

    assert sequence.frame_path("out/clouds_####.vdb", 7).name == "clouds_0007.vdb"
    assert sequence.frame_path("clouds_#.vdb", 12).name == "clouds_12.vdb"
    assert sequence.frame_path("a##/c_###_v##.vdb", 3).as_posix() == "a##/c_###_v03.vdb"  # the name's last run
    assert sequence.frame_path("c_####.vdb", -5).name == "c_-0005.vdb"
    assert sequence.frame_path("plain.vdb", 5).name == "plain.vdb"
    assert sequence.parse_frames("1-4") == [1, 2, 3, 4] and sequence.parse_frames("9") == [9]
    names = [p.name for p in sequence.sequence_paths(tmp_path / "clouds_####.vdb", [1, 2, 3, 4])]
    assert names == ["clouds_0001.vdb", "clouds_0002.vdb", "clouds_0003.vdb", "clouds_0004.vdb"]
    with pytest.raises(NubisError, match="clouds_####.vdb"):
        sequence.sequence_paths(tmp_path / "clouds.vdb", [1, 2])
    for bad in ("4-1", "a-b", "1-2000000"):
        with pytest.raises(NubisError, match="--frames"):
            sequence.parse_frames(bad)


def _velocity_array(path):
    from nubis_addon.core import bundled

    grid = bundled.openvdb().read(str(path), "velocity")
    lo, hi = grid.evalActiveVoxelBoundingBox()
    shape = tuple(int(h - a + 1) for a, h in zip(lo, hi, strict=True))
    arr = np.zeros((*shape, 3), np.float32)
    grid.copyToArray(arr, ijk=lo)
    return arr, np.array(lo)


def test_cli_sequence_with_velocity_matches_the_motion_vectors(make_scene, tmp_path):
    """`bake --frames 1-4 --velocity` writes four numbered files with a Vec3 `velocity` grid; the
    velocity, moved back one frame and projected through the camera, gives the motion vectors the
    viewport's motion pass draws for the same clouds (superstorm: wind and the vortex's turn)."""
    from nubis_addon import cli
    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.blender.scene import cloudstate
    from nubis_addon.core import vdbwrite

    out = tmp_path / "clouds_####.vdb"
    code = cli.run(["bake", "--voxel-size", "400", "--frames", "1-4", "--velocity", "--out", str(out)])
    assert code == 0
    files = sorted(p.name for p in tmp_path.iterdir())
    assert files == ["clouds_0001.vdb", "clouds_0002.vdb", "clouds_0003.vdb", "clouds_0004.vdb"]
    for name in files:
        info = vdbwrite.read_grid_info(tmp_path / name)
        assert set(info) == {"density", "velocity"}
        assert info["velocity"].active_voxels == info["density"].active_voxels > 1000

    scene = make_scene("superstorm")
    scene.nubis.wind_time_scale *= 100.0  # a hundred times the wind, so a frame moves the clouds pixels
    w, h = 64, 36
    baked = pipeline.bake(
        scene, tmp_path / "storm.vdb", BakeOptions(voxel_size=250.0, camera_only=True, size=(w, h), velocity=True)
    )
    vel, lo = _velocity_array(baked.path)
    motion = pipeline.render_motion(scene, w, h)
    inv = np.array(cloudstate.camera_inv_view_proj(scene, w, h), np.float64)
    vp = np.linalg.inv(inv)
    eye = np.array(cloudstate.camera_eye(scene)[:3])
    fps = scene.render.fps / scene.render.fps_base
    rows, cols = np.nonzero(motion[..., 3] > 0.3)
    ndc = np.stack([(cols + 0.5) / w * 2 - 1, 1 - (rows + 0.5) / h * 2, np.ones_like(cols, float)], 1)
    far = np.c_[ndc, np.ones(len(ndc))] @ inv.T
    d = far[:, :3] / far[:, 3:] - eye
    world = eye + d / np.linalg.norm(d, axis=1, keepdims=True) * motion[rows, cols, 2:3]
    idx = np.rint((world - np.array(baked.plan.origin)) / baked.plan.voxel_size).astype(int) - lo
    ok = np.all((idx >= 0) & (idx < vel.shape[:3]), axis=1)
    v = vel[idx[ok, 0], idx[ok, 1], idx[ok, 2]]
    found = np.any(v != 0, axis=1)
    assert found.sum() > 100, found.sum()
    world, v = world[ok][found], v[found]

    def pixels(p):
        q = np.c_[p, np.ones(len(p))] @ vp.T
        return q[:, :2] / q[:, 3:] * 0.5 * np.array([w, h])

    predicted = pixels(world) - pixels(world - v / fps)
    predicted[:, 1] *= -1  # image rows run down
    measured = motion[rows, cols, :2][ok][found]
    err = np.linalg.norm(predicted - measured, axis=1) / np.maximum(np.linalg.norm(measured, axis=1), 1e-3)
    assert np.median(np.linalg.norm(measured, axis=1)) > 0.05  # the clouds do move on screen
    assert np.median(err) < 0.05, np.median(err)
    assert np.percentile(err, 90) < 0.25, np.percentile(err, 90)


@pytest.fixture(scope="module")
def distributed_bakes(tmp_path_factory, blender):
    from nubis_addon.blender import ensure_registered
    from nubis_addon.blender.jobs import farm
    from nubis_addon.blender.scene import scenepresets
    from nubis_addon.core import distributed
    from nubis_addon.core.presets import load_preset

    blender.ops.wm.read_factory_settings(use_empty=True)
    ensure_registered()
    scene = blender.context.scene
    scenepresets.apply_preset(scene, load_preset("default"))
    out = tmp_path_factory.mktemp("dist")
    options = BakeOptions(voxel_size=300.0, velocity=True)
    engine = distributed.parse_engine("local:2")
    source = distributed.SceneSource(preset="default")
    results = {}
    for kind, frames in (("serial", [1, 2]), ("frames", [1, 2]), ("tiles", [2])):
        results[kind] = farm.bake_sequence(
            scene, out / kind / "c_##.vdb", frames, options, None if kind == "serial" else engine, source
        )
    return results


def test_distributed_bakes_equal_the_serial_bake_voxel_for_voxel(distributed_bakes):
    from nubis_addon.core import vdbwrite

    serial = {r.frame: r.path for r in distributed_bakes["serial"].results}
    pairs = [(r.path, serial[r.frame]) for kind in ("frames", "tiles") for r in distributed_bakes[kind].results]
    assert len(pairs) == 3 and distributed_bakes["tiles"].engine == "local:2"
    for a, b in pairs:
        assert a.name == b.name and a.name.startswith("c_0")
        ia, ib = vdbwrite.read_grid_info(a), vdbwrite.read_grid_info(b)
        assert set(ia) == set(ib) == {"density", "velocity"}
        assert ia["density"].active_voxels == ib["density"].active_voxels > 1000
        assert ia["velocity"].active_voxels == ib["velocity"].active_voxels
        da, la = vdbwrite.read_grid_array(a, "density")
        db, lb = vdbwrite.read_grid_array(b, "density")
        assert la == lb and np.array_equal(da, db)


def test_distributed_without_dask_says_what_to_do(monkeypatch, tmp_path, capsys):
    from nubis_addon import cli
    from nubis_addon.core import distributed

    monkeypatch.setattr(distributed, "distributed", None)
    monkeypatch.setitem(sys.modules, "distributed", None)  # `import distributed` fails, as without Dask
    code = cli.run(["bake", "--distributed", "local:2", "--out", str(tmp_path / "c.vdb")])
    assert code == 1
    err = capsys.readouterr().err
    assert "need Dask" in err and "pip install" in err
    assert cli.run(["bake", "--distributed", "farm:9", "--out", str(tmp_path / "c.vdb")]) == 1
    assert "local:N" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
