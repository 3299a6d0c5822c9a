"""Blender's side of the extension, listed from the top down: each module imports only modules listed
after it.

- commands: the command line's commands (cli.py parses, these run); farm: bakes of frame sequences and
  bakes spread over Dask workers;
- registration: registers what follows (and ensure_registered for the command line and farm workers);
- panels, paint, operators: the sidebar, the Paint Sky tool and what the buttons do;
- preferences: the add-on's preferences (the cache, the user's presets);
- properties: the property groups, generated from core/schema.py;
- events: what a change triggers, and Blender's handlers;
- work: the bake or render that runs in steps while the artist keeps working;
- scene_render: F12 and Render Animation with the clouds in EEVEE and Cycles, and the panorama;
- viewport: the 3D view's draw; preview: the same draw headless, and the benchmark;
- pipeline, reference: renders, bakes, Cycles renders and comparisons, Cycles' noise and its reuse;
- snapshot: what a bake reads from the scene when it starts, with GPU inputs of its own;
- scene_io: Blender data to and from the plain data core/ and render/ work on;
- sky: the physical sky World and its captures; vdbclouds: Volume objects drawn as Nubis clouds;
- cycles_setup: a bake as a Cycles volume with the matching material;
- runtime: session GPU resources and the user's folders; mainthread: work a render thread hands to the
  main thread; handlers: application handlers added once; status: messages for the sidebar;
- cli_command: `blender -b --command nubis`, registered by the package's register().
"""

from __future__ import annotations

from .registration import ensure_registered, register, unregister

__all__ = ("ensure_registered", "register", "unregister")
