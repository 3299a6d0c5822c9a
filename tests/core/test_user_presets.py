"""User presets: the TOML writer round-trips every setting through the one validator, files are
written atomically into the user's folder, and only the user's own presets can be removed."""

from __future__ import annotations

import copy
import struct
import tomllib
from pathlib import Path

import pytest

from nubis_addon.core import presets, schema, userpresets
from nubis_addon.core.errors import NubisError


def _same(a: presets.Preset, b: presets.Preset) -> None:
    assert (a.name, a.description) == (b.name, b.description)
    assert a.params == b.params
    assert a.extra == b.extra
    assert a.layers == b.layers
    assert a.storms == b.storms
    # A layered preset's further layers: each one's name, switch, own settings and field stack.
    assert [(c.name, c.enabled, c.params, c.field_layers) for c in a.cloud_layers] == [
        (c.name, c.enabled, c.params, c.field_layers) for c in b.cloud_layers
    ]


def _round_trip(preset: presets.Preset) -> presets.Preset:
    text = userpresets.dump_preset(preset)
    tomllib.loads(text)  # plain TOML
    return presets.preset_from_bytes(text.encode("utf-8"))


@pytest.mark.parametrize("name", presets.list_presets())
def test_every_shipped_preset_round_trips(name: str) -> None:
    preset = presets.load_preset(name)
    _same(_round_trip(preset), preset)


def _off_default(s: schema.Setting, i: int):
    """A value of `s` that is not its default, inside its range (so the test sees every key written)."""
    if s.kind == "bool":
        return not s.default
    if s.kind == "enum":
        return next(c for c in s.choices if c != s.default)
    if s.kind == "int":
        hi = int(s.max) if s.max is not None else s.default + 10
        return s.default + 1 if s.default + 1 <= hi else s.default - 1
    if s.kind == "float":
        lo = s.min if s.min is not None else s.default - 1.0
        hi = s.max if s.max is not None else s.default + 1.0
        return lo + (hi - lo) * (0.3 + 0.01 * (i % 7))
    if s.kind in ("vector", "color"):
        return [float(v) * 0.5 + 0.125 * (k + 1) for k, v in enumerate(s.default)]
    return f'text {i} "quoted" \\ ünïcode'


def test_every_setting_off_its_default_round_trips() -> None:
    preset = presets.parse_preset({})
    for i, s in enumerate(schema.PRESET_SCENE):
        if s.key not in ("layer_bottom", "layer_top", "march_steps_min", "march_steps_max"):
            preset.params[s.key] = _off_default(s, i)
    preset.params.update(layer_bottom=1200.5, layer_top=5100.25, march_steps_min=40, march_steps_max=90)
    for section, table in schema.EXTRA_SECTIONS.items():
        for i, (name, s) in enumerate(table.items()):
            if section != "preset":  # its name and description are the Preset's own fields
                preset.extra[section][name] = _off_default(s, i)
    preset.name, preset.description = 'My "best" sky', "Line one\twith a tab"
    preset.layers = []
    for i, kind in enumerate(schema.LAYER_KINDS):
        layer = schema.table_defaults(schema.FIELD_LAYER)
        for j, s in enumerate(schema.FIELD_LAYER):
            if s.name not in ("name", "kind", "mask", "image", "remap", "center"):
                layer[s.name] = _off_default(s, i + j)
        layer.update(name=f"L{i}", kind=kind, mask="L0" if i else "", image="painted.png" if kind == "image" else "")
        layer.update(remap=[0.1, 0.9, 0.0, 1.0], center=[1000.0, -2000.0])
        preset.layers.append(layer)
    preset.storms = []
    for i in range(2):
        storm = schema.table_defaults(schema.STORM)
        for j, s in enumerate(schema.STORM):
            if s.in_preset and s.name != "name":
                storm[s.name] = _off_default(s, i + j)
        storm["name"] = f"Storm {i}"
        preset.storms.append(storm)
    back = _round_trip(preset)
    _same(back, preset)
    # Nothing was left to its default, so a key the writer forgot would have shown above.
    assert back.params != schema.defaults()


def test_the_writer_refuses_what_the_loader_would_refuse(tmp_path: Path) -> None:
    preset = presets.load_preset("default")
    preset.name = "Broken"
    preset.params["layer_top"] = preset.params["layer_bottom"] - 10.0
    with pytest.raises(NubisError, match="layer.top must be above layer.bottom"):
        userpresets.save_user_preset(tmp_path, preset)
    preset = presets.load_preset("default")
    preset.name = "Infinite"
    preset.params["density_sigma"] = float("inf")
    with pytest.raises(NubisError, match="finite"):
        userpresets.save_user_preset(tmp_path, preset)
    assert list(tmp_path.iterdir()) == []


def test_save_load_overwrite_and_remove(tmp_path: Path) -> None:
    preset = presets.load_preset("superstorm")
    preset.name, preset.description = "Evening Storm", "A storm at dusk, for the trailer"
    preset.params["noise_seed"] = 7
    path = userpresets.save_user_preset(tmp_path, preset)
    assert path == tmp_path / "evening_storm.toml"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["evening_storm.toml"]  # no temporary left
    _same(presets.load_preset(str(path)), preset)
    assert presets.load_preset(str(path)).path == path
    preset.params["noise_seed"] = 8
    userpresets.save_user_preset(tmp_path, preset)
    assert presets.load_preset(str(path)).params["noise_seed"] == 8
    with pytest.raises(NubisError, match="exists already"):
        userpresets.save_user_preset(tmp_path, preset, overwrite=False)
    assert userpresets.list_user_presets(tmp_path) == [path]
    assert userpresets.remove_user_preset(tmp_path, "evening_storm") == path
    assert userpresets.list_user_presets(tmp_path) == []
    with pytest.raises(NubisError, match="no preset of yours"):
        userpresets.remove_user_preset(tmp_path, "evening_storm")


def test_shipped_presets_are_neither_overwritten_nor_removed(tmp_path: Path) -> None:
    shipped = presets.preset_dir()
    before = {p.name: p.read_bytes() for p in shipped.glob("*.toml")}
    preset = presets.load_preset("default")
    for name in ("Default", "  cirrus SKY ", "Mixed-Sky"):
        preset.name = name
        with pytest.raises(NubisError, match="shipped with Nubis"):
            userpresets.save_user_preset(tmp_path, preset)
    with pytest.raises(NubisError, match="only presets you saved can be removed"):
        userpresets.remove_user_preset(tmp_path, "default")
    # Pointing "the user's folder" at the shipped folder removes nothing either.
    with pytest.raises(NubisError, match="shipped with Nubis"):
        preset.name = "stratus overcast"
        userpresets.save_user_preset(shipped, preset)
    assert {p.name: p.read_bytes() for p in shipped.glob("*.toml")} == before


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("", "give the preset a name"),
        ("   ", "give the preset a name"),
        ("!!!", "at least one letter"),
        ("x" * 65, "64"),
    ],
)
def test_bad_names_are_refused(tmp_path: Path, name: str, message: str) -> None:
    preset = presets.load_preset("default")
    preset.name = name
    with pytest.raises(NubisError, match=message):
        userpresets.save_user_preset(tmp_path, preset)


def test_float32_values_are_written_short_and_read_back_to_the_same_float32() -> None:
    def f32(x: float) -> float:
        return struct.unpack("f", struct.pack("f", x))[0]

    assert userpresets.tidy_float32(f32(0.3)) == 0.3
    assert userpresets.tidy_float32(f32(0.1)) <= 0.1  # a hard maximum of 0.1 still holds
    assert userpresets.tidy_float32([f32(1.1), 2]) == [1.1, 2]
    for x in (1e-7, 3.14159265, 6371000.0, 12345.678, 2.0**-20, 0.85, 1e8, -0.0):
        assert f32(userpresets.tidy_float32(f32(x))) == f32(x)
    assert userpresets.tidy_float32(True) is True and userpresets.tidy_float32("a") == "a"


def test_saving_does_not_change_the_preset_it_was_given(tmp_path: Path) -> None:
    preset = presets.load_preset("mixed_sky")
    preset.name = "Copy"
    before = copy.deepcopy(preset)
    userpresets.save_user_preset(tmp_path, preset)
    _same(preset, before)
