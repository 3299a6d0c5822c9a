"""What the sidebar shows of work done elsewhere: the viewport draw's last error and the benchmark's table.

A draw callback cannot report to the user, so it leaves its message here for the panels to show.
"""

from __future__ import annotations

_last_error: list[str] = []
last_benchmark: list[tuple[str, str]] = []  # the sidebar's Benchmark button's result: (name, value) rows


def set_error(message: str) -> None:
    if not _last_error or _last_error[0] != message:
        _last_error[:] = [message]


def clear_error() -> None:
    _last_error.clear()


def last_error() -> str:
    return _last_error[0] if _last_error else ""
