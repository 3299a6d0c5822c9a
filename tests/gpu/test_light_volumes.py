"""The optical-depth volumes of the real-time light (core/lightvolume.py, docs/viewport.md#light-volumes):
filled only when what they hold changes, and closer to the reference march than GPU Pro 7's long tap
on a thick deck."""

from dataclasses import replace

import numpy as np


def test_volumes_are_refilled_only_when_what_they_hold_changes(make_scene):
    from nubis_addon.blender import runtime, scene_io
    from nubis_addon.core import lightvolume

    scene = make_scene("default")
    clouds = runtime.cloud_gpu(scene.nubis.noise_seed)
    state = scene_io.state_from_scene(scene)
    clouds.update(state)
    fills = clouds.volume_fills
    # Accumulation passes, a small camera move and the reference switch leave them as they are.
    clouds.update(replace(state, jitter_pass=5))
    radius = state.params["layer_draw_radius"]
    clouds.update(replace(state, draw_center=(state.draw_center[0] + 0.01 * radius, state.draw_center[1])))
    clouds.update(replace(state, light_mode=1))
    # A bake reads densities only: a new time without light fills nothing.
    clouds.update(replace(state, time=state.time + 99.0), light=False)
    # Lighting-only settings are applied when the volumes are read, not held in them.
    lit = {"lighting_ambient": 3.0, "lighting_sky_occlusion": 0.1, "lighting_ms_attenuation": 0.5}
    clouds.update(replace(state, params={**state.params, **lit}), light=True)
    clouds.update(replace(state, sun_radiance=(9.0, 1.0, 1.0), ambient=(0.0, 0.0, 2.0)))
    # Playback within one step of the wind's drift keeps them (a quarter texel: core/lightvolume.py).
    held = lightvolume.refill_time(state)
    clouds.update(replace(state, time=held + 1e-3))
    assert clouds.volume_fills == fills
    clouds.update(state)
    # The wind's time, the sun and a density setting refill them.
    clouds.update(replace(state, time=state.time + 10.0))
    clouds.update(replace(state, sun_direction=(0.5, 0.0, 0.866)))
    clouds.update(replace(state, params={**state.params, "density_sigma": state.params["density_sigma"] * 2}))
    assert clouds.volume_fills == fills + 3


def test_volumes_see_the_whole_deck_that_the_long_tap_misses(make_scene):
    """A stratus deck: the real-time light with the volumes against the reference march (the same light
    model with its optical depths marched: 48 fine samples towards the sun, 24 up and 24 down), and GPU
    Pro 7's long tap against the same, in one run."""
    from nubis_addon.blender import pipeline, runtime
    from nubis_addon.core import metrics

    scene = make_scene("stratus_overcast")
    clouds = runtime.cloud_gpu(scene.nubis.noise_seed)
    images = {}
    try:
        for label, light_mode, volume in (("reference", 1, 1), ("long tap", 0, 0), ("volumes", 0, 1)):
            clouds.switches["NUBIS_LIGHT_VOLUME"] = volume
            images[label] = pipeline.render_shot(pipeline.viewport_shot(scene, 64, 36, light_mode, "full"), 2)
    finally:
        clouds.switches["NUBIS_LIGHT_VOLUME"] = 1
    assert all(np.all(np.isfinite(i)) for i in images.values())
    long_tap = metrics.compare(images["long tap"], images["reference"])
    volumes = metrics.compare(images["volumes"], images["reference"])
    # Measured 2026-12-02 (5.3, llvmpipe), with the light model of docs/viewport.md#light-model: the long
    # tap 18.5 % error, bias +10.9 % (the deck beyond the cone is missed, so its inside is too bright);
    # the volumes sliced by altitude 11.1 %, bias -9.5 % (a box along the sun: 15.6 %, -15.6 %).
    assert long_tap["luminance_bias"] > 0.05, long_tap
    assert volumes["luminance_rel_error"] < 0.75 * long_tap["luminance_rel_error"], (volumes, long_tap)
    assert abs(volumes["luminance_bias"]) < 0.13, volumes
