"""Nubis for Blender: real-time volumetric cloudscapes after Guerrilla Games' Nubis.

Layers, each importing only those below it: cli.py (argument parsing and exit codes) over blender/
(bpy glue) over render/ (the gpu module) over core/ (pure Python and numpy). Importing this package
does not import bpy, so core/ tests run without Blender.
"""


def register() -> None:
    from . import blender, cli
    from .blender.headless import blender_command

    blender.register()
    blender_command.register(cli.run)


def unregister() -> None:
    from . import blender
    from .blender.headless import blender_command

    blender_command.unregister()
    blender.unregister()
