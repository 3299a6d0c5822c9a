"""Final renders with the clouds: F12, Render Animation and `blender -b -f` in EEVEE and Cycles
(scene_render), the clouds in front of the scene's objects on a veil (composition), and the clouds'
shadows on them (shadows).

May import: core/, render/, blender/host/, blender/scene/, blender/jobs/."""
