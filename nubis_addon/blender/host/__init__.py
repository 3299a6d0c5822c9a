"""What every Blender-side module stands on, importing no other folder of blender/: the session's GPU
resources and the user's folders (runtime), application handlers added once (handlers), work handed to
the main thread (mainthread), the sidebar's messages (status), the interface's shared pieces (ui), the
add-on's preferences, and the presets the sidebar lists (presetlist).

May import: core/, render/ and host/ itself."""
