"""Entry points that run with no interface: the command line's commands (commands, parsed by cli.py),
`blender -b --command nubis` (blender_command), and what a Dask worker process runs for a farm bake
(daskworker). The commands and the worker register the extension first, so they sit above registration.

May import: every folder of blender/ and registration."""
