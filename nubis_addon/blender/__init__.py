"""Blender glue: properties, operators, panels, the viewport draw and the command-line command."""

from __future__ import annotations

import bpy

from . import cli_command, operators, panels, properties, scene_render, sky, viewport

_registered = False


def register() -> None:
    global _registered
    if _registered:
        return
    properties.register()
    operators.register()
    panels.register()
    viewport.register()
    sky.register()
    scene_render.register()
    cli_command.register()
    _registered = True


def unregister() -> None:
    global _registered
    if not _registered:
        return
    cli_command.unregister()
    scene_render.unregister()
    sky.unregister()
    viewport.unregister()
    panels.unregister()
    operators.unregister()
    properties.unregister()
    from . import runtime

    runtime.free()
    _registered = False


def ensure_registered() -> None:
    """For the command line: the property group must exist before a scene is read or built."""
    if not hasattr(bpy.types.Scene, "nubis"):
        global _registered
        _registered = False
        register()
