"""Coverage is the fraction of the sky the low clouds cover (core/coverage.py): measured in the viewport's
own render straight down on the default cloudscape, and kept by presets written before it was."""

from __future__ import annotations

import numpy as np
import pytest

from nubis_addon.core import coverage


def _top_view_cover(scene, size: int = 192) -> float:
    """The fraction of columns whose opacity seen from straight above exceeds 0.05 (the cloud cover
    `render` reports), over a square well inside the field and the draw radius, cirrus left out."""
    from mathutils import Matrix

    from nubis_addon.blender.host import runtime
    from nubis_addon.blender.scene import cloudstate
    from nubis_addon.core import camera
    from nubis_addon.render import engine

    state = cloudstate.state_from_scene(scene)
    p = state.params
    half = 0.9 * min(p["field_size"] / 2, p["layer_draw_radius"] / 2**0.5)
    x, y = state.draw_center
    top, bottom = 20000.0, -100.0  # an orthographic view from above the layers to the ground
    inv = Matrix(((half, 0, 0, x), (0, half, 0, y), (0, 0, -(top - bottom) / 2, (top + bottom) / 2), (0, 0, 0, 1)))
    state.pixel_angle, state.pixel_size = camera.pixel_footprint(np.array(inv), size, size)
    state.params["cirrus_coverage"] = 0.0
    clouds = runtime.cloud_gpu(scene.nubis.noise_seed)
    clouds.update(state, light=False)
    alpha = engine.render_offscreen(clouds, inv, (0.0, 0.0, 0.0, 0.0), size, size)[..., 3]
    return float((alpha > 0.05).mean())


def test_coverage_is_the_fraction_of_the_sky_covered(make_scene):
    scene = make_scene("default")
    measured = {}
    for cover in (0.0, 0.25, 0.5, 0.75):
        scene.nubis.density_cover = cover
        measured[cover] = _top_view_cover(scene)
    assert measured[0.0] == 0.0
    for cover in (0.25, 0.5, 0.75):
        # 0.245, 0.512 and 0.754 when measured (192x192, 2026-12-02); the promise is within 0.1.
        assert abs(measured[cover] - cover) < 0.05, measured


def test_a_preset_with_the_old_multiplier_keeps_its_look(make_scene, tmp_path):
    """`[density] coverage = 0.6` without `cover` (mixed_sky before the change) becomes the fraction of
    the sky 0.6 covered on its own field, so the shaders get 0.6 back."""
    from nubis_addon.blender.scene import cloudstate, scenepresets
    from nubis_addon.core.presets import find_preset, load_preset

    text = find_preset("mixed_sky").read_text(encoding="utf-8")
    old = tmp_path / "old_mixed.toml"
    old.write_text(text.replace("cover = 0.41475", "coverage = 0.6"), encoding="utf-8")
    preset = load_preset(str(old))
    assert preset.legacy_coverage == pytest.approx(0.6)
    scene = make_scene("default")
    scenepresets.apply_preset(scene, preset)
    assert scene.nubis.density_cover == pytest.approx(0.41475, abs=0.002)
    assert cloudstate.state_from_scene(scene).params["density_coverage"] == pytest.approx(0.6, abs=0.005)


def test_the_multiplier_found_covers_the_fraction_asked():
    rng = np.random.default_rng(3)
    hist = coverage.histogram(rng.uniform(0.0, 0.6, (256, 256)))
    for cover in (0.01, 0.2, 0.5, 0.9):
        m = coverage.multiplier_for(cover, hist)
        assert coverage.covered_fraction(m, hist) == pytest.approx(cover, abs=1e-4)
    assert coverage.multiplier_for(0.0, hist) == 0.0
    assert coverage.multiplier_for(float("nan"), hist) == 0.0
    assert coverage.multiplier_for(1.0, hist) == coverage.MAX_MULTIPLIER  # overcast: every column full
    empty = coverage.histogram(np.zeros((8, 8)))
    assert coverage.covered_fraction(coverage.multiplier_for(0.5, empty), empty) == 0.0
