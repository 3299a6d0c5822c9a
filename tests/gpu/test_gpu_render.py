"""The offscreen render and the viewport draw, on the GPU (Mesa llvmpipe in CI)."""

import numpy as np
from gpu_helpers import split_coverage_scene


def test_gpu_context_is_real(blender):
    import gpu

    assert gpu.platform.renderer_get()  # fails loudly without a context; never skipped
    assert gpu.types.GPUOffScreen(4, 4)


def test_clouds_only_where_coverage_is_positive(make_scene):
    from nubis_addon.blender.jobs import pipeline

    scene = split_coverage_scene(make_scene)
    rgba = pipeline.render_viewport(scene, 96, 96)
    assert np.all(np.isfinite(rgba))
    left, right = rgba[:, :40, 3], rgba[:, 56:, 3]
    assert left.mean() > 0.3, left.mean()
    assert right.max() == 0.0, right.max()
    assert rgba[:, :40, :3].mean() > 0.05  # lit, not black


def test_zero_coverage_renders_nothing(make_scene):
    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.blender.scene import datafield

    scene = make_scene("default")
    res = scene.nubis.field_resolution
    datafield.write_field_image(scene.nubis, "a", np.zeros((res, res, 4), np.float32))
    datafield.write_field_image(scene.nubis, "cirrus", np.zeros((res, res, 4), np.float32))
    rgba = pipeline.render_viewport(scene, 64, 36)
    assert rgba.max() == 0.0


def test_default_preset_has_sky_and_cloud(make_scene):
    from nubis_addon.blender.jobs import pipeline

    rgba = pipeline.render_viewport(make_scene("default"), 128, 72)
    alpha = rgba[..., 3]
    assert 0.1 < (alpha > 0.05).mean() < 0.95  # some sky shows between clouds
    assert alpha[-10:].max() == 0.0  # below the horizon the ground hides the clouds


def test_viewport_draw_uses_the_render_code(make_scene):
    """The draw-handler path (one pixel in 16 per redraw into the temporal history, upscaled over the
    bound framebuffer) reproduces the offscreen render once every pixel has its sample."""
    import gpu

    from nubis_addon.blender.host import status
    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.blender.live import viewport
    from nubis_addon.blender.scene import cloudstate
    from nubis_addon.render.offscreens import read_pixels

    assert viewport.is_registered()
    scene = make_scene("default")
    w, h = 64, 36
    expected = pipeline.render_viewport(scene, w, h)
    inv = cloudstate.camera_inv_view_proj(scene, w, h)
    offscreen = gpu.types.GPUOffScreen(w, h, format="RGBA32F")
    with offscreen.bind():
        fb = gpu.state.active_framebuffer_get()
        for _ in range(16):
            fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
            tv = viewport.draw_view(
                scene, viewport.ViewDraw(inv, scene.camera.matrix_world.translation, w, h, key="test")
            )
        got = read_pixels(fb, w, h)[::-1]
    offscreen.free()
    assert tv.since_change == 16 and not tv.converged
    assert status.last_error() == ""
    # The viewport buffer is half float; everything else is the same shader.
    np.testing.assert_allclose(got, expected, atol=2e-3)


def test_motion_vectors_follow_the_wind(make_scene):
    """GDC22's scroll motion vectors: a cloud seen from above moves downwind by speed x timestep."""
    from gpu_helpers import split_coverage_scene

    from nubis_addon.blender.jobs import pipeline

    speed, time_scale = 100.0, 4.0  # the features move at speed x time scale in animation seconds
    scene = split_coverage_scene(
        make_scene, wind_speed=speed, wind_upward_bias=0.0, wind_direction=0.0, wind_time_scale=time_scale
    )
    w = h = 64
    m = pipeline.render_motion(scene, w, h)
    cloudy = m[..., 3] > 0.5
    assert cloudy.mean() > 0.2
    dt = 1.0 / (scene.render.fps / scene.render.fps_base)
    # A 90 degree square frustum looking straight down: a metre at height difference z spans w / (2 z)
    # pixels, and +X is to the right. z is the ray distance times the cosine to the view axis.
    rows, cols = np.mgrid[0:h, 0:w]
    ndc_x, ndc_y = (cols + 0.5) / w * 2 - 1, 1 - (rows + 0.5) / h * 2
    z = (m[..., 2] / np.sqrt(1 + ndc_x**2 + ndc_y**2))[cloudy]
    expected = speed * time_scale * dt * w / (2.0 * z)
    np.testing.assert_allclose(m[..., 0][cloudy], expected, rtol=0.01)
    assert np.abs(m[..., 1][cloudy]).max() < 0.01 * expected.max()
    assert np.all(m[m[..., 3] == 0] == 0.0)


def test_solid_shading_draws_the_worlds_sky_behind_the_clouds(make_scene):
    """Sky in Solid: the World's sky (the capture the clouds are lit by) behind the clouds, which stay
    over it, and nothing drawn in front of an object (the far plane)."""
    import gpu

    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.blender.live import viewport
    from nubis_addon.blender.scene import cloudstate
    from nubis_addon.render.offscreens import read_pixels

    scene = make_scene("default")
    assert scene.nubis.viewport_solid_sky  # on by default
    w, h = 64, 36
    inv = cloudstate.camera_inv_view_proj(scene, w, h)
    eye = scene.camera.matrix_world.translation
    offscreen = gpu.types.GPUOffScreen(w, h, format="RGBA32F")
    with offscreen.bind():
        fb = gpu.state.active_framebuffer_get()
        for _ in range(16):  # every pixel marched once
            fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
            viewport.draw_view(scene, viewport.ViewDraw(inv, eye, w, h, key="sky", sky=True))
        got = read_pixels(fb, w, h)[::-1]
        fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=0.5)  # an object in front of everything
        viewport.draw_view(scene, viewport.ViewDraw(inv, eye, w, h, key="sky", sky=True))
        covered = read_pixels(fb, w, h)[::-1]
    offscreen.free()
    clouds = pipeline.render_viewport(scene, w, h)
    sky = pipeline.sky_background(scene, w, h)
    assert np.all(got[..., 3] > 0.999) and np.abs(covered).max() == 0.0
    clear = clouds[..., 3] < 0.01
    assert clear.sum() > 50
    # The lighting's capture of the World is coarser than the final renders' background (the sun's glow
    # is softer), so per pixel it agrees within a few per cent, not exactly.
    rel = np.abs(got[clear][:, :3] - sky[clear]) / np.maximum(sky[clear], 1e-3)
    assert np.median(rel) < 0.03 and np.abs(got[clear][:, :3] - sky[clear]).mean() < 0.1 * sky[clear].mean()
    # The clouds over the sky: premultiplied over, as in Material Preview.
    over = clouds[..., :3] + sky * (1.0 - clouds[..., 3:4])
    assert np.abs(got[..., :3] - over).mean() < 0.05 * over.mean()
