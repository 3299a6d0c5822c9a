"""Blender's side of the extension, listed from the top down: each module imports only modules listed
after it.

- commands: the command line's commands (cli.py parses, these run); daskworker: what a Dask worker process
  runs for a farm bake (it registers the extension, so it sits above registration);
- registration: registers what follows (and ensure_registered for the command line and farm workers);
- panels, skylayers, stormbuttons, operators: the sidebar, its Cloud Layers list's and Superstorms panel's
  buttons, and what the other buttons do;
- paint: the Paint Sky tool, its operator and panel; properties: the property groups, generated from
  core/schema.py; preview: the viewport's draw headless, and the benchmark; scene_render: F12 and Render
  Animation with the clouds in EEVEE and Cycles, and the panorama; work: the bake or render that runs in
  steps while the artist keeps working; farm: bakes of frame sequences and bakes spread over Dask workers;
- events: what a change triggers, and Blender's handlers; comparison: the viewport against Cycles
  rendering the bake of the same shot (compare); pipeline: renders, bakes and Cycles renders;
- shadows: the clouds' shadow casters in final renders; composition: F12's depth pre-pass and the veil of
  the clouds in front of the objects;
- viewport: the 3D view's draw; snapshot: what a bake reads from the scene when it starts, with GPU inputs
  of its own;
- scenepresets: a preset into a scene and a scene back into a preset; scene_io: the scene as one
  CloudState, what core/ and render/ draw from;
- datafield: the data field in the scene (its field layers, images, strokes and composite, for every cloud
  layer); superstorms: the storms' Empties, stencils and lights; sceneparams: the scene's settings as plain
  values, their animation, and what the session remembers of each scene; reference: Cycles' noise and its
  reuse;
- sun_air: Cycles rendering the bake lit by the sun through the air (a shell only shadow rays see);
- sky: the physical sky World and its captures;
- vdbclouds: Volume objects drawn as Nubis clouds; mainthread: work a render thread hands to the main
  thread; presetlist: the presets the sidebar lists; preferences: the add-on's preferences (the cache, the
  user's presets);
- runtime: session GPU resources and the user's folders; cycles_setup: a bake as a Cycles volume with the
  matching material; handlers: application handlers added once; status: messages for the sidebar; ui: what
  the interface's pieces share (has_cloudscape, the cloudscape poll, the sidebar panel, redraws);
- blender_command: `blender -b --command nubis`, registered by the package's register().
"""

from __future__ import annotations

from .registration import ensure_registered, register, unregister

__all__ = ("ensure_registered", "register", "unregister")
