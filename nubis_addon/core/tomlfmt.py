"""Values in messages are quoted as TOML, the language presets are written in: `true`, not `True`;
`"text"`, not `'text'`; `1979-05-27`, not `datetime.date(1979, 5, 27)`."""

from __future__ import annotations

import datetime
import math
from typing import Any

_LIMIT = 80  # long values are cut: a message stays one readable line


def toml_value(value: Any) -> str:
    """``value`` as a TOML literal (an inline table for a dict), shortened to about 80 characters."""
    text = _format(value)
    return text if len(text) <= _LIMIT else text[: _LIMIT - 3] + "..."


def toml_literal(value: Any) -> str:
    """``value`` as a whole TOML literal, never shortened: what a written preset holds."""
    return _format(value)


def _format(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        escaped = value.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n").replace("\t", "\\t")
        escaped = "".join(c if c.isprintable() else _escape(c) for c in escaped)
        return f'"{escaped}"'
    if isinstance(value, datetime.datetime | datetime.date | datetime.time):
        return value.isoformat()
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_format(v) for v in value) + "]"
    if isinstance(value, dict):
        if not value:
            return "{}"
        return "{ " + ", ".join(f"{_key(k)} = {_format(v)}" for k, v in value.items()) + " }"
    return str(value)


def _escape(c: str) -> str:
    return f"\\u{ord(c):04x}" if ord(c) <= 0xFFFF else f"\\U{ord(c):08x}"


def _key(key: Any) -> str:
    key = str(key)
    if key and all(c.isalnum() or c in "-_" for c in key) and key.isascii():
        return key
    return _format(key)
