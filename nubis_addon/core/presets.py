"""Presets are TOML data, validated on load and never executed.

Every error names the file and the field, and says what to do.
"""

from __future__ import annotations

import copy
import math
import os
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from . import cloudlayers, limits, paint, schema
from .errors import NubisError
from .fsutil import not_a_file
from .state import MAX_STORMS
from .tomlfmt import toml_value

# The enum choices, re-exported for the compositor and the tests.
FIELD_CHANNELS = schema.FIELD_CHANNELS
LAYER_KINDS = schema.LAYER_KINDS
BLEND_MODES = schema.BLEND_MODES
GRADIENT_SHAPES = schema.GRADIENT_SHAPES
_SCENE_BY_PLACE: dict[tuple[str, str], schema.Setting] = {(s.section, s.name): s for s in schema.PRESET_SCENE}
_PLACE_OF_KEY = {s.key: f"{s.section}.{s.name}" for s in schema.PRESET_SCENE}
SECTIONS = frozenset(s.section for s in schema.PRESET_SCENE) | frozenset(schema.EXTRA_SECTIONS)


@dataclass
class Preset:
    name: str
    path: Path | None
    params: dict[str, Any]
    extra: dict[str, dict[str, Any]]
    layers: list[dict[str, Any]] = field(default_factory=list)
    description: str = ""
    storms: list[dict[str, Any]] = field(default_factory=list)
    # A preset written before Coverage was a fraction of the sky sets only the multiplier on the field;
    # applying it sets the fraction that multiplier covers on its own field (core/coverage.py).
    legacy_coverage: float | None = None
    # A layered sky's further layers ([[cloud_layers]], core/cloudlayers.py); the first is the preset's own.
    cloud_layers: list[cloudlayers.CloudLayer] = field(default_factory=list)


def preset_dir() -> Path:
    return Path(__file__).resolve().parents[2] / "presets"


def list_presets(folder: Path | None = None) -> list[str]:
    folder = folder or preset_dir()
    return sorted(p.stem for p in folder.glob("*.toml"))


def find_preset(name: str, folder: Path | None = None) -> Path:
    """Presets are found by name in presets/, or by an explicit path to a .toml file."""
    folder = folder or preset_dir()
    # not_a_file, not Path.is_file: is_file raises for a name longer than the file system allows and
    # calls a folder or a device "not found".
    if name.endswith(".toml") or os.sep in name:
        path = Path(name).expanduser()
        why = not_a_file(path)
        if why == "does not exist":
            raise NubisError(f"preset file '{path}' not found: check the path")
        if why:
            raise NubisError(f"the preset file '{path}' {why}: give the path of a .toml preset")
        return path
    path = folder / f"{name}.toml"
    if not_a_file(path):
        known = ", ".join(list_presets(folder)) or "none"
        raise NubisError(f"no preset named '{name}': choose one of {known}")
    return path


def load_preset(name_or_path: str | os.PathLike, folder: Path | None = None) -> Preset:
    path = find_preset(str(name_or_path), folder)
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise NubisError(f"cannot read preset '{path}' ({err.strerror}): check its permissions") from None
    return preset_from_bytes(raw, path)


def preset_from_bytes(raw: bytes, path: Path | None = None) -> Preset:
    """A preset from a file's bytes: a Preset, or a NubisError that names the file and what to fix."""
    where = str(path) if path else "<preset>"
    try:
        # utf-8-sig: a byte-order mark, as Windows editors write one, is no part of the TOML.
        data = tomllib.loads(raw.decode("utf-8-sig"))
    except UnicodeDecodeError:
        raise NubisError(f"preset '{where}' is not UTF-8 text: restore it from the presets folder") from None
    except tomllib.TOMLDecodeError as err:
        # tomllib quotes characters as Python does ('\x14'); name them as Unicode does (U+0014).
        reason = re.sub(r"'\\[xuU]([0-9a-fA-F]+)'", lambda m: f"U+{int(m.group(1), 16):04X}", str(err))
        raise NubisError(f"preset '{where}' is not valid TOML ({reason}): fix the file or restore it") from None
    except RecursionError:
        raise NubisError(f"preset '{where}' nests arrays or tables too deeply: fix the file or restore it") from None
    return parse_preset(data, path)


def parse_preset(data: dict[str, Any], path: Path | None = None) -> Preset:
    where = str(path) if path else "<preset>"
    params = schema.defaults()
    extra = {sec: schema.table_defaults(table.values()) for sec, table in schema.EXTRA_SECTIONS.items()}
    layers: list[dict[str, Any]] = []
    storms: list[dict[str, Any]] = []
    for sec, table in data.items():
        if sec == "storms":
            storms = _parse_storms(table, where)
            continue
        if sec == "cloud_layers":
            continue  # read once the first layer's settings are known: a further layer starts as a copy
        if not isinstance(table, dict):
            raise NubisError(f"{where}: '{sec}' must be a table like [{sec}], not {toml_value(table)}")
        if sec not in SECTIONS:
            raise NubisError(f"{where}: unknown section [{sec}]; sections are {', '.join(sorted(SECTIONS))}")
        for key, value in table.items():
            if sec == "field" and key == "layers":
                layers = _parse_layers(value, where)
                continue
            here = f"{where}: {sec}.{key}"
            if (sec, key) in _SCENE_BY_PLACE:
                setting = _SCENE_BY_PLACE[(sec, key)]
                params[setting.key] = check_value(setting, value, here)
            elif key in schema.EXTRA_SECTIONS.get(sec, {}):
                extra[sec][key] = check_value(schema.EXTRA_SECTIONS[sec][key], value, here)
            else:
                raise NubisError(f"{where}: unknown setting {sec}.{key}: remove it or check the spelling")
    for rule in schema.CROSS_LIMITS:
        if not rule.holds(params):
            raise NubisError(f"{where}: {rule.message} ({rule.stated(params, _PLACE_OF_KEY)})")
    _check_span(extra["camera"]["location"], f"{where}: camera.location")
    _check_masks(layers, where)
    further = _parse_cloud_layers(data.get("cloud_layers", []), (params, layers), where)
    meta = extra.pop("preset")
    density = data.get("density", {})
    legacy = params["density_coverage"] if "coverage" in density and "cover" not in density else None
    return Preset(meta["name"], path, params, extra, layers, meta["description"], storms, legacy, further)


# The sections a [[cloud_layers]] table holds: those of a layer's own settings, and [field] for its stack.
_CLOUD_LAYER_PLACES = {(s.section, s.name): s for s in schema.CLOUD_LAYER_SETTINGS}
CLOUD_LAYER_SECTIONS = ("field", *dict.fromkeys(s.section for s in schema.CLOUD_LAYER_SETTINGS))


def _parse_cloud_layers(value: Any, first_layer: tuple, where: str) -> list[cloudlayers.CloudLayer]:
    """The further layers of a layered sky: each starts as a copy of the first layer's own settings and
    field stack (`first_layer`: its settings, its stack), and its tables change what differs. The whole
    stack is then checked (core/cloudlayers.py: check_stack)."""
    first, first_stack = first_layer
    if not isinstance(value, list):
        raise NubisError(f"{where}: cloud_layers must be written as [[cloud_layers]] tables")
    most = cloudlayers.MAX_CLOUD_LAYERS - 1
    if len(value) > most:
        raise NubisError(
            f"{where}: a sky holds at most {cloudlayers.MAX_CLOUD_LAYERS} cloud layers, the preset's own and "
            f"{most} [[cloud_layers]], not {len(value) + 1}: remove {len(value) - most} of the [[cloud_layers]]"
        )
    out = []
    for i, raw in enumerate(value):
        here = f"{where}: cloud_layers[{i}]"
        if not isinstance(raw, dict):
            raise NubisError(f"{here} must be a table, not {toml_value(raw)}")
        out.append(_parse_cloud_layer(raw, first_layer, here, i))
        if any(c.name == out[-1].name for c in out[:-1]):
            raise NubisError(f"{here}.name: another cloud layer is named {toml_value(out[-1].name)}: give each its own")
    if out:  # one layer keeps the schema's own limits (a sky of one layer may reach 30 km)
        ranges = [("the preset's own layer", first["layer_bottom"], first["layer_top"])]
        ranges += [(c.name, c.params["layer_bottom"], c.params["layer_top"]) for c in out]
        cloudlayers.check_stack(ranges, where)
    return out


def _parse_cloud_layer(raw: dict[str, Any], first_layer: tuple, here: str, i: int) -> cloudlayers.CloudLayer:
    first, first_stack = first_layer
    own = cloudlayers.own_params(first)
    name, enabled, field_layers = f"Layer {i + 2}", True, copy.deepcopy(first_stack)
    for sec, table in raw.items():
        if sec == "name":
            if not isinstance(table, str) or not table.strip():
                raise NubisError(f"{here}.name must be a name in quotes, not {toml_value(table)}")
            name = table.strip()
            limits.check_text(f"{here}.name", name)
            continue
        if sec == "enabled":
            if not isinstance(table, bool):
                raise NubisError(f"{here}.enabled must be true or false, not {toml_value(table)}")
            enabled = table
            continue
        if sec not in CLOUD_LAYER_SECTIONS or not isinstance(table, dict):
            raise NubisError(
                f"{here}: unknown entry '{sec}'; a cloud layer holds name, enabled and the tables "
                f"{', '.join(f'[cloud_layers.{s}]' for s in CLOUD_LAYER_SECTIONS)}"
            )
        for key, val in table.items():
            if sec == "field" and key == "layers":
                field_layers = _parse_layers(val, f"{here}")
                _check_masks(field_layers, here)
            elif (sec, key) in _CLOUD_LAYER_PLACES:
                setting = _CLOUD_LAYER_PLACES[(sec, key)]
                own[setting.key] = check_value(setting, val, f"{here}.{sec}.{key}")
            elif (sec, key) in _SCENE_BY_PLACE:
                raise NubisError(
                    f"{here}.{sec}.{key} is the sky's, shared by every layer: set it in the preset's own [{sec}]"
                )
            else:
                raise NubisError(f"{here}: unknown setting {sec}.{key}: remove it or check the spelling")
    return cloudlayers.CloudLayer(name, own, field_layers, enabled)


def _parse_storms(value: Any, where: str) -> list[dict[str, Any]]:
    if isinstance(value, list):
        limits.check_count(f"{where}: storms", len(value), MAX_STORMS, f"remove {len(value) - MAX_STORMS} of them")
    return _parse_tables(value, where, "storms", schema.STORM)


def _parse_tables(value: Any, where: str, name: str, settings: tuple[schema.Setting, ...]) -> list[dict[str, Any]]:
    """An array of tables ([[name]]), each filled from the schema's defaults and checked key by key."""
    if not isinstance(value, list):
        raise NubisError(f"{where}: {name} must be written as [[{name}]] tables")
    by_name = {s.name: s for s in settings if s.in_preset}
    tables = []
    for i, raw in enumerate(value):
        here = f"{where}: {name}[{i}]"
        if not isinstance(raw, dict):
            raise NubisError(f"{here} must be a table, not {toml_value(raw)}")
        table = schema.table_defaults(settings)
        for key, val in raw.items():
            if key not in by_name:
                raise NubisError(f"{here}: unknown key '{key}'; keys are {', '.join(by_name)}")
            table[key] = check_value(by_name[key], val, f"{here}.{key}")
        tables.append(table)
    return tables


def _number(value: Any, where: str) -> float:
    """A TOML integer or float as a finite float (a huge integer is out of range, not a crash)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise NubisError(f"{where} must be a number, not {toml_value(value)}")
    try:
        number = float(value)
    except OverflowError:
        number = math.inf
    if not math.isfinite(number):
        raise NubisError(f"{where} must be a finite number, not {toml_value(value)}")
    return number


def _check_range(value: Any, lo: float, hi: float, where: str) -> None:
    if not lo <= value <= hi:
        raise NubisError(f"{where} = {toml_value(value)} is out of range: use a value between {lo:g} and {hi:g}")


def check_value(setting: schema.Setting, value: Any, where: str) -> Any:
    """A preset's value for `setting`, checked against the schema: its type, range, choices or length."""
    kind = setting.kind
    if kind == "bool":
        if not isinstance(value, bool):
            raise NubisError(f"{where} must be true or false, not {toml_value(value)}")
        return value
    if kind == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise NubisError(f"{where} must be a whole number, not {toml_value(value)}")
    elif kind == "float":
        value = _number(value, where)
    elif kind in ("vector", "color"):
        if not isinstance(value, list):
            raise NubisError(f"{where} must be a list like [1.0, 2.0], not {toml_value(value)}")
        _check_vector(value, setting.size, where)
        return value
    elif not isinstance(value, str):  # enum, string, image
        raise NubisError(f"{where} must be text in quotes, not {toml_value(value)}")
    elif setting.name != "description":  # names and paths; a description's tab or line break is harmless
        limits.check_text(where, value)
    if kind == "enum" and value not in setting.choices:
        choices = ", ".join(toml_value(c) for c in setting.choices)
        raise NubisError(f"{where} = {toml_value(value)} is not allowed: use one of {choices}")
    if kind in ("int", "float") and setting.min is not None and setting.max is not None:
        _check_range(value, setting.min, setting.max, where)
    return value


def _check_vector(value: list, n: int, where: str) -> None:
    if len(value) != n or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value):
        raise NubisError(f"{where} must be a list of {n} numbers, not {toml_value(value)}")
    for i, v in enumerate(value):
        value[i] = _number(v, where)


def _check_span(value: list, where: str) -> None:
    """A position in metres the renderer can serve (core/limits.py)."""
    if not all(abs(v) <= limits.POSITION_MAX for v in value):
        raise NubisError(
            f"{where} = {toml_value(value)} is out of range: keep each coordinate within "
            f"{limits.POSITION_MAX:g} m of the origin"
        )


def _parse_layers(value: Any, where: str) -> list[dict[str, Any]]:
    if isinstance(value, list):
        limits.check_count(
            f"{where}: field.layers",
            len(value),
            limits.MAX_FIELD_LAYERS,
            "merge or remove layers (each costs a full pass)",
        )
        # A paint layer's strokes (core/paint.py) are its own array, not a setting of the schema.
        dabs = [raw.get("dabs") if isinstance(raw, dict) else None for raw in value]
        value = [{k: v for k, v in raw.items() if k != "dabs"} if isinstance(raw, dict) else raw for raw in value]
    else:
        dabs = []
    layers = _parse_tables(value, where, "field.layers", schema.FIELD_LAYER)
    for i, layer in enumerate(layers):
        here = f"{where}: field.layers[{i}]"
        if layer["kind"] == "paint" and layer["channel"] not in paint.PAINT_CHANNELS:
            raise NubisError(
                f"{here}.channel: a paint layer paints {', '.join(paint.PAINT_CHANNELS)}, "
                f"not {toml_value(layer['channel'])}"
            )
        if dabs[i] is not None:
            if layer["kind"] != "paint":
                raise NubisError(f'{here}.dabs: only a paint layer (kind = "paint") holds strokes')
            layer["dabs"] = paint.parse_dabs(dabs[i], f"{here}.dabs")
        _check_span(layer["center"], f"{here}.center")
        if layer["remap"][0] == layer["remap"][1]:
            raise NubisError(f"{here}.remap: the input range is empty; make remap[0] and remap[1] differ")
        if layer["kind"] == "image" and not layer["image"]:
            raise NubisError(f"{here}.image: an image layer needs the name or path of an image")
        layer["name"] = layer["name"] or f"Layer {i + 1}"
    return layers


def _check_masks(layers: list[dict[str, Any]], where: str) -> None:
    seen: set[str] = set()
    for i, layer in enumerate(layers):
        if layer["mask"] and layer["mask"] not in seen:
            raise NubisError(
                f"{where}: field.layers[{i}].mask names {toml_value(layer['mask'])}, which is not an earlier layer: "
                "masks must refer to a layer above them"
            )
        seen.add(layer["name"])
