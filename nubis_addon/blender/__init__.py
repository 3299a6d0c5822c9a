"""Blender's side of the extension, in folders by purpose, listed from the top down: each imports only
the folders listed after it, and no folder imports one above it (tests/core/test_architecture.py).

- headless/: the command line's commands, `blender -b --command nubis`, a Dask worker's tasks;
- registration.py: registers the properties, handlers, operators, panels and the draw (and
  ensure_registered for the command line and farm workers);
- sidebar/: the property groups, panels, buttons and the Paint Sky tool;
- f12/: F12 and Render Animation with the clouds in EEVEE and Cycles, the veil in front of the scene's
  objects, the clouds' shadows;
- jobs/: renders, bakes, Cycles renders, compare, preview and the benchmark, farms, the job that runs in
  steps while the artist works;
- live/: the 3D viewport's draw and what each change triggers;
- scene/: the scene's clouds as data: settings, field, storms, VDB clouds, the sky World, presets, the
  scene as one CloudState;
- host/: the session's GPU resources and folders, handlers, the main thread, the interface's shared
  pieces, the preferences.

live/ and jobs/ stand side by side: neither imports the other. Each folder's own docstring lists its
modules.
"""

from __future__ import annotations

from .registration import ensure_registered, register, unregister

__all__ = ("ensure_registered", "register", "unregister")
