"""The sun each cloud sees (docs/sky.md#the-sun-each-cloud-sees): the march's sun at a point, read back
through the probe stage (tests/gpu_probe.py), against core/sky.transmittance's own integral along that
point's path to the sun; Earth's shadow where the planet's geometry puts it; the lamp's colour everywhere
without a Nubis sky's air."""

import dataclasses
import math

import numpy as np
import pytest

ENERGY = 5.0  # the default preset's sun strength


def _sun_scene(make_scene, elevation: float, azimuth: float = 230.0):
    from nubis_addon.blender.host import runtime
    from nubis_addon.blender.scene import cloudstate

    scene = make_scene("default", sun__elevation=elevation, sun__azimuth=azimuth)
    state = cloudstate.state_from_scene(scene)
    gpu_inputs = runtime.cloud_gpu(scene.nubis.noise_seed)
    gpu_inputs.update(state, light=False)
    return scene, state, gpu_inputs


def _expected(state, points: np.ndarray) -> np.ndarray:
    """core/sky.transmittance along each point's own path: its altitude over the clouds' planet and the
    sun's elevation over its own horizon there, times the sun above the air."""
    from nubis_addon.core import sky

    planet = state.params["layer_planet_radius"]
    sun = np.array(state.sun_direction) / np.linalg.norm(state.sun_direction)
    rows = []
    for p in points.astype(np.float64):
        centred = p + np.array([0.0, 0.0, planet])
        up = centred / np.linalg.norm(centred)
        altitude = np.linalg.norm(centred) - planet
        elevation = math.asin(float(np.clip(up @ sun, -1.0, 1.0)))
        rows.append(np.array(sky.transmittance(elevation, altitude, *state.sun_air)) * np.array(state.sun_radiance))
    return np.array(rows)


@pytest.mark.parametrize("elevation", [6.0, 4.0, 1.0, 0.0, -1.0])
def test_the_march_s_sun_at_each_altitude_is_the_air_s_transmittance(make_scene, elevation):
    """Within 2 % of the integral (1e-4 of the sun's strength where hardly any light is left), at
    altitudes from 500 m to 12 km, over the camera and 60 km towards and away from the sun."""
    from gpu_probe import probe_sun

    _scene, state, gpu_inputs = _sun_scene(make_scene, elevation)
    assert state.sun_air is not None and state.sun_radiance == (ENERGY,) * 3
    sun = np.array(state.sun_direction)
    towards = np.array([sun[0], sun[1], 0.0]) / math.hypot(sun[0], sun[1])
    points = np.array(
        [
            side * 60e3 * towards + np.array([0.0, 0.0, h])
            for side in (-1.0, 0.0, 1.0)
            for h in (500, 1500, 2500, 4000, 8000, 12000)
        ],
        np.float32,
    )
    got = probe_sun(gpu_inputs, points).astype(np.float64)
    want = _expected(state, points)
    np.testing.assert_allclose(got, want, rtol=0.02, atol=1e-4 * ENERGY)
    # Higher is redder-to-whiter and brighter: the light has less air left to cross.
    column = got[6:12]
    lit = column[:, 0] > 1e-3
    assert np.all(np.diff(column[lit, 0]) > 0.0)


def test_earth_s_shadow_line_is_where_the_planet_s_geometry_puts_it(make_scene):
    """With the sun 1 degree below the horizon, a point over the camera is in the planet's shadow below
    R (1 / cos 1 deg - 1), about 969 m, and lit above it; 60 km along the ground towards the sun the line is
    lower (the sun stands higher over the horizon there), 60 km away higher (altitudes over the planet's
    curve, 80 m apart)."""
    from gpu_probe import probe_sun

    from nubis_addon.core import sky

    _scene, state, gpu_inputs = _sun_scene(make_scene, -1.0)
    line = sky.EARTH_RADIUS * (1.0 / math.cos(math.radians(1.0)) - 1.0)
    heights = np.array([line - 40.0, line + 40.0])
    over = probe_sun(gpu_inputs, np.array([[0.0, 0.0, h] for h in heights], np.float32))
    assert np.all(over[0] == 0.0) and over[1, 0] > 0.0
    sun = np.array(state.sun_direction)
    towards = np.array([sun[0], sun[1], 0.0]) / math.hypot(sun[0], sun[1])
    planet = state.params["layer_planet_radius"]
    tilt = 60e3 / planet  # the horizon 60 km along the ground leans by this angle
    for side in (1.0, -1.0):
        moved = sky.EARTH_RADIUS * (1.0 / math.cos(math.radians(1.0) - side * tilt) - 1.0)
        assert (moved < line) == (side > 0)
        up = math.sin(side * tilt) * towards + math.cos(side * tilt) * np.array([0.0, 0.0, 1.0])
        near = [up * (planet + moved + dh) - np.array([0.0, 0.0, planet]) for dh in (-40.0, 40.0)]
        got = probe_sun(gpu_inputs, np.array(near, np.float32))
        assert np.all(got[0] == 0.0) and got[1, 0] > 0.0, (side, moved, got)


def test_without_a_nubis_sky_every_cloud_takes_the_lamp_s_colour(make_scene):
    """Sun Color off (the artist's own lamp colour): no air, the lamp's colour x strength at every
    altitude, the sun below the horizon included."""
    from gpu_probe import probe_sun

    from nubis_addon.blender.host import runtime
    from nubis_addon.blender.scene import cloudstate, skyground

    scene = make_scene("default", sun__elevation=2.0)
    scene.nubis.sky_sun_color = False
    lamp = skyground.find_sun(scene)
    lamp.data.color = (1.0, 0.5, 0.25)
    state = cloudstate.state_from_scene(scene)
    assert state.sun_air is None
    gpu_inputs = runtime.cloud_gpu(scene.nubis.noise_seed)
    gpu_inputs.update(state, light=False)
    got = probe_sun(gpu_inputs, np.array([[0.0, 0.0, h] for h in (300.0, 3000.0, 9000.0)], np.float32))
    np.testing.assert_allclose(got, np.tile(np.array([1.0, 0.5, 0.25]) * lamp.data.energy, (3, 1)), rtol=1e-5)


@pytest.mark.parametrize("engine", ["EEVEE", "CYCLES"])
def test_f12_at_minus_one_degree_shows_lit_clouds_over_an_unlit_ground(make_scene, blender, engine, tmp_path):
    """The sun 1 degree below the horizon, a 200 km ground, the camera 400 m up looking 8 degrees down:
    F12 with the sun's strength at 5 against F12 with it at 0. Above the horizon the clouds (over 1.5 km,
    above the shadow line) gain the sun's red light; the ground, in Earth's shadow, gains nothing."""
    from nubis_addon.blender.scene import cloudstate, skyground
    from nubis_addon.core import imageio
    from nubis_addon.core import sky as skymath

    scene = make_scene("default", sun__elevation=-1.0, sun__azimuth=0.0)
    blender.ops.mesh.primitive_plane_add(size=200000.0)
    cam = scene.camera
    cam.location = (0.0, 0.0, 400.0)
    cam.rotation_euler = (math.radians(82.0), 0.0, 0.0)  # towards +Y, the sun's side
    cam.data.lens = 18.0
    width, height = 96, 54
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = width, height, 100
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.cycles.device, scene.cycles.samples, scene.cycles.use_denoising = "CPU", 8, False
    scene.eevee.taa_render_samples = 4
    scene.eevee.shadow_resolution_scale = 0.25
    scene.nubis.sky_environment_width = 128
    names = {e.identifier for e in blender.types.RenderSettings.bl_rna.properties["engine"].enum_items}
    scene.render.engine = (
        engine if engine == "CYCLES" else next(e for e in ("BLENDER_EEVEE_NEXT", "BLENDER_EEVEE") if e in names)
    )
    lamp = skyground.find_sun(scene)
    assert max(lamp.data.color) == 0.0  # the ground's transmittance: Earth's shadow
    images = {}
    for energy in (5.0, 0.0):
        lamp.data.energy = energy
        scene.render.filepath = str(tmp_path / f"sun_{energy:g}.exr")
        blender.ops.render.render(write_still=True)
        images[energy] = imageio.read_image(tmp_path / f"sun_{energy:g}.exr")[..., :3].astype(np.float64)
    inv = cloudstate.camera_inv_view_proj(scene, width, height)
    up = skymath.camera_directions(inv, cloudstate.camera_eye(scene), width, height)[..., 2]
    gain = images[5.0] - images[0.0]
    sky_rows, ground_rows = up > 0.05, up < -0.05
    assert sky_rows.sum() > 300 and ground_rows.sum() > 300
    red, green = gain[..., 0][sky_rows], gain[..., 1][sky_rows]
    # The clouds glow: over a tenth of the sky's pixels gain red light, more red than green (measured at
    # 96x54 on 5.3: 16 % of them in Cycles at 8 samples, 20 % in EEVEE).
    lit = red > 0.02 * images[0.0][..., 0][sky_rows].mean()
    assert lit.mean() > 0.1, (engine, lit.mean())
    assert red[lit].mean() > 2.0 * green[lit].mean()
    # The ground: in Earth's shadow, nothing from the sun directly; it gains only the glowing clouds' light
    # (they light the scene as part of the sky), under 3 % of its own (1.3 % in EEVEE, 1.5 % in Cycles).
    ground = np.abs(gain[ground_rows]).mean()
    assert ground < 0.03 * images[0.0][ground_rows].mean(), (engine, ground, images[0.0][ground_rows].mean())


@pytest.mark.parametrize("elevation", [4.0, -1.0])
def test_cycles_lights_the_bake_through_the_same_air(make_scene, blender, elevation, tmp_path):
    """What Cycles renders the bake with (blender/jobs/sun_air.py): the lamp's sun above the air, and a shell
    only shadow rays see. Three white cards facing the sun at 0.3, 2.5 and 6 km, seen from the sun's side, lit by
    the sun alone (the World black): each gets the sun times the air's
    transmittance from where it stands (core/sky.transmittance) within 3 %, the card in Earth's shadow
    nothing; and the lamp's colour is the ground's again afterwards."""
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Vector

    from nubis_addon.blender.jobs import sun_air
    from nubis_addon.blender.scene import cloudstate, skyground
    from nubis_addon.core import imageio

    scene = make_scene("default", sun__elevation=elevation, sun__azimuth=90.0)
    lamp = skyground.find_sun(scene)
    ground_colour = tuple(lamp.data.color)
    state = cloudstate.state_from_scene(scene)
    sun = Vector(state.sun_direction).normalized()
    centres = [Vector((0.0, y, z)) for y, z in ((-3000.0, 300.0), (0.0, 2500.0), (3000.0, 6000.0))]
    white = blender.data.materials.new("white card")
    if white.node_tree is None:
        white.use_nodes = True
    white.node_tree.nodes.clear()
    diffuse = white.node_tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    out = white.node_tree.nodes.new("ShaderNodeOutputMaterial")
    white.node_tree.links.new(diffuse.outputs[0], out.inputs["Surface"])
    for c in centres:
        blender.ops.mesh.primitive_plane_add(size=1000.0, location=c)
        blender.context.object.rotation_euler = sun.to_track_quat("Z", "Y").to_euler()
        blender.context.object.data.materials.append(white)
    # Seen from the sun's side, square on: y across the picture, the altitude up it (100 m a pixel).
    cam = blender.data.objects.new("towards the cards", blender.data.cameras.new("towards the cards"))
    cam.data.type, cam.data.ortho_scale, cam.data.clip_end = "ORTHO", 9000.0, 50000.0
    cam.location = Vector((0.0, 0.0, 3000.0)) + sun * 20000.0
    cam.rotation_euler = (-sun).to_track_quat("-Z", "Z").to_euler()
    scene.collection.objects.link(cam)
    scene.camera = cam
    scene.render.engine = "CYCLES"
    scene.cycles.device, scene.cycles.samples, scene.cycles.use_denoising = "CPU", 4, False
    scene.cycles.max_bounces = 0
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 90, 90, 100
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.nubis.sky_render_clouds = False
    scene.cycles.samples = 64  # Cycles picks one texel of the table per look-up (stochastic filtering)
    for node in scene.world.node_tree.nodes:  # a black World: the sun's light alone, no sky noise
        if node.bl_idname == "ShaderNodeBackground":
            node.inputs["Strength"].default_value = 0.0
    lamp.data.energy = 5.0
    # A point sun, as the march's: the lamp's 0.53-degree disc averages the transmittance over half a
    # degree, which near the shadow line is not its value at the disc's centre.
    lamp.data.angle = 0.0
    scene.render.filepath = str(tmp_path / "cards.exr")
    with sun_air.above_the_air(scene) as through:
        assert through and lamp.data.color[:] == (1.0, 1.0, 1.0)
        blender.ops.render.render(write_still=True)
    lit = imageio.read_image(scene.render.filepath)[..., :3].astype(np.float64)
    assert tuple(lamp.data.color) == pytest.approx(ground_colour)
    assert _shell_gone(blender)
    blender.context.view_layer.update()
    seen = [world_to_camera_view(scene, cam, c) for c in centres]  # from the bottom left; images: top row first
    cells = [(int((1.0 - v.y) * 90), int(v.x * 90)) for v in seen]
    got = np.array([lit[row - 2 : row + 2, col - 2 : col + 2].mean(axis=(0, 1)) for row, col in cells])
    # Each 4x4-pixel window is 400 m of card across the altitudes it spans (steep near the shadow line):
    # what the shell gave is compared with the transmittance's mean over the window's pixels, each where
    # its camera ray meets the card.
    right, up = (cam.matrix_world.to_3x3() @ Vector(axis) for axis in ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)))
    lit_state = dataclasses.replace(state, sun_radiance=(5.0,) * 3)
    want = []
    for (row, col), c in zip(cells, centres, strict=True):
        hits = []
        for i in range(row - 2, row + 2):
            for j in range(col - 2, col + 2):
                o = cam.location + ((j + 0.5) / 90 - 0.5) * 9000.0 * right + (0.5 - (i + 0.5) / 90) * 9000.0 * up
                hits.append(tuple(o - sun * (o - c).dot(sun)))
        want.append(_expected(lit_state, np.array(hits, np.float32)).mean(axis=0) / math.pi)
    want = np.array(want)
    np.testing.assert_allclose(got, want, rtol=0.03, atol=2e-3 * want.max())
    if elevation < 0.0:
        assert np.all(want[0] == 0.0) and want[2, 0] > 0.0  # the low card in Earth's shadow, the high one lit


def _shell_gone(blender) -> bool:
    from nubis_addon.blender.jobs import sun_air

    return (
        blender.data.objects.get(sun_air.SHELL_NAME) is None and blender.data.materials.get(sun_air.SHELL_NAME) is None
    )


def test_a_cloud_s_flank_takes_the_horizon_s_light_at_the_luminance_its_calibration_fixed(make_scene):
    """docs/viewport.md#light-model: at the sun a Nubis sky is calibrated at (30°) the flank's light has
    the luminance of the light from above; at 4° it is brighter than that and far warmer (the glow
    along the horizon against the blue overhead); the march's clouds take its colour."""
    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.core import metrics

    def lum(c):
        return float(metrics.luminance(np.array(c, np.float32)))

    _scene, day, _gpu = _sun_scene(make_scene, 30.0)
    assert lum(day.ambient_flank) == pytest.approx(lum(day.ambient), rel=0.01)
    scene, low, _gpu = _sun_scene(make_scene, 4.0)
    assert 1.02 < lum(low.ambient_flank) / lum(low.ambient) < 1.3
    warmth = (low.ambient_flank[0] / low.ambient_flank[2]) / (low.ambient[0] / low.ambient[2])
    assert warmth > 1.5
    shot = pipeline.viewport_shot(scene, 96, 54, 0, "full")
    flank = pipeline.render_shot(shot, 2)
    shot.state = dataclasses.replace(shot.state, ambient_flank=shot.state.ambient)
    above = pipeline.render_shot(shot, 2)
    cloud = (flank[..., 3] > 0.5) & (above[..., 3] > 0.5)
    assert cloud.sum() > 200
    red_blue = [img[cloud][:, 0].sum() / img[cloud][:, 2].sum() for img in (flank, above)]
    assert red_blue[0] > 1.03 * red_blue[1], red_blue
