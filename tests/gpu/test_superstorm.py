"""Superstorms on the GPU: stencils stay inside their radius, the vortex slows outward, lightning
keyframes light the storm on their frame, and the baked glow grid stays inside the storm."""

import math

import numpy as np
import pytest

from nubis_addon.core.jobs import BakeOptions


@pytest.fixture
def storm_scene(make_scene):
    scene = make_scene("superstorm")
    storm = scene.nubis.storms[0]
    return scene, storm


def _gpu(scene):
    from nubis_addon.blender.host import runtime
    from nubis_addon.blender.scene import cloudstate

    state = cloudstate.state_from_scene(scene)
    clouds = runtime.cloud_gpu(scene.nubis.noise_seed)
    clouds.update(state, light=False)  # densities and the vortex only
    return clouds, state


def test_outside_every_stencil_the_density_is_the_storm_free_density(storm_scene, blender):
    from gpu_probe import probe_density

    from nubis_addon.blender.scene import superstorms

    scene, storm = storm_scene
    scene.nubis.layers[0].remap = (0.3, 0.7, 0.0, 0.5)
    blender.ops.nubis.generate_field()
    scene.nubis.density_cover = 0.3  # more fair-weather clouds around the storm (the preset has 2 %)
    cx, cy = superstorms.storm_centre(storm)
    rng = np.random.default_rng(3)
    n = 6000
    angle = rng.uniform(0, 2 * math.pi, n)
    dist = rng.uniform(storm.radius * 1.001, storm.radius * 2.5, n)
    pts = np.stack([cx + dist * np.cos(angle), cy + dist * np.sin(angle), rng.uniform(1500, 4000, n)], axis=1)
    inside = np.stack(
        [cx + 0.3 * storm.radius * np.cos(angle), cy + 0.3 * storm.radius * np.sin(angle), rng.uniform(1500, 4000, n)],
        axis=1,
    )
    clouds, _ = _gpu(scene)
    with_storm = probe_density(clouds, pts)
    with_storm_inside = probe_density(clouds, inside)
    blender.ops.nubis.storm_remove()
    assert len(scene.nubis.storms) == 0
    clouds, _ = _gpu(scene)
    without = probe_density(clouds, pts)
    without_inside = probe_density(clouds, inside)
    assert (without[:, 0] > 0).mean() > 0.05  # the comparison covers real clouds
    np.testing.assert_array_equal(with_storm[:, :2], without[:, :2])
    assert with_storm_inside[:, 0].sum() > 2 * without_inside[:, 0].sum()  # and the storm did change its inside


def test_vortex_turns_faster_near_the_centre(storm_scene):
    from gpu_probe import probe_vortex

    from nubis_addon.blender.scene import superstorms

    scene, storm = storm_scene
    cx, cy = superstorms.storm_centre(storm)
    # Points in the middle of rings 0..4 (away from the blended overlaps), on a line out of the centre.
    fractions = (np.arange(5) + 0.5) / 6.0
    xy = np.stack([cx + fractions * storm.radius, np.full(5, cy)], axis=1)
    turned = []
    for seconds in (0.0, 10.0):
        scene.nubis.wind_time_offset = seconds
        clouds, state = _gpu(scene)
        moved = probe_vortex(clouds, xy)[:, :2]
        turned.append(np.arctan2(moved[:, 1] - cy, moved[:, 0] - cx))
    speed = np.angle(np.exp(1j * (turned[1] - turned[0]))) / 10.0  # radians per second, unwrapped
    assert speed[0] == pytest.approx(storm.spin, rel=0.05)  # the inner ring spins at the storm's spin
    assert np.all(np.diff(speed) < 0), speed  # each ring outward turns slower
    assert speed[-1] > 0


def test_lightning_keyframe_lights_its_frame_only(storm_scene, blender):
    from nubis_addon.blender.jobs import pipeline

    scene, storm = storm_scene
    scene.camera.location = (0.0, 3000.0, 2.0)
    scene.camera.rotation_euler = (math.radians(150), 0.0, 0.0)
    scene.frame_set(100)
    assert blender.ops.nubis.lightning_sequence(flashes=1, discharges=0, peak=400.0) == {"FINISHED"}
    scene.frame_set(100)
    assert storm.flash == pytest.approx(400.0 * 0.25)
    lit = pipeline.render_viewport(scene, 48, 27)
    at_flash = (storm.flash_x, storm.flash_y)
    scene.frame_set(90)
    assert storm.flash == 0.0
    # The position is set ahead of the flash, for the viewport's flash mask (GDC22).
    assert (storm.flash_x, storm.flash_y) == at_flash
    dark = pipeline.render_viewport(scene, 48, 27)
    luminance = np.array([0.2126, 0.7152, 0.0722])
    assert (lit[..., :3] @ luminance).mean() > 1.1 * (dark[..., :3] @ luminance).mean()
    # Ten frames earlier the picture is exactly the flash-free one.
    scene.animation_data_clear()
    storm.flash = 0.0
    scene.frame_set(90)
    np.testing.assert_array_equal(dark, pipeline.render_viewport(scene, 48, 27))


def test_baked_glow_grid_stays_inside_the_storm(storm_scene, tmp_path):
    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.blender.scene import superstorms
    from nubis_addon.core import vdbwrite

    scene, storm = storm_scene
    result = pipeline.bake(scene, tmp_path / "storm.vdb", BakeOptions(voxel_size=500.0))
    info = vdbwrite.read_grid_info(result.path)
    # The storm's darkening bakes as absorption (GDC22; docs/sources.md#storm-darkening), its glow as emission.
    assert set(info) == {"density", "glow", "absorption"}
    glow, lo = vdbwrite.read_grid_array(result.path, "glow")
    z, y, x = np.nonzero(glow > 0)
    assert len(x) > 10
    cx, cy = superstorms.storm_centre(storm)
    wx = result.plan.origin[0] + (x + lo[0]) * 500.0
    wy = result.plan.origin[1] + (y + lo[1]) * 500.0
    assert np.hypot(wx - cx, wy - cy).max() <= storm.radius


def _rotated(img: np.ndarray, angle: float) -> np.ndarray:
    """`img` turned by `angle` radians about its centre in image coordinates, bilinear."""
    n = img.shape[0]
    c = (n - 1) / 2.0
    y, x = np.mgrid[0:n, 0:n] - c
    xs = np.clip(np.cos(angle) * x + np.sin(angle) * y + c, 0, n - 1.001)
    ys = np.clip(-np.sin(angle) * x + np.cos(angle) * y + c, 0, n - 1.001)
    x0, y0 = xs.astype(int), ys.astype(int)
    fx, fy = xs - x0, ys - y0
    top = img[y0, x0] * (1 - fx) + img[y0, x0 + 1] * fx
    bottom = img[y0 + 1, x0] * (1 - fx) + img[y0 + 1, x0 + 1] * fx
    return top * (1 - fy) + bottom * fy


def _vortex_views(make_scene, blend: float, size: int = 96, dt: float = 0.4):
    """Luminance of the storm seen straight up from under its centre at two moments `dt` apart, and
    the motion vectors of the second."""
    import dataclasses

    from nubis_addon.blender.host import runtime
    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.blender.scene import superstorms
    from nubis_addon.render import engine

    scene = make_scene("superstorm", wind_speed=0.0)
    storm = scene.nubis.storms[0]
    storm.spin = 0.5
    storm.blend = blend
    cx, cy = superstorms.storm_centre(storm)
    scene.camera.location = (cx, cy, 200.0)
    scene.camera.rotation_euler = (np.pi, 0.0, 0.0)
    shot = pipeline.viewport_shot(scene, size, size)
    shot.state.jitter = False
    t0 = shot.state.time
    before = pipeline.render_shot(shot)[..., :3].mean(axis=-1)
    shot.state.time = t0 + dt
    after = pipeline.render_shot(shot)[..., :3].mean(axis=-1)
    clouds = runtime.cloud_gpu(shot.noise_seed)
    clouds.update(dataclasses.replace(shot.state, motion_dt=dt))
    motion = engine.render_motion(clouds, shot.inv_view_proj, shot.eye, shot.inv_view_proj.inverted(), size, size)
    c = (size - 1) / 2.0
    y, x = np.mgrid[0:size, 0:size] - c
    r = np.hypot(x, y)
    ring = (r > 10) & (r < 0.45 * size) & (motion[..., 3] > 0.3)
    # The angle the motion vectors turn by (tangential offset over radius, image coordinates).
    implied = float(np.mean(((x * motion[..., 1] - y * motion[..., 0]) / np.maximum(r, 1.0) ** 2)[ring]))
    return before, after, ring, implied


def test_motion_vectors_follow_the_rendered_vortex(make_scene):
    """GDC22's storm motion vectors must say where the visible vortex really moves. Looking up at the
    mesocyclone from under its centre, the rendered picture at one moment is matched against the next
    by turning it (the best-fitting angle is what the eye sees), and the motion vectors must turn the
    same way by the same angle. The detail noise is read at rotate(p, +angle(t)), so the clouds
    themselves turn clockwise seen from above (motion vectors that turned the other way passed the
    test this one replaces)."""
    before, after, ring, implied = _vortex_views(make_scene, 1.0)
    assert ring.sum() > 500
    angles = np.linspace(-0.3, 0.3, 241)
    misfit = [float(((_rotated(before, a) - after)[ring] ** 2).mean()) for a in angles]
    seen = float(angles[int(np.argmin(misfit))])
    assert abs(seen) > 0.05, "the rendered vortex did not turn"
    assert implied == pytest.approx(seen, rel=0.15)


def test_motion_vectors_fade_in_with_the_storm(make_scene):
    """While a storm grows in (lifecycle blend under 0.25) its vortex turns slower by the density's
    fade, smoothstep(0, 0.25, blend), and only that share of its detail turns at all: the motion
    vectors slow down by the fade squared."""
    *_, full = _vortex_views(make_scene, 1.0)
    *_, young = _vortex_views(make_scene, 0.1)
    fade = 0.1 / 0.25
    fade = fade * fade * (3.0 - 2.0 * fade)
    assert young / full == pytest.approx(fade * fade, rel=0.05)


def test_removing_a_storm_keeps_the_others_animation(storm_scene, blender):
    scene, _storm = storm_scene
    s = scene.nubis
    assert blender.ops.nubis.storm_add() == {"FINISHED"}
    s.active_storm = 1
    scene.frame_set(1)
    assert blender.ops.nubis.storm_lifecycle(ramp_in=1.0, hold=1.0, ramp_out=1.0) == {"FINISHED"}
    s.active_storm = 0
    assert blender.ops.nubis.storm_remove() == {"FINISHED"}
    from nubis_addon.blender.scene import sceneparams

    paths = {fc.data_path for fc in sceneparams.fcurves(scene)}
    assert paths == {"nubis.storms[0].blend"}  # the keyed storm moved to index 0 and kept its keys
    scene.frame_set(1 + 24)
    assert s.storms[0].blend == pytest.approx(1.0)
    assert blender.ops.nubis.storm_remove() == {"FINISHED"}
    assert not sceneparams.fcurves(scene)


def test_bake_operator_refuses_a_path_relative_to_an_unsaved_file(storm_scene, blender):
    assert not blender.data.filepath
    with pytest.raises(RuntimeError, match="not saved yet"):
        blender.ops.nubis.bake_vdb(filepath="//clouds.vdb")
