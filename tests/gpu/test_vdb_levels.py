"""A VDB cloud whose finest bricks pass the GPU budget is drawn from a coarser level of its file, the same
in the viewport, F12 and `render`, and each says so (docs/vdb.md#levels-of-detail).

The cloud is a soft ball 1.7 km across at 20 m voxels, thin (0.004 per metre at most) so its opacity follows
its density: 1.4 MB of bricks at its own voxels, 0.26 MB at level 1. The budget, 1 MB, is set as the command
line sets it (NUBIS_VDB_GPU_BUDGET).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from conftest import run_cli  # noqa: E402
from vdb_helpers import DEFAULT_VIEW_BASE, ball, write_grid  # noqa: E402

W, H = 48, 27


@pytest.fixture(scope="module")
def fine_cumulus(tmp_path_factory) -> Path:
    v, n, (x, y, z) = 20.0, 120, DEFAULT_VIEW_BASE
    rows = [[v, 0, 0, 0], [0, v, 0, 0], [0, 0, v, 0], [x - n / 2 * v, y - n / 2 * v, z, 1]]
    return Path(write_grid(tmp_path_factory.mktemp("vdb_levels") / "fine.vdb", ball(n, 0.004), rows))


def _scene(blender, make_scene, path: Path):
    scene = make_scene("default")
    scene.nubis.density_cover, scene.nubis.cirrus_coverage = 0.0, 0.0
    vol = blender.data.volumes.new(path.stem)
    vol.filepath = str(path)
    obj = blender.data.objects.new(path.stem, vol)
    scene.collection.objects.link(obj)
    vol.nubis_cloud.enabled = True
    return scene, obj


def test_over_the_budget_the_viewport_draws_a_coarser_level_and_says_so(blender, make_scene, fine_cumulus, monkeypatch):
    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.blender.scene import vdbclouds

    scene, obj = _scene(blender, make_scene, fine_cumulus)
    finest = pipeline.render_viewport(scene, W, H)
    [placed] = pipeline.viewport_shot(scene, W, H).state.vdb_clouds
    assert placed.cloud.level == 0 and vdbclouds.level_note(obj) == ""
    assert placed.cloud.gpu_bytes > 2**20  # the file's own bricks pass the budget below
    monkeypatch.setenv("NUBIS_VDB_GPU_BUDGET", "1")
    [placed] = pipeline.viewport_shot(scene, W, H).state.vdb_clouds
    assert placed.cloud.level == 1 and placed.cloud.gpu_bytes <= 2**20
    assert placed.cloud.voxel_size == pytest.approx(40.0)
    assert vdbclouds.level_note(obj).startswith("Level 1: 2x coarser")
    coarse = pipeline.render_viewport(scene, W, H)
    # The same cloud, its edges softer: the opacity within a few hundredths of the finest level's.
    assert coarse[..., 3].max() > 0.3
    assert float(np.sqrt(np.mean((coarse[..., 3] - finest[..., 3]) ** 2))) < 0.05
    monkeypatch.setenv("NUBIS_VDB_GPU_BUDGET", "lots")
    from nubis_addon.core.errors import NubisError

    with pytest.raises(NubisError, match="NUBIS_VDB_GPU_BUDGET is 'lots': set it to a whole number of megabytes"):
        vdbclouds.gpu_budget()


def test_f12_draws_the_level_that_fits(blender, make_scene, fine_cumulus, tmp_path, monkeypatch):
    from nubis_addon.blender.scene import vdbclouds
    from nubis_addon.core import imageio

    scene, obj = _scene(blender, make_scene, fine_cumulus)
    r = scene.render
    r.engine, r.resolution_x, r.resolution_y, r.resolution_percentage = "CYCLES", W, H, 100
    r.image_settings.file_format = "OPEN_EXR"
    scene.cycles.device, scene.cycles.samples, scene.cycles.use_denoising = "CPU", 4, False
    scene.nubis.sky_environment_width = 128
    monkeypatch.setenv("NUBIS_VDB_GPU_BUDGET", "1")
    images = {}
    for marked in (False, True):
        obj.data.nubis_cloud.enabled = marked
        r.filepath = str(tmp_path / f"f12_{marked}.exr")
        blender.ops.render.render(write_still=True)
        images[marked] = imageio.read_image(r.filepath)[..., :3]
    changed = (np.abs(images[True] - images[False]).max(axis=-1) > 0.02).mean()
    assert changed > 0.03, "F12 must show the cloud"
    assert vdbclouds.level_note(obj).startswith("Level 1")


def test_render_says_which_level_it_draws(fine_cumulus, tmp_path, cache_dir):
    from nubis_addon.core import imageio

    out = tmp_path / "cloud.png"
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    env = {"TMPDIR": str(tmp), "NUBIS_CACHE_DIR": str(cache_dir), "NUBIS_VDB_GPU_BUDGET": "1"}
    r = run_cli("render", "--vdb", str(fine_cumulus), "--out", str(out), "--width", "64", "--height", "36", env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    notes = [line for line in r.stderr.splitlines() if "is drawn at level" in line]
    assert len(notes) == 1 and notes[0].startswith("nubis: note: the Nubis cloud 'fine' is drawn at level 1"), notes
    assert "over the 1.0 MB budget" in notes[0]
    assert (imageio.read_image(out)[..., 3] > 0.2).mean() > 0.02
