"""core/paint.py: dabs along a stroke, their raster, painted coverage against the slider, presets with strokes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nubis_addon.core import paint, paintraster, presets, userpresets
from nubis_addon.core.errors import NubisError

GRID = paint.Grid(256, 64000.0, 0.0, 0.0)  # 250 m pixels


def test_dabs_are_spaced_along_the_stroke_with_the_pressure_interpolated():
    dabs = paint.stroke_dabs([(0, 0, 0.0, True), (10000, 0, 1.0, False)], radius=1000.0, strength=0.5)
    assert dabs.shape[1] == len(paint.DAB_COLUMNS)
    xs = dabs[:, 0]
    np.testing.assert_allclose(np.diff(xs), 200.0)  # SPACING radii apart
    assert dabs[0, 6] == 1 and not dabs[1:, 6].any()
    np.testing.assert_allclose(dabs[:, 3], 0.5 * xs / 10000.0, atol=1e-12)
    # Points fed one by one (a live drag) make the same dabs as the whole stroke.
    spacer = paint.Spacer(1000.0, 0.5)
    rows = [r for p in [(0, 0, 0.0, True), (3000, 0, 0.3, False), (10000, 0, 1.0, False)] for r in spacer.add(*p)]
    whole = paint.stroke_dabs([(0, 0, 0.0, True), (3000, 0, 0.3, False), (10000, 0, 1.0, False)], 1000.0, 0.5)
    np.testing.assert_allclose(paint.as_dabs(rows), whole)


def test_overlapping_dabs_of_one_stroke_take_the_larger_weight_not_the_sum():
    slow = paint.stroke_dabs([(0, 0, 1, True), (4000, 0, 1, False)], 2000.0, 0.7, spacing=0.05)
    fast = paint.stroke_dabs([(0, 0, 1, True), (4000, 0, 1, False)], 2000.0, 0.7, spacing=0.5)
    r_slow, r_fast = paintraster.Raster(GRID), paintraster.Raster(GRID)
    r_slow.add_all(slow)
    r_fast.add_all(fast)
    assert r_slow.values.max() == pytest.approx(0.7, abs=0.01)  # the sum of 81 dabs would pass 1
    assert r_fast.values.max() == pytest.approx(0.7, abs=0.02)
    # Two strokes do add, clamped to 1.
    r_slow.add_all(slow)
    r_slow.add_all(slow)
    assert r_slow.values.max() == pytest.approx(1.0)
    # Subtracting lowers, to -1 at most.
    r = paintraster.Raster(GRID)
    r.add_all(paint.stroke_dabs([(0, 0, 1, True)], 2000.0, -1.0))
    assert r.values.min() == pytest.approx(-1.0, abs=0.03) and r.values.max() == 0.0


def test_a_dab_touches_only_its_disc():
    r = paintraster.Raster(GRID)
    rect = r.add((1000.0, -2000.0, 1500.0, 1.0, 0, 0, 1))
    xs = (np.arange(256) + 0.5) / 256 * 64000.0 - 32000.0
    gx, gy = np.meshgrid(xs, xs)
    outside = np.hypot(gx - 1000.0, gy + 2000.0) >= 1500.0
    assert np.all(r.values[outside] == 0.0)
    r0, r1, c0, c1 = rect
    mask = np.zeros_like(r.values, bool)
    mask[r0:r1, c0:c1] = True
    assert np.all(r.values[~mask] == 0.0)
    assert r.values[~outside].min() >= 0.0 and r.values.max() > 0.95


def test_falloffs_and_smoothing():
    for falloff, edge in (("constant", 1.0), ("linear", 0.5), ("smooth", 0.5)):
        r = paintraster.Raster(GRID)
        x0 = -32000.0 + 128.5 * 250.0  # a pixel centre
        r.add((x0, x0, 1000.0, 1.0, paint.FALLOFFS.index(falloff), 0, 1))
        assert r.values[128, 130] == pytest.approx(edge, abs=1e-6)  # 500 m from the centre
    r = paintraster.Raster(GRID)
    r.add_all(paint.stroke_dabs([(0, 0, 1, True)], 1500.0, 1.0, falloff="constant"))
    hard_edge = np.abs(np.diff(r.values, axis=1)).max()
    r.add_all(paint.stroke_dabs([(0, 0, 1, True)], 3000.0, 1.0, mode="smooth"))
    assert np.abs(np.diff(r.values, axis=1)).max() < 0.7 * hard_edge


def test_the_cached_raster_grows_with_new_strokes_and_rebuilds_after_an_undo():
    paintraster.forget()
    a = paint.stroke_dabs([(0, 0, 1, True), (5000, 0, 1, False)], 2000.0, 1.0)
    b = paint.stroke_dabs([(0, 4000, 1, True), (5000, 4000, 1, False)], 2000.0, -0.5)
    both = np.vstack([a, b])
    fresh = paintraster.Raster(GRID)
    fresh.add_all(both)
    r1 = paintraster.raster(7, a, GRID)
    r2 = paintraster.raster(7, both, GRID)
    assert r2 is r1 and r2.count == len(both)  # only the new stroke was rasterized
    np.testing.assert_array_equal(r2.values, fresh.values)
    r3 = paintraster.raster(7, a, GRID)  # undo: fewer dabs
    assert r3 is not r2
    only_a = paintraster.Raster(GRID)
    only_a.add_all(a)
    np.testing.assert_array_equal(r3.values, only_a.values)


def test_painted_coverage_adds_after_the_multiplier_and_is_stored_divided_by_it():
    pre = np.full((4, 4), 0.2, np.float32)
    values = np.zeros((4, 4), np.float32)
    values[1, 1], values[2, 2] = 1.0, -0.5
    layer = paintraster.PaintLayer("coverage", 1.0, values)
    for m in (0.5, 2.0, 0.0):
        out = paintraster.paint_plane("coverage", pre, [layer], m)
        m_eff = paintraster.effective_multiplier(m, [layer])
        seen = np.clip(out * m_eff, 0, 1)
        assert seen[1, 1] == pytest.approx(1.0)
        assert seen[0, 0] == pytest.approx(min(0.2 * m, 1.0), abs=1e-6)  # unpainted: as the slider had it
        assert seen[2, 2] == pytest.approx(max(min(0.2 * m, 1.0) - 0.5, 0.0), abs=1e-6)
    assert paintraster.effective_multiplier(0.0, [layer]) == paint.MULTIPLIER_FLOOR
    assert paintraster.effective_multiplier(0.0, [paintraster.PaintLayer("type", 1.0, values)]) == 0.0
    # Other channels add to their value, clamped.
    typ = paintraster.paint_plane("type", pre, [paintraster.PaintLayer("type", 0.5, values)], 1.0)
    assert typ[1, 1] == pytest.approx(0.7) and typ[2, 2] == pytest.approx(0.0) and typ[0, 0] == pytest.approx(0.2)
    # A rectangle re-composites just that part, identically.
    rect = (1, 3, 0, 2)
    part = paintraster.paint_plane("coverage", pre, [layer], 0.5, rect)
    np.testing.assert_array_equal(part, paintraster.paint_plane("coverage", pre, [layer], 0.5)[1:3, 0:2])


def test_bad_brushes_and_strokes_are_refused_with_what_to_do():
    cases = [
        (lambda: paint.check_brush(GRID, 0.0, 1.0), "at least 125 m"),
        (lambda: paint.check_brush(GRID, math.nan, 1.0), "must be a finite number of metres, not NaN"),
        (lambda: paint.check_brush(GRID, 1e6, 1.0), "at most 64000 m"),
        (lambda: paint.check_brush(GRID, 1000.0, 0.0), "between 0.01 and 1"),
        (lambda: paint.check_points(GRID, []), "no points"),
        (lambda: paint.check_points(GRID, [(math.inf, 0, 1, True)]), "not infinite"),
        (lambda: paint.stroke_dabs([(1e6, 0, 1, True)], 1000.0, 1.0, grid=GRID), "x -32000 to 32000 m"),
    ]
    for call, words in cases:
        with pytest.raises(NubisError, match=words):
            call()
    paint.check_brush(GRID, 125.0, 1.0)
    paint.check_points(GRID, [(1e6, 0, 1, True), (0, 0, 1, False)])  # partly outside is fine: clipped
    assert len(paint.stroke_dabs([(1e6 + 100, 0, 1, True), (0, 0, 1, False)], 1000.0, 1.0, grid=GRID)) == 165


def test_a_preset_keeps_a_paint_layers_strokes(tmp_path):
    preset = presets.load_preset("clear_sky")
    dabs = paint.stroke_dabs([(-3000.0, 0.0, 1.0, True), (3000.0, 0.0, 0.5, False)], 2500.0, 1.0)
    rows = [[*map(float, r[:4]), *map(int, r[4:])] for r in dabs]
    layer = dict(preset.layers[0], name="Paint Coverage", kind="paint", channel="coverage", blend="add", dabs=rows)
    preset.layers.append(layer)
    text = userpresets.dump_preset(preset)
    back = presets.preset_from_bytes(text.encode(), tmp_path / "p.toml")
    assert back.layers[-1]["dabs"] == rows
    # Bad strokes in a hand-edited preset: the row and the rule.
    bad = text.replace("dabs = [\n  [", "dabs = [\n  [1e999, ", 1)
    with pytest.raises(NubisError, match=r"dabs\[0\]"):
        presets.preset_from_bytes(bad.encode(), tmp_path / "p.toml")
    wrong = text.replace('kind = "paint"', 'kind = "perlin"')
    with pytest.raises(NubisError, match="only a paint layer"):
        presets.preset_from_bytes(wrong.encode(), tmp_path / "p.toml")
