"""What follows the artist live: the 3D viewport's draw (viewport), what each change of a setting, a frame
or a file triggers (events), and a Paint Sky stroke as it is painted, patched into the drawn field
(paintstroke).

May import: core/, render/, blender/host/, blender/scene/."""
