"""The optical-depth volumes of the real-time light (core/lightvolume.py, docs/viewport.md#light-volumes):
filled only when what they hold changes, and closer to the reference march than GPU Pro 7's long tap
on a thick deck."""

from dataclasses import replace

import numpy as np


def test_volumes_are_refilled_only_when_what_they_hold_changes(make_scene):
    from nubis_addon.blender.host import runtime
    from nubis_addon.blender.scene import cloudstate
    from nubis_addon.core import lightvolume

    scene = make_scene("default")
    clouds = runtime.cloud_gpu(scene.nubis.noise_seed)
    state = cloudstate.state_from_scene(scene)
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
    from nubis_addon.blender.host import runtime
    from nubis_addon.blender.jobs import pipeline
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


_READBACK: list = []  # the readback shader, made once and never freed (see _sky_volume)


def _sky_volume(clouds) -> np.ndarray:
    """The sky volume read back: (slices, rows, columns, 2), the depth from the top and the sideways depth.
    Each slice is drawn into an offscreen by a fragment shader (texelFetch): Blender 4.5 reads only a 3D
    texture's first slice back. The shader is kept for the process: Blender remembers the last shader bound
    by its address, and a freed one whose address a new shader then takes leaves the freed program in
    use (the next cloud render drew this shader's output)."""
    if not _READBACK:
        _READBACK.append(_readback_shader())
    return _read_slices(_READBACK[0], clouds.volumes["sky_volume"])


def _readback_shader():
    import gpu

    info = gpu.types.GPUShaderCreateInfo()
    info.vertex_in(0, "VEC2", "pos")
    info.sampler(0, "FLOAT_3D", "volume")
    info.push_constant("INT", "slice")
    info.fragment_out(0, "VEC4", "color")
    info.vertex_source("void main() { gl_Position = vec4(pos, 0.0, 1.0); }")
    info.fragment_source("void main() { color = texelFetch(volume, ivec3(ivec2(gl_FragCoord.xy), slice), 0); }")
    return gpu.shader.create_from_info(info)


def _read_slices(shader, volume) -> np.ndarray:
    import gpu
    from gpu_extras.batch import batch_for_shader

    from nubis_addon.core import lightvolume
    from nubis_addon.render.offscreens import read_pixels

    batch = batch_for_shader(shader, "TRIS", {"pos": [(-1.0, -1.0), (3.0, -1.0), (-1.0, 3.0)]})
    w, h, depth = lightvolume.SIZE
    slices = []
    offscreen = gpu.types.GPUOffScreen(w, h, format="RGBA32F")
    try:
        with offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            for k in range(depth):
                fb.clear(color=(0.0, 0.0, 0.0, 0.0))
                shader.bind()
                shader.uniform_sampler("volume", volume)
                shader.uniform_int("slice", k)
                batch.draw(shader)
                slices.append(np.asarray(read_pixels(fb, w, h))[..., :2])
    finally:
        offscreen.free()
    return np.stack(slices)


def test_the_sky_volume_knows_a_towers_flank_from_a_decks_middle(make_scene):
    """The sideways channel (docs/viewport.md#sideways): 1 (the harmonic mean of depth + 1 over open
    directions) where no cloud is near, far more inside a deck, and less on a tower's flank than in its
    core; and the sky light it lets in brightens the towers under the World alone while a deck's look
    barely moves."""
    from nubis_addon.blender.host import runtime
    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.blender.scene import cloudstate
    from nubis_addon.core import metrics

    sides, lum = {}, {}
    for name in ("stratus_overcast", "cumulonimbus"):
        scene = make_scene(name, sun__strength=0.0)
        clouds = runtime.cloud_gpu(scene.nubis.noise_seed)
        clouds.update(cloudstate.state_from_scene(scene))
        volume = _sky_volume(clouds)
        depth_above, side = volume[..., 0], volume[..., 1]
        assert np.all(np.isfinite(volume)) and side.min() >= 0.99, side.min()
        # The domain's top slice holds no cloud, nor does anything beside it: open on every side.
        assert np.allclose(side[0], 1.0, atol=0.01), (side[0].min(), side[0].max())
        column = depth_above[-1]  # each column's whole depth
        # the slice where the cloud is densest (the deck's, the tower's middle)
        densest = int(np.argmax(np.diff(depth_above, axis=0).mean(axis=(1, 2))))
        sides[name] = (side[densest], column)
        shots = {}
        for value in (0.0, 1.0):
            shot = pipeline.viewport_shot(scene, 64, 36, 0, "full")
            shot.state.params["lighting_side_light"] = value
            shots[value] = pipeline.render_shot(shot, 2)
        lum[name] = [metrics.luminance(shots[v])[shots[v][..., 3] > 0.05].mean() for v in (0.0, 1.0)]
    side, column = sides["stratus_overcast"]
    middle = side[column > np.percentile(column, 90)]
    assert np.median(middle) > 20.0, np.median(middle)
    # The tower: its core (columns of more than half the deepest's depth) against its flanks (a fiftieth to
    # a fifth of it).
    side, column = sides["cumulonimbus"]
    core = column > 0.5 * column.max()
    flank = (column > 0.02 * column.max()) & (column < 0.2 * column.max())
    assert np.median(side[core]) > 3.0 * np.median(side[flank]), (np.median(side[core]), np.median(side[flank]))
    deck, tower = (lum[n][1] / lum[n][0] for n in ("stratus_overcast", "cumulonimbus"))
    # Measured 2026-12-03 (5.3, llvmpipe): the deck's middle 200 and the tower's core 206 against its
    # flanks' 2.4; Side Light 1 against 0 under the World alone: the tower +24.5 %, the deck +1.0 %.
    assert tower > 1.12, lum
    assert abs(deck - 1.0) < 0.2 * (tower - 1.0), lum
