"""Adding and removing Blender application handlers (bpy.app.handlers) as (list, function) pairs, once each."""

from __future__ import annotations


def add(pairs) -> None:
    for handlers, fn in pairs:
        if fn not in handlers:
            handlers.append(fn)


def remove(pairs) -> None:
    for handlers, fn in pairs:
        if fn in handlers:
            handlers.remove(fn)
