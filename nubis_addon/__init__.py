"""Nubis for Blender: real-time volumetric cloudscapes after Guerrilla Games' Nubis.

Layers: core/ (pure Python + numpy), render/ (the gpu module), blender/ (bpy glue), cli.py.
Importing this package does not import bpy, so core/ tests run without Blender.
"""


def register() -> None:
    from . import blender

    blender.register()


def unregister() -> None:
    from . import blender

    blender.unregister()
