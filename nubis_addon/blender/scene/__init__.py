"""The scene's clouds as data: its settings as plain values and their animation (sceneparams), the data
field's layers, images and strokes (datafield), the superstorms, the VDB clouds (vdbclouds), the physical
sky World (sky), its ground below the horizon (skyground) and its capture for the clouds' light
(skycapture), the scene as one CloudState the renderer draws (cloudstate), presets in and out of a scene
(scenepresets), a bake as a Cycles volume (cycles_setup), and the scene's own surfaces as renders see
them (surfaces).

May import: core/, render/, blender/host/."""
