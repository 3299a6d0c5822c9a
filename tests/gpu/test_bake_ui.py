"""Bakes from the sidebar: a bake cancelled half way leaves the earlier VDB byte-identical, the Bake
panel's estimate comes before any bake, Bake Sequence writes numbered files and loads them as a
Volume sequence (a `//` path in an unsaved file: tests/gpu/test_superstorm.py)."""

from __future__ import annotations

from pathlib import Path

from nubis_addon.core.jobs import BakeOptions


def test_a_cancelled_bake_leaves_the_earlier_file_byte_identical(make_scene, tmp_path):
    from nubis_addon.blender.jobs import pipeline

    scene = make_scene("default")
    path = tmp_path / "clouds.vdb"
    pipeline.bake(scene, path, BakeOptions(voxel_size=800.0))
    before = path.read_bytes()
    steps = pipeline.bake_steps(scene, path, BakeOptions(voxel_size=400.0), tiles_per_step=1)
    fractions = [next(steps), next(steps)]  # two tiles in: half way is far from done
    assert 0.0 < fractions[0] < fractions[1] < 1.0
    steps.close()  # what Esc does
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clouds.vdb"]  # no staging left either
    # Run to its end, the same steps write the new bake.
    result = pipeline.run_steps(pipeline.bake_steps(scene, path, BakeOptions(voxel_size=400.0)))
    assert result.plan.voxel_size == 400.0 and path.read_bytes() != before


def test_the_bake_panel_estimates_before_baking(make_scene):
    from nubis_addon.blender.jobs import pipeline

    scene = make_scene("default")
    coarse = pipeline.bake_estimate(scene, 800.0)
    fine = pipeline.bake_estimate(scene, 400.0)
    assert 0 < coarse[0] < fine[0] and coarse[1] < fine[1]
    assert pipeline.bake_estimate(scene, 400.0) == fine  # cached while nothing changes


def test_bake_sequence_writes_numbered_files_and_loads_them_as_a_sequence(blender, make_scene, tmp_path):
    from nubis_addon.blender.scene import cycles_setup

    scene = make_scene("default")
    scene.frame_start, scene.frame_end = 3, 5
    scene.nubis.bake_voxel_size = 1500.0
    assert blender.ops.nubis.bake_frames(directory=str(tmp_path), step=1) == {"FINISHED"}
    assert sorted(p.name for p in tmp_path.glob("*.vdb")) == ["clouds_0003.vdb", "clouds_0004.vdb", "clouds_0005.vdb"]
    vol = scene.objects[cycles_setup.VOLUME_NAME].data
    assert vol.is_sequence and vol.frame_start == 3 and vol.frame_duration == 3 and vol.frame_offset == 2
    assert Path(blender.path.abspath(vol.filepath)).name == "clouds_0003.vdb"


def test_render_clouds_runs_in_steps_and_a_cancel_leaves_the_image_untouched(make_scene):
    """Render Clouds is modal like the bakes: tile by tile, one timer tick each, Esc closes the steps
    before the image 'Nubis Render' is touched; run to its end it is the headless render."""
    import bpy
    import numpy as np

    from nubis_addon.blender.jobs import pipeline, work
    from nubis_addon.blender.sidebar import operators

    scene = make_scene("default")
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 300, 140, 100
    assert issubclass(operators.NUBIS_OT_render_image, work.ModalSteps)
    steps = pipeline.render_shot_steps(pipeline.viewport_shot(scene, 300, 140))
    fractions = [next(steps), next(steps)]  # 3x2 tiles of 128 pixels: two of six
    assert fractions == [1 / 6, 2 / 6]
    steps.close()  # what Esc does
    assert bpy.data.images.get("Nubis Render") is None
    assert bpy.ops.nubis.render_image() == {"FINISHED"}  # background mode: to its end at once
    img = bpy.data.images["Nubis Render"]
    assert tuple(img.size) == (300, 140)
    got = np.empty(300 * 140 * 4, np.float32)
    img.pixels.foreach_get(got)
    want = pipeline.render_viewport(scene, 300, 140)[::-1]
    assert want[..., 3].max() > 0.5
    np.testing.assert_allclose(got.reshape(140, 300, 4), want, atol=1e-5)
