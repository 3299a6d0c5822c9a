"""The sun each cloud sees (docs/sky.md#the-sun-each-cloud-sees): the march's sun at a point, read back
through the probe stage (tests/gpu_probe.py), against core/sky.transmittance's own integral along that
point's path to the sun; Earth's shadow where the planet's geometry puts it; the lamp's colour everywhere
without a Nubis sky's air."""

import math

import numpy as np
import pytest

ENERGY = 5.0  # the default preset's sun strength


def _sun_scene(make_scene, elevation: float, azimuth: float = 230.0):
    from nubis_addon.blender import runtime, scene_io

    scene = make_scene("default", sun__elevation=elevation, sun__azimuth=azimuth)
    state = scene_io.state_from_scene(scene)
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

    from nubis_addon.blender import runtime, scene_io, sky

    scene = make_scene("default", sun__elevation=2.0)
    scene.nubis.sky_sun_color = False
    lamp = sky.find_sun(scene)
    lamp.data.color = (1.0, 0.5, 0.25)
    state = scene_io.state_from_scene(scene)
    assert state.sun_air is None
    gpu_inputs = runtime.cloud_gpu(scene.nubis.noise_seed)
    gpu_inputs.update(state, light=False)
    got = probe_sun(gpu_inputs, np.array([[0.0, 0.0, h] for h in (300.0, 3000.0, 9000.0)], np.float32))
    np.testing.assert_allclose(got, np.tile(np.array([1.0, 0.5, 0.25]) * lamp.data.energy, (3, 1)), rtol=1e-5)
