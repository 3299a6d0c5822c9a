"""The add-on's preferences (Edit > Preferences > Add-ons > Nubis Clouds): where the noise cache and the
user's presets live, how much the cache holds, and a Clear Cache button.

Blender finds an add-on's preferences by the add-on's module name: `bl_ext.<repo>.nubis` when installed
as an extension, `nubis_addon` when the package is registered as a plain module (the tests, the command
line); runtime.py derives it the same way for the user folders."""

from __future__ import annotations

import bpy
from bpy.props import IntProperty

from ...core import bricks, noise
from ...core.errors import NubisError
from . import runtime


def _megabytes(nbytes: int) -> str:
    return f"{nbytes / 2**20:.1f} MB"


def cache_summary() -> str:
    """One line on the noise cache: what it holds and its bounds."""
    usage = noise.cache_usage(runtime.cache_dir())
    sets = "1 noise set" if usage.sets == 1 else f"{usage.sets} noise sets"
    return (
        f"{sets}, {_megabytes(usage.nbytes)} (keeps at most {noise.CACHE_MAX_SEEDS} sets, "
        f"{_megabytes(noise.CACHE_MAX_BYTES)}; the least recently used go first)"
    )


class NubisPreferences(bpy.types.AddonPreferences):
    bl_idname = runtime._EXT_PACKAGE

    vdb_gpu_budget: IntProperty(
        name="VDB Cloud GPU Budget (MB)",
        description=(
            "GPU memory the VDB clouds may take together. A cloud whose finest bricks need more is drawn "
            "from a coarser level of its file (2x, 4x, ... fewer voxels per side), in the viewport, F12 and bakes"
        ),
        default=bricks.DEFAULT_GPU_LIMIT // 2**20,
        min=1,
        max=65536,
    )

    def draw(self, _context):
        layout = self.layout
        try:
            cache, presets = runtime.cache_dir(), runtime.user_preset_dir()
            summary = cache_summary()
        except NubisError as err:
            layout.label(text=str(err), icon="ERROR")
            return
        box = layout.box()
        box.label(text="Noise Cache", icon="FILE_CACHE")
        row = box.row()
        row.label(text=str(cache))
        row.operator("wm.path_open", text="", icon="FILEBROWSER").filepath = str(cache)
        box.label(text=summary)
        generating = runtime.noise_generating()
        if generating is not None:
            box.label(text=f"Generating noise for seed {generating}...", icon="TIME")
        box.operator("nubis.clear_cache", icon="TRASH")
        box = layout.box()
        box.label(text="VDB Clouds", icon="OUTLINER_OB_VOLUME")
        box.prop(self, "vdb_gpu_budget")
        box = layout.box()
        box.label(text="User Presets", icon="PRESET")
        row = box.row()
        row.label(text=str(presets))
        row.operator("wm.path_open", text="", icon="FILEBROWSER").filepath = str(presets)


CLASSES = (NubisPreferences,)

register, unregister = bpy.utils.register_classes_factory(CLASSES)
