"""A stroke painted by script, saved, and rendered from the .blend by `render --blend` from 20 km straight
up: the cover rises under the stroke and nowhere else."""

from __future__ import annotations

import numpy as np
from conftest import run_cli
from gpu_helpers import stroke_elements

STROKE_X = (-8000.0, 8000.0)  # along y = 0
RADIUS = 2500.0
VIEW = 24000.0  # the orthographic camera's width, metres
SIZE = 120


def stroke(points=9):
    return stroke_elements(np.linspace(*STROKE_X, points))


def top_camera(bpy, scene):
    """The scene camera 20 km up, looking straight down, orthographic over VIEW metres."""
    cam = scene.camera
    cam.location = (0.0, 0.0, 20000.0)
    cam.rotation_euler = (0.0, 0.0, 0.0)
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = VIEW
    cam.data.clip_end = 100000.0
    scene.render.resolution_x = scene.render.resolution_y = SIZE


def distance_to_stroke() -> np.ndarray:
    """Each pixel's distance (metres, on the ground) from the stroke's centre line, bottom row first."""
    t = (np.arange(SIZE) + 0.5) / SIZE - 0.5
    xs, ys = np.meshgrid(t * VIEW, t * VIEW)
    dx = np.maximum(np.maximum(STROKE_X[0] - xs, xs - STROKE_X[1]), 0.0)
    return np.hypot(dx, ys)


def cover(path) -> np.ndarray:
    from nubis_addon.core import imageio

    rgba = imageio.read_image(path)
    return (rgba[::-1, :, 3] > 0.05).astype(np.float64)  # top row first on disk


def test_a_scripted_stroke_changes_the_cover_under_it_and_nowhere_else(blender, make_scene, tmp_path, cache_dir):
    scene = make_scene("clear_sky")
    top_camera(blender, scene)
    before_blend, after_blend = tmp_path / "before.blend", tmp_path / "after.blend"
    blender.ops.wm.save_as_mainfile(filepath=str(before_blend), copy=True)
    result = blender.ops.nubis.paint_field(channel="COVERAGE", radius=RADIUS, strength=1.0, stroke=stroke())
    assert result == {"FINISHED"}
    blender.ops.wm.save_as_mainfile(filepath=str(after_blend), copy=True)

    env = {"NUBIS_CACHE_DIR": str(cache_dir), "TMPDIR": str(tmp_path)}
    images = {}
    for name, blend in (("before", before_blend), ("after", after_blend)):
        out = tmp_path / f"{name}.exr"  # the clouds' own alpha (a PNG is over the sky)
        r = run_cli("render", "--blend", str(blend), "--out", str(out), env=env)
        assert r.returncode == 0, r.stderr[-2000:]
        images[name] = cover(out)
    d = distance_to_stroke()
    under, rest = d < 0.5 * RADIUS, d > RADIUS + 1500.0  # the clouds' own edges billow past the brush
    rise = images["after"][under].mean() - images["before"][under].mean()
    change = abs(images["after"][rest].mean() - images["before"][rest].mean())
    print(f"cover under the stroke +{rise:.3f}, elsewhere {change:.4f}")
    assert rise >= 0.3
    assert change <= 0.05
    # Not only on average: no pixel far from the stroke changed its cover.
    assert np.abs(images["after"] - images["before"])[d > RADIUS + 4000.0].max() == 0.0
