"""Viewport quality levels as data (presets/quality/quality.toml): each row sets the ray march and the
temporal viewport together, after GDC 2022's platform table for PS4 and PS5."""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

from . import schema
from .errors import NubisError

# Each row's keys and the scene setting each one writes (the schema's `quality` column).
ROW_KEYS: dict[str, str] = schema.QUALITY_COLUMNS
DEFAULT = "standard"


@dataclass(frozen=True)
class Quality:
    name: str
    label: str
    description: str
    settings: dict[str, Any]  # scene setting key -> value

    def apply(self, params: dict[str, Any]) -> dict[str, Any]:
        """`params` with this row's settings written over them (a new dict)."""
        return {**params, **self.settings}

    def matches(self, params: dict[str, Any]) -> bool:
        return all(params.get(k) == v for k, v in self.settings.items())


def quality_file() -> Path:
    return Path(__file__).resolve().parents[2] / "presets" / "quality" / "quality.toml"


@cache
def qualities(path: Path | None = None) -> dict[str, Quality]:
    """The rows by name, in file order; every error names the file and the row and says what to do."""
    path = path or quality_file()
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8-sig"))  # a byte-order mark is no part of the TOML
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as err:
        raise NubisError(
            f"cannot read the quality levels '{path}' ({err}): restore the file from the extension"
        ) from None
    rows = data.get("quality")
    if not isinstance(rows, list) or not rows:
        raise NubisError(f"'{path}' holds no [[quality]] rows: restore the file from the extension")
    out: dict[str, Quality] = {}
    for n, row in enumerate(rows, start=1):
        where = f"{path.name}, quality row {n}"
        if not isinstance(row, dict) or not isinstance(row.get("name"), str) or not row["name"]:
            raise NubisError(f"{where}: every row needs a name")
        unknown = set(row) - set(ROW_KEYS) - {"name", "label", "description"}
        missing = set(ROW_KEYS) - set(row)
        if unknown or missing:
            raise NubisError(f"{where} ('{row['name']}'): unknown keys {sorted(unknown)}, missing {sorted(missing)}")
        settings = {}
        for key, target in ROW_KEYS.items():
            settings[target] = _check(schema.BY_KEY[target], row[key], f"{where}, {key}")
        label, description = str(row.get("label", row["name"])), str(row.get("description", ""))
        out[row["name"]] = Quality(row["name"], label, description, settings)
    return out


def quality(name: str) -> Quality:
    rows = qualities()
    if name not in rows:
        raise NubisError(f"no quality named '{name}': choose one of {', '.join(rows)}")
    return rows[name]


def _check(p, value: Any, where: str) -> Any:
    if p.kind == "bool":
        if not isinstance(value, bool):
            raise NubisError(f"{where}: write true or false")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise NubisError(f"{where}: write a number")
    if p.kind == "int":
        if int(value) != value:
            raise NubisError(f"{where}: write a whole number")
        value = int(value)
    else:
        value = float(value)
    if not (p.min <= value <= p.max):
        raise NubisError(f"{where}: {value} is outside {p.min:g}-{p.max:g}")
    return value
