"""compare's Cycles reference: sampled until its own noise is under a target, and reused by a later
comparison only when nothing Cycles sees has changed (blender/reference.py)."""

import json

import numpy as np
import pytest

from nubis_addon.blender import reference


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
    image, noise, taken = reference.sample_to_target(render, 16, 0.05, said.append)
    assert noise["luminance_rel_error"] <= 0.05
    assert taken == sum(s for s, _ in calls) and taken > 16
    assert [seed for _, seed in calls] == list(range(len(calls))), "every render has its own seed"
    assert len(calls) == 4 and calls[0][0] == calls[1][0] == 8 and calls[2][0] == calls[3][0]
    assert "more for 5 %" in said[0]
    assert abs(float(image[..., 0].mean()) - 1.0) < 0.05


def _compare(blender, out, **kw):
    from nubis_addon.blender import ensure_registered, pipeline, scene_io
    from nubis_addon.core.presets import load_preset

    blender.ops.wm.read_factory_settings(use_empty=True)
    ensure_registered()
    scene = blender.context.scene
    preset = load_preset("default")
    preset.extra["camera"]["rotation"] = [150.0, 0.0, 20.0]  # steeply up: a small camera bake
    preset.params["cirrus_coverage"] = 0.0
    scene_io.apply_preset(scene, preset)
    edit = kw.pop("edit", None)
    if edit:
        edit(scene)
    return pipeline.compare(scene, out, 32, 18, mode="single", voxel_size=40.0, reference=False, **kw)


@pytest.fixture(scope="module")
def first(tmp_path_factory, blender):
    out = tmp_path_factory.mktemp("reference")
    return out, _compare(blender, out, samples=8, noise_target=10.0)


def test_a_noise_target_adds_samples_until_cycles_noise_is_under_it(first):
    _out, m = first
    assert m["cycles_noise"]["luminance_rel_error"] <= 0.10, m["cycles_noise"]
    assert m["samples"] > 8 and m["cycles_reference"]["samples"] == m["samples"]
    assert not m["cycles_reference"]["reused"]


def test_an_unchanged_scene_reuses_the_reference_and_an_edit_cycles_sees_does_not(first, blender):
    out, m = first
    again = _compare(blender, out, samples=8, noise_target=10.0, reuse_reference=True)
    assert again["cycles_reference"]["reused"], again["cycles_reference"]
    assert again["cycles_reference"]["key"] == m["cycles_reference"]["key"]
    assert again["samples"] == m["samples"] and again["cycles_noise"] == m["cycles_noise"]
    assert again["luminance_rel_error"] == pytest.approx(m["luminance_rel_error"], abs=0.03)

    # A viewport-only lighting term: Cycles never sees it, the reference stays.
    def ambient(scene):
        scene.nubis.lighting_ambient *= 1.5

    lit = _compare(blender, out, samples=8, noise_target=10.0, reuse_reference=True, edit=ambient)
    assert lit["cycles_reference"]["reused"]

    # The sun brightens: Cycles renders again.
    def sun(scene):
        lamp = next(o for o in scene.objects if o.type == "LIGHT")
        lamp.data.energy *= 1.25

    moved = _compare(blender, out, samples=8, noise_target=10.0, reuse_reference=True, edit=sun)
    assert not moved["cycles_reference"]["reused"]
    assert moved["cycles_reference"]["key"] != m["cycles_reference"]["key"]
    saved = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    assert saved["cycles_reference"]["key"] == moved["cycles_reference"]["key"]
