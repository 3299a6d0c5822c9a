"""`blender -b [FILE.blend] --command nubis ...`: the command line, registered with Blender.

The function that runs it is handed in by the package's register() (nubis_addon/__init__.py), which
sits above both cli.py and blender/: nothing in blender/ imports the command line."""

from __future__ import annotations

from collections.abc import Callable

import bpy

COMMAND_ID = "nubis"
_handle = None
_run: list[Callable] = []


def execute(argv: list[str]) -> int:
    return _run[0](argv, in_blender=True)


def register(run: Callable[..., int]) -> None:
    global _handle
    _run[:] = [run]
    if _handle is None:
        _handle = bpy.utils.register_cli_command(COMMAND_ID, execute)


def unregister() -> None:
    global _handle
    if _handle is not None:
        bpy.utils.unregister_cli_command(_handle)
        _handle = None


def is_registered() -> bool:
    return _handle is not None
