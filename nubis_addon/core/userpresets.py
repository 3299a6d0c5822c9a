"""Presets the user saves: written as the same TOML the shipped presets are (presets/*.toml), read back
through the one validator (core/presets.py), never executed.

A saved preset holds every setting: the scene settings a preset carries, the layer stack, the storms,
and the sun, world, camera and render sections, each value written even where it is the default, so
loading it gives back the cloudscape that was saved. Files are written atomically (core/fsutil.py).
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path
from typing import Any

import numpy as np

from . import fsutil, presets, schema
from .errors import NubisError
from .tomlfmt import toml_literal

HEADER = "# A Nubis Clouds preset, saved from Blender. TOML data: edit it freely, it is validated on load.\n"
MAX_NAME = 64  # characters of a preset's name


def dump_preset(preset: presets.Preset) -> str:
    """`preset` as TOML that :func:`core.presets.preset_from_bytes` reads back to the same Preset. Sections
    follow the schema's order, [[field.layers]] after [field] and [[storms]] after the scene's sections."""
    out = [HEADER, "\n[preset]\n"]
    out.append(_line("name", preset.name))
    out.append(_line("description", preset.description))
    sections: dict[str, list[schema.Setting]] = {}
    for s in schema.PRESET_SCENE:
        sections.setdefault(s.section, []).append(s)
    for section, settings in sections.items():
        out.append(f"\n[{section}]\n")
        out.extend(_line(s.name, preset.params[s.key]) for s in settings)
        if section == "field":
            out.extend(_field_layers(preset.layers, "field.layers"))
    for storm in preset.storms:
        out.append("\n[[storms]]\n")
        out.extend(_table(storm, schema.STORM))
    for section, table in schema.EXTRA_SECTIONS.items():
        if section == "preset":
            continue
        values = preset.extra.get(section, {})
        out.append(f"\n[{section}]\n")
        out.extend(_line(name, values[name]) for name in table if name in values)
    out.extend(_cloud_layers(preset))
    return "".join(out)


def _field_layers(layers: list[dict[str, Any]], header: str) -> list[str]:
    out = []
    for layer in layers:
        out.append(f"\n[[{header}]]\n")
        out.extend(_table(layer, schema.FIELD_LAYER))
        if layer.get("dabs"):  # a paint layer's strokes, one dab a line
            rows = ",\n".join("  " + toml_literal(row) for row in layer["dabs"])
            out.append(f"dabs = [\n{rows},\n]\n")
    return out


def _cloud_layers(preset: presets.Preset) -> list[str]:
    """The further layers of a layered sky, last in the file: a [[cloud_layers]] table's sub-tables belong to
    the table above them, so nothing else may follow."""
    sections: dict[str, list[schema.Setting]] = {}
    for s in schema.CLOUD_LAYER_SETTINGS:
        if s.in_preset:
            sections.setdefault(s.section, []).append(s)
    out = []
    for cloud in preset.cloud_layers:
        out.append("\n[[cloud_layers]]\n")
        out.append(_line("name", cloud.name))
        out.append(_line("enabled", cloud.enabled))
        for section, settings in sections.items():
            out.append(f"\n[cloud_layers.{section}]\n")
            out.extend(_line(s.name, cloud.params[s.key]) for s in settings)
        out.extend(_field_layers(cloud.field_layers, "cloud_layers.field.layers"))
    return out


def _table(values: dict[str, Any], settings: tuple[schema.Setting, ...]) -> list[str]:
    return [_line(s.name, values[s.name]) for s in settings if s.in_preset and s.name in values]


def _line(key: str, value: Any) -> str:
    if isinstance(value, float) and not math.isfinite(value):
        raise NubisError(f"cannot save {key} = {value}: a preset holds finite numbers only; fix the setting")
    return f"{key} = {toml_literal(value)}\n"


def file_stem(name: str) -> str:
    """The file name (without .toml) a preset named `name` is saved under: lower case, words joined by _."""
    stem = re.sub(r"[^0-9a-z]+", "_", name.strip().lower()).strip("_")
    return stem[:MAX_NAME]


def check_name(name: str, shipped: Path | None = None) -> str:
    """The file stem for a new preset's `name`, or a NubisError saying what to change."""
    if not name.strip():
        raise NubisError("give the preset a name")
    if len(name) > MAX_NAME:
        raise NubisError(f"the preset name is {len(name)} characters long: keep it within {MAX_NAME}")
    stem = file_stem(name)
    if not stem:
        raise NubisError(f"the preset name '{name}' needs at least one letter or digit")
    if stem in presets.list_presets(shipped):
        raise NubisError(f"a preset shipped with Nubis is called '{stem}': choose another name")
    return stem


def save_user_preset(folder: str | os.PathLike, preset: presets.Preset, overwrite: bool = True) -> Path:
    """Write `preset` as ``<folder>/<stem>.toml`` atomically and return its path. The text is validated
    before it is written: a preset Nubis could not load again is never saved."""
    stem = check_name(preset.name)
    folder = fsutil.check_output_dir(folder)
    path = folder / f"{stem}.toml"
    if path.exists() and not overwrite:
        raise NubisError(f"a preset named '{stem}' exists already in '{folder}': choose another name")
    text = dump_preset(preset)
    presets.preset_from_bytes(text.encode("utf-8"), path)  # refuse to write what would not load
    try:
        with fsutil.atomic_path(path) as tmp:
            tmp.write_text(text, encoding="utf-8")
    except OSError as err:
        raise NubisError(f"cannot write the preset '{path}' ({err.strerror}): choose a writable folder") from None
    return path


def list_user_presets(folder: str | os.PathLike) -> list[Path]:
    d = Path(folder)
    return sorted(d.glob("*.toml")) if d.is_dir() else []


def remove_user_preset(folder: str | os.PathLike, stem: str, shipped: Path | None = None) -> Path:
    """Delete the user's preset `stem` from `folder`; a shipped preset is never deleted."""
    path = Path(folder) / f"{stem}.toml"
    if not path.is_file():
        if stem in presets.list_presets(shipped):
            raise NubisError(f"'{stem}' is a preset shipped with Nubis: only presets you saved can be removed")
        raise NubisError(f"there is no preset of yours named '{stem}' in '{folder}'")
    try:
        path.unlink()
    except OSError as err:
        raise NubisError(f"cannot remove the preset '{path}' ({err.strerror}): check its permissions") from None
    return path


def tidy_float32(value: Any) -> Any:
    """A value read from Blender (float32 properties) as the shortest decimal that reads back to the same
    float32: 0.3, not 0.30000001192092896. A property at a hard maximum such as 0.1 then stays within
    the validator's range, which the float32 value itself (0.10000000149) is not."""
    if isinstance(value, float) and math.isfinite(value):
        return float(format_float32(value))
    if isinstance(value, list | tuple):
        return [tidy_float32(v) for v in value]
    return value


def format_float32(value: float) -> str:
    """The shortest decimal string whose nearest float32 is ``float32(value)``."""
    return str(np.float32(value))
