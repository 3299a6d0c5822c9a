"""A GPU context for the `gpu` module in background mode (docs/platform-notes.md#gpu-in-background-mode)."""

from __future__ import annotations

import bpy
import gpu

from ..core.errors import NubisError

_ready = False


def _gpu_works() -> bool:
    try:
        gpu.types.Buffer("FLOAT", 1)
        gpu.types.GPUOffScreen(4, 4)
    except SystemError:
        return False
    return True


def ensure_gpu_context() -> None:
    """Make the gpu module usable; in background mode, rendering one tiny Workbench frame creates
    Blender's GPU context, which then lives for the rest of the session."""
    global _ready
    if _ready:
        return
    if not bpy.app.background or _gpu_works():
        _ready = True
        return
    scene = bpy.data.scenes.new(".nubis_gpu_init")
    cam_data = bpy.data.cameras.new(".nubis_gpu_init")
    cam = bpy.data.objects.new(".nubis_gpu_init", cam_data)
    try:
        scene.collection.objects.link(cam)
        scene.camera = cam
        scene.render.engine = "BLENDER_WORKBENCH"
        scene.render.resolution_x = scene.render.resolution_y = 4
        bpy.ops.render.render(scene=scene.name)
    except RuntimeError as err:
        raise NubisError(f"Blender could not render in background mode ({err}): {_EGL_HINT}") from None
    finally:
        bpy.data.objects.remove(cam)
        bpy.data.cameras.remove(cam_data)
        bpy.data.scenes.remove(scene)
    if not _gpu_works():
        raise NubisError(f"no GPU context in background mode: {_EGL_HINT}")
    _ready = True


_EGL_HINT = (
    "install Mesa's EGL and OpenGL drivers (Debian: apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri) "
    "or run on a machine with a GPU"
)


def renderer_name() -> str:
    return f"{gpu.platform.renderer_get()} ({gpu.platform.backend_type_get()})"
