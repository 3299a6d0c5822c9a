"""Registering the extension's Blender side: properties, handlers, operators, panels and the draw."""

from __future__ import annotations

import bpy

from .f12 import scene_render
from .host import preferences, runtime
from .jobs import work
from .live import events, viewport
from .scene import sky, vdbclouds
from .sidebar import operators, paint, panels, properties, skylayers, stormbuttons

_registered = [False]


def register() -> None:
    if _registered[0]:
        return
    properties.register()
    events.register()
    operators.register()
    skylayers.register()
    stormbuttons.register()
    panels.register()
    vdbclouds.register()  # its sidebar panel is a child of the main one
    paint.register()  # likewise
    preferences.register()
    viewport.register()
    sky.register()
    scene_render.register()
    work.register()
    _registered[0] = True


def unregister() -> None:
    if not _registered[0]:
        return
    work.unregister()
    scene_render.unregister()
    sky.unregister()
    viewport.unregister()
    preferences.unregister()
    paint.unregister()
    vdbclouds.unregister()
    panels.unregister()
    stormbuttons.unregister()
    skylayers.unregister()
    operators.unregister()
    events.unregister()
    properties.unregister()
    runtime.free()
    _registered[0] = False


def ensure_registered() -> None:
    """For the command line: the property group must exist before a scene is read or built."""
    if not hasattr(bpy.types.Scene, "nubis"):
        _registered[0] = False
        register()
