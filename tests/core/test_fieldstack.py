"""The one composite pipeline a cloud layer's field goes through (core/fieldstack.py): the first layer and
every further one alike."""

from __future__ import annotations

import numpy as np

from nubis_addon.core import coverage, fieldstack, paint, paintraster, presets, schema
from nubis_addon.core import storms as stormgen


def _inputs(**kw) -> fieldstack.StackInputs:
    preset = presets.load_preset("default")
    params = dict(preset.params, field_resolution=64)
    return fieldstack.StackInputs(layers=preset.layers, params=params, **kw)


def test_the_multiplier_is_found_before_the_storms_and_the_storm_still_writes_its_stencil():
    plain = fieldstack.composite_stack(_inputs(cover=0.5))
    p = _inputs().params
    storm = stormgen.Storm(x=p["field_origin_x"], y=p["field_origin_y"], radius=0.3 * p["field_size"], coverage=1.0)
    stormy = fieldstack.composite_stack(_inputs(cover=0.5, storms=[storm]))
    assert stormy.multiplier == plain.multiplier  # the stencil is its own system (GDC22)
    assert not np.array_equal(stormy.planes["b"][..., 0], plain.planes["b"][..., 0])  # storm coverage written
    assert plain.multiplier == coverage.multiplier_for(0.5, plain.cover_hist)


def test_painted_cover_on_a_clear_sky_is_the_paint_alone():
    """A clear sky (Coverage 0) with a stroke: the shader multiplies the stored plane by the stored
    (floored) multiplier, so unpainted texels must store 0. The layered path once painted with the floored
    multiplier and left them at field x 0.001."""
    res = 64
    values = np.zeros((res, res), np.float32)
    values[20:30, 20:30] = 1.0
    stroke = paintraster.PaintLayer("coverage", 1.0, values)
    done = fieldstack.composite_stack(_inputs(cover=0.0, painted=[stroke], has_paint=True))
    assert done.multiplier == 0.0 and done.stored_multiplier == paint.MULTIPLIER_FLOOR
    seen = done.planes["a"][..., 0] * done.stored_multiplier  # what the shader reads
    assert np.allclose(seen[values == 0.0], 0.0) and np.allclose(seen[values == 1.0], 1.0)
    assert done.pre_paint is not None and done.pre_paint[1] == 0.0


def test_the_weather_rules_apply_only_when_on():
    off = fieldstack.composite_stack(_inputs())
    wet = _inputs(rain=1.0)
    drizzle = schema.table_defaults(schema.FIELD_LAYER)
    drizzle.update(name="Rain", kind="constant", channel="precipitation", value=0.8)
    wet.layers = [*wet.layers, drizzle]
    rain = fieldstack.composite_stack(wet)
    # GPU Pro 7's rain rule: raining clouds turn to cumulonimbus (type towards 1), covering at least 70 %.
    assert np.all(rain.planes["a"][..., 2] >= 0.8 * 1.0 + 0.2 * off.planes["a"][..., 2] - 1e-6)
    assert np.all(rain.planes["a"][..., 0] >= 0.8 * 0.7 - 1e-6)
    horizon = fieldstack.composite_stack(_inputs(horizon=1000.0, camera_xy=(0.0, 0.0)))
    assert not np.array_equal(horizon.planes["a"], off.planes["a"])
