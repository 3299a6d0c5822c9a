"""What follows the artist live: the 3D viewport's draw (viewport) and what each change of a setting, a
frame or a file triggers (events).

May import: core/, render/, blender/host/, blender/scene/."""
