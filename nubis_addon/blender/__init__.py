"""Blender's side of the extension, a one-way chain from the top down:

- registration: registers what follows (and ensure_registered for the command line);
- commands: the command line's commands (cli.py parses, these run);
- panels, operators: the sidebar and what its buttons do;
- properties: the property groups, generated from core/schema.py;
- events: what a change triggers, and Blender's handlers;
- viewport: the 3D view's draw; preview: the same draw headless, and the benchmark;
- pipeline, cycles_setup: renders, bakes, Cycles scenes and comparisons;
- scene_io: Blender data to and from the plain data core/ and render/ work on;
- runtime: session GPU resources and the cache folder; status: messages for the sidebar;
- cli_command: `blender -b --command nubis`, registered by the package's register().
"""

from __future__ import annotations

from .registration import ensure_registered, register, unregister

__all__ = ("ensure_registered", "register", "unregister")
