"""Presets are TOML data, validated on load and never executed.

Every error names the file and the field, and says what to do.
"""

from __future__ import annotations

import math
import os
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from . import limits
from .errors import NubisError
from .params import PARAMS, PARAMS_BY_KEY, defaults
from .state import MAX_STORMS
from .tomlfmt import toml_value

FIELD_CHANNELS = (
    "coverage",
    "precipitation",
    "type",
    "bottom_type",
    "storm",
    "min_height",
    "max_height",
    "density",
    "cirrus_coverage",
    "cirrus_type",
    "none",
)
LAYER_KINDS = ("perlin", "worley", "perlin_worley", "gradient", "constant", "image")
BLEND_MODES = ("replace", "add", "multiply", "min", "max")
GRADIENT_SHAPES = ("linear", "radial")

# Every field-layer key, with (type, default, min, max) or (type, default, choices).
LAYER_SCHEMA: dict[str, tuple] = {
    "name": (str, ""),
    "kind": (str, "perlin", LAYER_KINDS),
    "channel": (str, "coverage", FIELD_CHANNELS),
    "blend": (str, "replace", BLEND_MODES),
    "enabled": (bool, True),
    "opacity": (float, 1.0, 0.0, 1.0),
    "mask": (str, ""),
    "invert_mask": (bool, False),
    "scale": (float, 8000.0, 1.0, 1e7),
    "seed": (int, 0, 0, 2**31 - 1),
    "octaves": (int, 4, 1, 10),
    "remap": (list, [0.0, 1.0, 0.0, 1.0]),
    "value": (float, 1.0, -1e6, 1e6),
    "gradient": (str, "linear", GRADIENT_SHAPES),
    "angle": (float, 0.0, -360.0, 360.0),
    "center": (list, [0.0, 0.0]),
    "radius": (float, 10000.0, 1.0, 1e7),
    "image": (str, ""),
}

EXTRA_SCHEMA: dict[str, dict[str, tuple]] = {
    "preset": {"name": (str, "Untitled"), "description": (str, "")},
    "sun": {
        "elevation": (float, 35.0, -90.0, 90.0),
        "azimuth": (float, 135.0, -360.0, 360.0),
        "color": (list, [1.0, 0.96, 0.9]),
        "strength": (float, 4.0, 0.0, 1e5),
        "angle": (float, 0.53, 0.0, 180.0),
    },
    # `sky`: a physically based World (Blender's Sky Texture) whose sky light has the luminance of
    # colour x strength at the preset's sun; false keeps the flat colour. Air, aerosol and ozone are
    # multiples of the standard atmosphere (the Sky Texture's densities).
    "world": {
        "color": (list, [0.35, 0.5, 0.8]),
        "strength": (float, 1.0, 0.0, 1e5),
        "sky": (bool, True),
        "air": (float, 1.0, 0.0, 10.0),
        "aerosol": (float, 1.0, 0.0, 10.0),
        "ozone": (float, 1.0, 0.0, 10.0),
    },
    # SPEC 1.3.1: the weather rules, applied after the layer stack (S15, GPU Pro 7).
    "rules": {
        "rain": (bool, False),
        "horizon": (bool, False),
        "cumulonimbus_top": (float, 2.6, 0.0, 8.0),
        "horizon_start": (float, 15000.0, 0.0, 1e6),
    },
    "camera": {
        "location": (list, [0.0, 0.0, 2.0]),
        "rotation": (list, [80.0, 0.0, 0.0]),
        "lens": (float, 24.0, 1.0, 5000.0),
        "clip_end": (float, 200000.0, 10.0, 1e8),
    },
    "render": {
        "width": (int, 640, 4, 16384),
        "height": (int, 360, 4, 16384),
        "samples": (int, 64, 1, 65536),
        "volume_bounces": (int, 8, 0, 1024),
        "view_transform": (str, "AgX", ("AgX", "Standard", "Filmic", "Khronos PBR Neutral")),
        "frame": (int, 1, -1048574, 1048574),
    },
}


# A superstorm stencil (SPEC 1.9.1): where it is, how big and strong, and how it is lit.
STORM_SCHEMA: dict[str, tuple] = {
    "name": (str, "Superstorm"),
    "x": (float, 0.0, -1e7, 1e7),
    "y": (float, 0.0, -1e7, 1e7),
    "radius": (float, 12000.0, 100.0, 1e6),
    "coverage": (float, 1.0, 0.0, 1.0),
    "blend": (float, 1.0, 0.0, 1.0),
    "height": (float, 3.0, 0.1, 8.0),
    "base": (float, -0.1, -1.0, 1.0),
    "bottom_type": (float, 0.85, 0.0, 1.0),
    "seed": (int, 0, 0, 2**31 - 1),
    "spin": (float, 0.02, -10.0, 10.0),
    "darkening": (float, 3.0, 1.0, 50.0),
    "glow": (float, 0.0, 0.0, 1e4),
    "glow_color": (list, [1.0, 0.08, 0.03]),
    "ambient_boost": (float, 1.5, 0.0, 20.0),
    "anvil_offset": (float, 12000.0, -1e6, 1e6),
}


@dataclass
class Preset:
    name: str
    path: Path | None
    params: dict[str, Any]
    extra: dict[str, dict[str, Any]]
    layers: list[dict[str, Any]] = field(default_factory=list)
    description: str = ""
    storms: list[dict[str, Any]] = field(default_factory=list)


def preset_dir() -> Path:
    return Path(__file__).resolve().parents[2] / "presets"


def list_presets(folder: Path | None = None) -> list[str]:
    folder = folder or preset_dir()
    return sorted(p.stem for p in folder.glob("*.toml"))


def find_preset(name: str, folder: Path | None = None) -> Path:
    """Presets are found by name in presets/, or by an explicit path to a .toml file."""
    folder = folder or preset_dir()
    if name.endswith(".toml") or os.sep in name:
        path = Path(name).expanduser()
        if not path.is_file():
            raise NubisError(f"preset file '{path}' not found: check the path")
        return path
    path = folder / f"{name}.toml"
    if not path.is_file():
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
        data = tomllib.loads(raw.decode("utf-8"))
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
    params = defaults()
    extra: dict[str, dict[str, Any]] = {
        sec: {k: spec[1] for k, spec in keys.items()} for sec, keys in EXTRA_SCHEMA.items()
    }
    sections = {p.section for p in PARAMS}
    layers: list[dict[str, Any]] = []
    storms: list[dict[str, Any]] = []
    for sec, table in data.items():
        if sec == "storms":
            storms = _parse_storms(table, where)
            continue
        if not isinstance(table, dict):
            raise NubisError(f"{where}: '{sec}' must be a table like [{sec}], not {toml_value(table)}")
        if sec not in sections and sec not in EXTRA_SCHEMA:
            known = ", ".join(sorted(sections | set(EXTRA_SCHEMA)))
            raise NubisError(f"{where}: unknown section [{sec}]; sections are {known}")
        for key, value in table.items():
            if sec == "field" and key == "layers":
                layers = _parse_layers(value, where)
                continue
            flat = f"{sec}_{key}"
            if flat in PARAMS_BY_KEY:
                params[flat] = _check_param(PARAMS_BY_KEY[flat], value, f"{where}: {sec}.{key}")
            elif sec in EXTRA_SCHEMA and key in EXTRA_SCHEMA[sec]:
                extra[sec][key] = _check_value(EXTRA_SCHEMA[sec][key], value, f"{where}: {sec}.{key}")
            else:
                raise NubisError(f"{where}: unknown setting {sec}.{key}: remove it or check the spelling")
    if params["layer_top"] <= params["layer_bottom"]:
        raise NubisError(f"{where}: layer.top must be above layer.bottom")
    if params["march_steps_max"] < params["march_steps_min"]:
        raise NubisError(f"{where}: march.steps_max must be at least march.steps_min")
    for sec, key, n in (
        ("sun", "color", 3),
        ("world", "color", 3),
        ("camera", "location", 3),
        ("camera", "rotation", 3),
    ):
        _check_vector(extra[sec][key], n, f"{where}: {sec}.{key}")
    _check_span(extra["camera"]["location"], f"{where}: camera.location")
    _check_masks(layers, where)
    meta = extra.pop("preset")
    return Preset(meta["name"], path, params, extra, layers, meta["description"], storms)


def _parse_storms(value: Any, where: str) -> list[dict[str, Any]]:
    if isinstance(value, list):
        limits.check_count(f"{where}: storms", len(value), MAX_STORMS, f"remove {len(value) - MAX_STORMS} of them")
    storms = _parse_tables(value, where, "storms", STORM_SCHEMA)
    for i, storm in enumerate(storms):
        _check_vector(storm["glow_color"], 3, f"{where}: storms[{i}].glow_color")
    return storms


def _parse_tables(value: Any, where: str, name: str, schema: dict[str, tuple]) -> list[dict[str, Any]]:
    """An array of tables ([[name]]), each filled from the schema's defaults and checked key by key."""
    if not isinstance(value, list):
        raise NubisError(f"{where}: {name} must be written as [[{name}]] tables")
    tables = []
    for i, raw in enumerate(value):
        here = f"{where}: {name}[{i}]"
        if not isinstance(raw, dict):
            raise NubisError(f"{here} must be a table, not {toml_value(raw)}")
        table = {k: (list(spec[1]) if isinstance(spec[1], list) else spec[1]) for k, spec in schema.items()}
        for key, val in raw.items():
            if key not in schema:
                raise NubisError(f"{here}: unknown key '{key}'; keys are {', '.join(schema)}")
            table[key] = _check_value(schema[key], val, f"{here}.{key}")
        tables.append(table)
    return tables


_TYPE_NAMES = {str: "text in quotes", list: "a list like [1.0, 2.0]", bool: "true or false"}


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


def _check_param(p, value: Any, where: str) -> Any:
    if p.kind == "bool":
        if not isinstance(value, bool):
            raise NubisError(f"{where} must be true or false, not {toml_value(value)}")
        return value
    if p.kind == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise NubisError(f"{where} must be a whole number, not {toml_value(value)}")
    elif p.kind == "float":
        value = _number(value, where)
    if p.min is not None and p.max is not None:
        _check_range(value, p.min, p.max, where)
    return value


def _check_value(spec: tuple, value: Any, where: str) -> Any:
    typ = spec[0]
    if typ is float:
        value = _number(value, where)
    elif typ is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise NubisError(f"{where} must be a whole number, not {toml_value(value)}")
    elif not isinstance(value, typ):
        raise NubisError(f"{where} must be {_TYPE_NAMES.get(typ, typ.__name__)}, not {toml_value(value)}")
    if len(spec) == 3 and isinstance(spec[2], tuple) and value not in spec[2]:
        choices = ", ".join(toml_value(c) for c in spec[2])
        raise NubisError(f"{where} = {toml_value(value)} is not allowed: use one of {choices}")
    if len(spec) == 4:
        _check_range(value, spec[2], spec[3], where)
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
            f"{where}: field.layers", len(value), limits.MAX_LAYERS, "merge or remove layers (each costs a full pass)"
        )
    layers = _parse_tables(value, where, "field.layers", LAYER_SCHEMA)
    for i, layer in enumerate(layers):
        here = f"{where}: field.layers[{i}]"
        _check_vector(layer["remap"], 4, f"{here}.remap")
        _check_vector(layer["center"], 2, f"{here}.center")
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
