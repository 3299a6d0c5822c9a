"""`blender -b [FILE.blend] --command nubis ...`: the command line, registered with Blender."""

from __future__ import annotations

import bpy

COMMAND_ID = "nubis"
_handle = None


def execute(argv: list[str]) -> int:
    from ..cli import run

    return run(argv, in_blender=True)


def register() -> None:
    global _handle
    if _handle is None:
        _handle = bpy.utils.register_cli_command(COMMAND_ID, execute)


def unregister() -> None:
    global _handle
    if _handle is not None:
        bpy.utils.unregister_cli_command(_handle)
        _handle = None


def is_registered() -> bool:
    return _handle is not None
