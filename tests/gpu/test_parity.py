"""Measured parity of the viewport with Cycles (compare --mode single), pinned at a small size.

The shot looks steeply up into the default cumulus so the camera-only bake is small enough for
20 m voxels; the cirrus is off because the 2D layer becomes a slab only approximately. Cycles
renders 2 x 1024 samples with different seeds: their mean is the reference and their difference
measures its noise, which must sit well below the limits for the comparison to mean anything
(2026-12-06, Blender 5.3: luminance 0.015 flat and 0.017 sky, alpha 0.0035; twice the samples took
twice Cycles' time for noise 0.010 and 0.0025).
"""

import pytest

from nubis_addon.core.jobs import CompareOptions

# The targets for single scattering (measured 2026-11-22 on llvmpipe: alpha RMSE 0.006,
# luminance error 0.030, bias +0.001, IoU 0.99; Cycles' own noise 0.0024 / 0.018).
ALPHA_RMSE_MAX = 0.02
LUMINANCE_ERROR_MAX = 0.05


# With the physically based sky World (Blender's Sky Texture, New Cloudscape's default), measured
# 2026-12-01 on llvmpipe (Blender 5.0.1): alpha RMSE 0.005, luminance error 0.054, bias +0.013, IoU 0.99
# (Cycles' noise 0.021). The flat World keeps the issue's targets pinned; the sky's limits pin what it
# measures (docs/history.md#parity-with-cycles).
SKY_LUMINANCE_ERROR_MAX = 0.07
SKY_BIAS_MAX = 0.03


@pytest.fixture(scope="module", params=["flat", "sky"])
def world(request):
    return request.param


def _looking_up(sky: bool):
    """The default preset with the camera looking steeply up, under the sky World or the flat one."""
    from nubis_addon.core.presets import load_preset

    preset = load_preset("default")
    preset.extra["world"]["sky"] = sky
    preset.extra["camera"]["rotation"] = [150.0, 0.0, 20.0]
    return preset


def _compare_single(blender, preset, out, samples: int) -> dict:
    from nubis_addon.blender import ensure_registered
    from nubis_addon.blender.jobs import comparison
    from nubis_addon.blender.scene import scenepresets

    blender.ops.wm.read_factory_settings(use_empty=True)
    ensure_registered()
    scene = blender.context.scene
    scenepresets.apply_preset(scene, preset)
    return comparison.compare(
        scene,
        out,
        CompareOptions(width=48, height=27, samples=samples, mode="single", voxel_size=20.0, noise_estimate=True),
    )


@pytest.fixture(scope="module")
def single(tmp_path_factory, blender, world):
    preset = _looking_up(world == "sky")
    preset.params["cirrus_coverage"] = 0.0
    return _compare_single(blender, preset, tmp_path_factory.mktemp("parity"), 2048)


def test_single_scattering_parity(single, world):
    m = single
    assert m["mode"] == "single" and m["volume_bounces"] == 0 and m["samples"] == 2048
    assert m["alpha_rmse"] <= ALPHA_RMSE_MAX, m
    assert m["luminance_rel_error"] <= (LUMINANCE_ERROR_MAX if world == "flat" else SKY_LUMINANCE_ERROR_MAX), m
    assert abs(m["luminance_bias"]) <= (0.02 if world == "flat" else SKY_BIAS_MAX), m
    assert m["silhouette_iou"] >= 0.97, m


def test_cycles_noise_is_well_below_the_limits(single):
    noise = single["cycles_noise"]
    assert noise["alpha_rmse"] <= ALPHA_RMSE_MAX / 3, noise
    assert noise["luminance_rel_error"] <= LUMINANCE_ERROR_MAX / 2, noise


# The cirrus alone under the physical sky, looking up through it: the viewport's 2D layer against its
# baked slab in Cycles (docs/sources.md#cirrus-lighting). Measured 2026-12-01 on llvmpipe, 1024 samples:
# lit as the slab Cycles renders, in the reference sky light's directions, luminance error 0.053 and
# bias +0.001 on Blender 5.0.1 (Cycles' own noise 0.041), 0.049 / -0.001 on 4.5.15; lit by sky light
# in proportion to its opacity, as before, 0.56 / +0.56.
CIRRUS_LUMINANCE_ERROR_MAX = 0.08
CIRRUS_BIAS_MAX = 0.04


@pytest.fixture(scope="module")
def cirrus_only(tmp_path_factory, blender):
    preset = _looking_up(True)
    preset.layers = [layer for layer in preset.layers if layer["channel"] != "coverage"]
    for layer in preset.layers:
        if layer["channel"] == "cirrus_coverage":
            layer["remap"] = [0.0, 1.0, 0.4, 1.0]  # cirrus over most of the view, thin to thick
    preset.params["cirrus_coverage"] = 1.0
    return _compare_single(blender, preset, tmp_path_factory.mktemp("parity_cirrus"), 1024)


def test_cirrus_is_lit_as_its_slab(cirrus_only):
    m = cirrus_only
    assert m["mean_alpha_b"] > 0.05, "the shot must see the cirrus: " + str(m)
    assert m["alpha_rmse"] <= ALPHA_RMSE_MAX, m
    assert m["luminance_rel_error"] <= CIRRUS_LUMINANCE_ERROR_MAX, m
    assert abs(m["luminance_bias"]) <= CIRRUS_BIAS_MAX, m
