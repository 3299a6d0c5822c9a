"""Preset loading and validation (core/, no Blender)."""

from pathlib import Path

import pytest

from nubis_addon.core.errors import NubisError
from nubis_addon.core.presets import list_presets, load_preset
from nubis_addon.core.schema import PRESET_SCENE as PARAMS
from nubis_addon.core.schema import defaults


def test_every_shipped_preset_loads():
    names = list_presets()
    assert "default" in names
    for name in names:
        preset = load_preset(name)
        assert preset.name and preset.layers, name


def test_missing_preset_names_the_choices():
    with pytest.raises(NubisError, match="no preset named 'nope': choose one of .*default"):
        load_preset("nope")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[layer]\nbottom = 'high'\n", r"layer\.bottom must be a number"),
        ("[layer]\nbottom = 1e9\n", r"layer\.bottom = .* is out of range"),
        ("[lighting]\nphase_g0 = nan\n", r"lighting\.phase_g0 must be a finite number"),
        ("[layer]\nbottomm = 1.0\n", r"unknown setting layer\.bottomm"),
        ("[weather]\nx = 1\n", r"unknown section \[weather\]"),
        ("[sun]\ncolor = [1, 2]\n", r"sun\.color must be a list of 3 numbers"),
        ("[[field.layers]]\nkind = 'clouds'\n", r'field\.layers\[0\]\.kind = "clouds" is not allowed'),
        ("[[field.layers]]\nmask = 'later'\n", r'mask names "later", which is not an earlier layer'),
        ("[layer]\nbottom = 5000.0\ntop = 4000.0\n", r"layer\.top must be above layer\.bottom"),
        ("[layer\nbottom = 1\n", r"is not valid TOML"),
    ],
)
def test_broken_preset_names_file_and_field(tmp_path: Path, text: str, message: str):
    path = tmp_path / "broken.toml"
    path.write_text(text)
    with pytest.raises(NubisError, match=message) as info:
        load_preset(str(path))
    assert str(path) in str(info.value)


def test_a_byte_order_mark_is_no_part_of_the_preset(tmp_path: Path):
    """Windows editors save UTF-8 with a byte-order mark; the preset reads as it would without one."""
    shipped = Path(__file__).resolve().parents[2] / "presets" / "stratocumulus.toml"
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + shipped.read_bytes())
    assert load_preset(str(path)).params == load_preset(str(shipped)).params


def test_binary_garbage_is_reported(tmp_path: Path):
    path = tmp_path / "garbage.toml"
    path.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(NubisError, match="not UTF-8"):
        load_preset(str(path))


def test_defaults_cover_every_parameter_and_respect_ranges():
    values = defaults()
    assert set(values) == {p.key for p in PARAMS}
    for p in PARAMS:
        if p.kind in ("float", "int"):
            assert p.min <= values[p.key] <= p.max, p.key
