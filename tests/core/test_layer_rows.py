"""A cloud layer's settings on the GPU come from the schema's flags (docs/architecture.md): a new per-layer
float is one line in core/schema.py, and render/uniforms.py packs it, declares it in NubisLayer and
unpacks it in nubis_layer(i) by itself."""

import dataclasses
import re

import pytest

from nubis_addon.core import schema
from nubis_addon.render import uniforms


def _members(struct: str) -> list[str]:
    return re.findall(r"^\s+(?:float|vec2|vec4|int) (\w+);", struct, re.M)


def test_every_flagged_float_is_a_member_with_an_accessor():
    members = _members(uniforms._layer_struct())
    source = uniforms.layer_source()
    flagged = [s for s in schema.SCENE if s.layer_member]
    assert len(flagged) >= 6
    for s in flagged:
        assert s.cloud_layer and s.kind in ("float", "int", "bool"), f"{s.key}: a layer member is one number per layer"
        assert s.layer_member in members
        assert f"L.{s.layer_member} = nubis_layer_{s.layer_member}(i);" in source
    assert len(members) == len(set(members)), "a member named twice"
    rows = [row for row, _fields in uniforms._LAYER_ROWS]
    assert all(sum(f.size for f in fields) == 4 for _row, fields in uniforms._LAYER_ROWS)
    assert len(rows) == len(set(rows))


def test_a_new_per_layer_setting_is_one_line_in_the_schema(monkeypatch):
    """The dry run of docs/architecture.md: one more flagged setting, and the rows, the struct and the
    accessor follow; its value is packed from a layer's own settings."""
    new = dataclasses.replace(
        schema.BY_KEY["density_erosion"], name="haze_test", label="Haze", cloud_layer=True, layer_member="haze"
    )
    monkeypatch.setattr(schema, "CLOUD_LAYER_SETTINGS", (*schema.CLOUD_LAYER_SETTINGS, new))
    rows = uniforms._settings_rows()
    fields = [f for _row, row_fields in rows for f in row_fields if f.name]
    assert [f.name for f in fields][-1] == "haze"
    assert sum(1 for _row, row_fields in rows for f in row_fields if f.name is None) == -len(fields) % 4
    layer = uniforms._Layer({"density_haze_test": 0.25}, 0.0, 1.0, None, None)
    assert fields[-1].value(layer) == pytest.approx(0.25)
