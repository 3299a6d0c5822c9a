"""compare's Cycles reference: sampled until its own noise is under a target, and reused by a later
comparison only when nothing Cycles sees has changed (blender/jobs/reference.py)."""

import json

import numpy as np
import pytest

from nubis_addon.blender.jobs import reference
from nubis_addon.core.jobs import CompareOptions


def test_rounds_are_sized_from_the_measured_noise_and_keep_every_sample():
    """A fake renderer whose noise falls as 1/sqrt(samples): the target is met in one extra round, and
    the result is the sample-weighted mean of every render."""
    rng = np.random.default_rng(1)
    calls = []

    def render(samples, seed):
        calls.append((samples, seed))
        image = np.zeros((8, 8, 4), np.float32)
        image[..., :3] = 1.0 + rng.normal(0.0, 1.0 / np.sqrt(samples), (8, 8, 1))
        image[..., 3] = 1.0
        return image

    said = []
    image, noise, taken = reference.sample_to_target(render, 16, reference.NoiseGoal(0.05), said.append)
    assert noise["luminance_rel_error"] <= 0.05
    assert taken == sum(s for s, _ in calls) and taken > 16
    assert [seed for _, seed in calls] == list(range(len(calls))), "every render has its own seed"
    assert len(calls) == 4 and calls[0][0] == calls[1][0] == 8 and calls[2][0] == calls[3][0]
    assert "more for 5 %" in said[0]
    assert abs(float(image[..., 0].mean()) - 1.0) < 0.05


def _compare(blender, out, **kw):
    from nubis_addon.blender import ensure_registered
    from nubis_addon.blender.jobs import comparison
    from nubis_addon.blender.scene import scenepresets
    from nubis_addon.core.presets import load_preset

    blender.ops.wm.read_factory_settings(use_empty=True)
    ensure_registered()
    scene = blender.context.scene
    preset = load_preset("default")
    preset.extra["camera"]["rotation"] = [150.0, 0.0, 20.0]  # steeply up: a small camera bake
    preset.params["cirrus_coverage"] = 0.0
    scenepresets.apply_preset(scene, preset)
    edit = kw.pop("edit", None)
    if edit:
        edit(scene)
    voxel = kw.pop("voxel_size", 40.0)
    step = kw.pop("step", None)
    options = CompareOptions(width=32, height=18, mode="single", voxel_size=voxel, reference=False, **kw)
    return comparison.compare(scene, out, options, step=step)


@pytest.fixture(scope="module")
def first(tmp_path_factory, blender):
    out = tmp_path_factory.mktemp("reference")
    # The viewport's own convergence is test_full_parity.py's: 4 passes here, where Cycles' is the subject.
    return out, _compare(blender, out, samples=8, noise_target=10.0, viewport_passes=4)


def test_a_noise_target_adds_samples_until_cycles_noise_is_under_it(first):
    _out, m = first
    assert m["cycles_noise"]["luminance_rel_error"] <= 0.10, m["cycles_noise"]
    assert m["samples"] > 8 and m["cycles_reference"]["samples"] == m["samples"]
    assert not m["cycles_reference"]["reused"]


def test_an_unchanged_scene_reuses_the_reference_and_an_edit_cycles_sees_does_not(first, blender):
    out, m = first
    again = _compare(blender, out, samples=8, noise_target=10.0, reuse_reference=True, viewport_passes=4)
    assert again["cycles_reference"]["reused"], again["cycles_reference"]
    assert again["viewport_passes"] == 4, "the options' passes, not the noise target's goal"
    assert again["cycles_reference"]["key"] == m["cycles_reference"]["key"]
    assert again["samples"] == m["samples"] and again["cycles_noise"] == m["cycles_noise"]
    assert again["luminance_rel_error"] == pytest.approx(m["luminance_rel_error"], abs=0.03)

    # A viewport-only lighting term: Cycles never sees it, the reference stays.
    def ambient(scene):
        scene.nubis.lighting_ambient *= 1.5

    lit = _compare(blender, out, samples=8, noise_target=10.0, reuse_reference=True, viewport_passes=4, edit=ambient)
    assert lit["cycles_reference"]["reused"]

    # The sun brightens: Cycles renders again.
    def sun(scene):
        lamp = next(o for o in scene.objects if o.type == "LIGHT")
        lamp.data.energy *= 1.25

    moved = _compare(blender, out, samples=8, noise_target=10.0, reuse_reference=True, viewport_passes=4, edit=sun)
    assert not moved["cycles_reference"]["reused"]
    assert moved["cycles_reference"]["key"] != m["cycles_reference"]["key"]
    saved = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    assert saved["cycles_reference"]["key"] == moved["cycles_reference"]["key"]


def test_a_memory_bound_comparison_bakes_finer_by_what_the_clouds_fill_and_falls_back_when_they_fill_more(
    tmp_path, blender, monkeypatch
):
    """Where the bound (every evaluated voxel cloud) refuses the voxels the camera asks for, compare counts
    what the clouds fill with a probe and bakes at the camera's size; if the clouds then fill more than
    the probe said, the guarded bake stops and compare bakes at the size the bound allows."""
    from nubis_addon.blender.scene import cloudstate
    from nubis_addon.core import bakeplan

    seen = {}

    def limit_to(bytes_of):
        def edit(scene):
            state = cloudstate.state_from_scene(scene)
            inv = np.array(cloudstate.camera_inv_view_proj(scene, 32, 18))
            wanted = bakeplan.camera_footprint_voxel(state, inv, 32, 18, scene.nubis.bake_voxel_size)
            region = bakeplan.view_footprint(state, inv)
            plan = bakeplan.plan_bake(state, wanted, memory_limit=2**62, region=region)  # the bound, unlimited
            seen["wanted"] = wanted
            monkeypatch.setattr(bakeplan, "DEFAULT_MEMORY_LIMIT", int(bakeplan.BASE_BYTES + bytes_of(plan)))

        return edit

    # Half the bound's bytes at the camera's size: the bound refuses it, what the clouds fill does not.
    half = limit_to(lambda plan: plan.evaluated_voxels * plan.bytes_per_active_voxel / 2)
    said = []
    m = _compare(blender, tmp_path / "fine", samples=4, voxel_size=None, edit=half, step=said.append)
    assert any("counting what the clouds fill" in s for s in said)
    assert not any("fill more than measured" in s for s in said)
    assert m["voxel_size"] == pytest.approx(seen["wanted"])
    assert 0.0 < m["bake_active_share"] < 0.5
    # A probe that under-counts: the plan fits, the clouds' 2000 voxels' worth of memory does not.
    monkeypatch.setattr(bakeplan, "SHARE_MARGIN", 1e-6)
    monkeypatch.setattr(bakeplan, "SHARE_FLOOR", 1e-9)
    tiny = limit_to(lambda plan: 2000 * plan.bytes_per_active_voxel)
    said.clear()
    m = _compare(blender, tmp_path / "fallback", samples=4, voxel_size=None, edit=tiny, step=said.append)
    assert any("fill more than measured" in s for s in said), said
    assert m["voxel_size"] > seen["wanted"] and m["bake_active_share"] == 1.0


def test_the_comparisons_viewport_integrates_each_pixels_area(blender):
    """Passes whose rays cross their pixels at places of their own (ViewportShot.pixel_area) converge on
    the pixel's box-filtered value, as Cycles' one-pixel box filter does; passes through the centres
    converge on the centre's value, a different image wherever a cloud's edge crosses a pixel."""
    import dataclasses

    from nubis_addon.blender import ensure_registered
    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.blender.scene import scenepresets
    from nubis_addon.core.presets import load_preset

    blender.ops.wm.read_factory_settings(use_empty=True)
    ensure_registered()
    scene = blender.context.scene
    scenepresets.apply_preset(scene, load_preset("default"))
    w, h, ss = 32, 18, 8
    centre_shot = pipeline.viewport_shot(scene, w, h)
    fine = pipeline.viewport_shot(scene, w * ss, h * ss)
    # The same noise mip levels as the pixels (they follow the footprint): only where the rays go differs.
    fine.state.pixel_angle, fine.state.pixel_size = centre_shot.state.pixel_angle, centre_shot.state.pixel_size
    box = pipeline.downsample(pipeline.render_shot(fine, 2), ss)
    centres = pipeline.render_shot(centre_shot, 16)
    areas = pipeline.render_shot(dataclasses.replace(centre_shot, pixel_area=True), 16)

    def rmse(a, b):
        return float(np.sqrt(((a[..., 3] - b[..., 3]) ** 2).mean()))

    assert box[..., 3].std() > 0.1, "the view holds cloud edges"
    assert rmse(areas, box) < rmse(centres, box) / 3, (rmse(areas, box), rmse(centres, box))
