"""Fixes of the formula audit: each test failed before its fix (GPU renders on llvmpipe)."""

from __future__ import annotations

import numpy as np


def _over(front: np.ndarray, back: np.ndarray) -> np.ndarray:
    return front + (1.0 - front[..., 3:4]) * back


def test_cirrus_covers_the_clouds_seen_from_above(make_scene):
    """From 20 km up the cirrus layer (9 km) is in front of the clouds below it, not behind them."""
    from nubis_addon.blender import pipeline

    def render(**overrides):
        scene = make_scene("default", **{"cirrus_opacity": 4.0, "cirrus_coverage": 3.0, **overrides})
        scene.camera.location = (0.0, 0.0, 20000.0)
        scene.camera.rotation_euler = (0.0, 0.0, 0.0)  # straight down
        shot = pipeline.viewport_shot(scene, 64, 64)
        shot.state.jitter = False
        return pipeline.render_shot(shot)

    full = render()
    clouds = render(cirrus_coverage=0.0)
    cirrus = render(density_coverage=0.0)
    both = (cirrus[..., 3] > 0.5) & (clouds[..., 3] > 0.5)
    assert both.sum() > 30, "the test needs thick cirrus over thick cloud"
    front = np.abs(full - _over(cirrus, clouds))[both].mean()
    behind = np.abs(full - _over(clouds, cirrus))[both].mean()
    assert front < 0.5 * behind


def test_cirrus_dims_the_clouds_but_keeps_their_powder_edges(make_scene):
    """GPU Pro 7's powder term darkens the sun-facing edges from the cloud's own depth towards the sun.
    A cirrus of optical depth about 1 between them and the sun must dim the clouds as a whole, not
    fill in that darkening (it did when its depth was added to the cloud's)."""
    from nubis_addon.blender import pipeline

    luminance = np.array([0.2126, 0.7152, 0.0722])

    def render(powder: float, cirrus: bool):
        overrides = {"lighting_powder": powder, "cirrus_coverage": 3.0 if cirrus else 0.0, "cirrus_opacity": 1.0}
        # The sun 20 degrees up behind the camera (the time-of-day picture's last shot).
        overrides.update(sun__elevation=20.0, sun__azimuth=200.0, camera__rotation=[100.0, 0.0, 20.0])
        scene = make_scene("default", **overrides)
        shot = pipeline.viewport_shot(scene, 96, 54)
        shot.state.jitter = False
        return pipeline.render_shot(shot)

    plain, plain_powder = render(0.0, False), render(1.0, False)
    veiled, veiled_powder = render(0.0, True), render(1.0, True)
    opaque = (plain[..., 3] > 0.95) & (veiled[..., 3] > 0.95)
    assert opaque.sum() > 200

    def lum(img):
        return (img[..., :3] @ luminance)[opaque]

    # The powder term darkens where the depth towards the sun is small and brightens deeper in (GPU
    # Pro 7's factor 2): its darkening is the mean shortfall where it darkens.
    def darkening(with_powder, without):
        return float(np.maximum(0.0, 1.0 - lum(with_powder) / lum(without)).mean())

    edges, veiled_edges = darkening(plain_powder, plain), darkening(veiled_powder, veiled)
    assert edges > 0.02, "the test needs visible powder edges"
    assert abs(veiled_edges - edges) <= 0.1 * edges
    assert lum(veiled).mean() < 0.95 * lum(plain).mean()  # the cirrus still dims the clouds
