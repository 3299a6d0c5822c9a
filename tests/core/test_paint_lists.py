"""core/paint.py's lists, each stated once: the channels a brush paints, the brush modes and the dab columns;
the rest (field places, column indices, Blender's menus and dab properties) derives from them. Core keys its
raster cache by numbers its caller gives, never by a Blender pointer."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from nubis_addon.core import fields, paint, schema
from nubis_addon.core.errors import NubisError

CORE = Path(paint.__file__).parent


def test_the_paint_channels_derive_from_the_brushs_list_and_the_field_layout():
    names = [c.name for c in paint.BRUSH_CHANNELS]
    assert names == ["coverage", "type", "precipitation", "storm"]  # the tool's menu order, kept in files
    assert set(paint.PAINT_CHANNELS) == set(names)
    assert list(paint.PAINT_CHANNELS) == [c for c in fields.CHANNELS if c in names]  # the layout's order
    for name, place in paint.PAINT_CHANNELS.items():
        assert place == fields.CHANNELS[name]
        assert name in schema.FIELD_CHANNELS  # a paint layer's channel is a field layer's channel


def test_a_paint_layer_on_a_channel_no_brush_paints_is_refused_in_one_sentence():
    for name in paint.PAINT_CHANNELS:
        paint.check_paint_channel("Paint", name)
    with pytest.raises(NubisError) as info:
        paint.check_paint_channel("Paint", "bottom_type")
    assert str(info.value) == (
        "the paint layer 'Paint' writes 'bottom_type', which a brush cannot paint: set its channel to one of "
        "coverage, precipitation, type, storm"
    )


def test_the_dab_columns_are_one_list_and_the_spacer_fills_them_by_name():
    assert paint.DAB_COLUMNS == ("x", "y", "radius", "strength", "falloff", "mode", "start")
    assert paint.DAB_COLUMNS == tuple(c.name for c in paint.DABS)
    assert {c.kind for c in paint.DABS} <= {"float", "int", "bool"}
    assert all(paint.DAB_COLUMNS[i] == name for name, i in paint.COLUMN.items())
    dabs = paint.stroke_dabs([(0.0, 0.0, 1.0, True), (3000.0, 0.0, 1.0, False)], 1000.0, -0.5, "linear", "smooth")
    column = paint.COLUMN
    assert np.all(dabs[:, column["radius"]] == 1000.0) and np.all(dabs[:, column["strength"]] == -0.5)
    assert np.all(dabs[:, column["falloff"]] == paint.FALLOFFS.index("linear"))
    assert np.all(dabs[:, column["mode"]] == paint.MODES.index("smooth"))
    assert dabs[0, column["start"]] == 1 and not dabs[1:, column["start"]].any()
    # A preset's row keeps its kinds: floats, then whole numbers.
    rows = paint.parse_dabs([[1, 2, 3, 0.5, 1, 0, 1]], "dabs")
    assert rows == [[1.0, 2.0, 3.0, 0.5, 1, 0, 1]]
    assert [type(v) for v in rows[0]] == [float] * 4 + [int] * 3
    with pytest.raises(NubisError, match=r"must be 7 numbers: x, y, radius, strength, falloff, mode, start$"):
        paint.parse_dabs([[1, 2, 3]], "dabs")


def test_the_brush_modes_say_their_key_their_sign_and_their_dabs():
    assert [m.name for m in paint.BRUSH_MODES] == ["add", "subtract", "smooth"]  # the Mode menu's order
    assert [m.key for m in paint.BRUSH_MODES] == ["", "ctrl", "shift"]
    assert paint.BRUSH_MODE["subtract"].sign == -1.0 and paint.BRUSH_MODE["add"].sign == 1.0
    assert {m.dab_mode for m in paint.BRUSH_MODES} == set(paint.MODES)


def test_core_holds_no_blender_identity():
    """The raster cache is keyed by the caller's numbers: nothing in core/ asks Blender for a pointer."""
    for path in CORE.glob("*.py"):
        text = path.read_text(encoding="utf-8")
        assert "as_pointer" not in text, path.name
