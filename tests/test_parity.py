"""Measured parity of the viewport with Cycles (compare --mode single), pinned at a small size.

The shot looks steeply up into the default cumulus so the camera-only bake is small enough for
40 m voxels; the cirrus is off because the 2D layer becomes a slab only approximately.
"""

import pytest


@pytest.fixture(scope="module")
def single(tmp_path_factory, blender):
    from nubis_addon.blender import ensure_registered, pipeline, scene_io
    from nubis_addon.core.presets import load_preset

    preset = load_preset("default")
    preset.params["cirrus_coverage"] = 0.0
    preset.extra["camera"]["rotation"] = [150.0, 0.0, 20.0]
    blender.ops.wm.read_factory_settings(use_empty=True)
    ensure_registered()
    scene = blender.context.scene
    scene_io.apply_preset(scene, preset)
    out = tmp_path_factory.mktemp("parity")
    return pipeline.compare(scene, out, 48, 27, samples=512, mode="single", voxel_size=40.0, noise_estimate=True)


def test_single_scattering_parity(single):
    m = single
    assert m["mode"] == "single" and m["volume_bounces"] == 0
    # Measured 2026-11 on llvmpipe (see README): alpha RMSE 0.031, luminance error 0.15, bias within
    # a few percent. The limits sit just above the measurement so a regression fails the test.
    assert m["alpha_rmse"] <= 0.04, m
    assert m["luminance_rel_error"] <= 0.20, m
    assert abs(m["luminance_bias"]) <= 0.06, m
    assert m["silhouette_iou"] >= 0.93, m


def test_cycles_noise_is_below_the_measured_error(single):
    noise = single["cycles_noise"]
    assert noise["alpha_rmse"] < single["alpha_rmse"]
    assert noise["luminance_rel_error"] < single["luminance_rel_error"]
