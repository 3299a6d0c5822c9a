"""A GPU context for the `gpu` module in background mode (docs/platform-notes.md#gpu-in-background-mode)."""

from __future__ import annotations

import atexit
import contextlib
from collections.abc import Callable

import bpy
import gpu

from ..core.errors import NubisError

_ready = False
_releases: list[Callable[[], None]] = []


def release_at_exit(release: Callable[[], None]) -> None:
    """Have `release` (which drops module-level GPU objects: shaders, batches, textures) run when the
    interpreter ends, before Blender's GPU context goes. A script that imports bpy as a module and ends
    normally tears Blender down in bpy's own exit handler; GPU objects left in module globals were freed
    after that, when Python cleared the modules, and a shader freed then crashed the process (GLShader's
    destructor on a context already gone). Exit handlers run last-registered first, and this module imports
    bpy first, so its handler runs before bpy's."""
    if release not in _releases:
        _releases.append(release)


def _release_all() -> None:
    for release in reversed(_releases):
        release()


atexit.register(_release_all)


def _gpu_works() -> bool:
    try:
        gpu.types.Buffer("FLOAT", 1)
        gpu.types.GPUOffScreen(4, 4)
    except (SystemError, RuntimeError):  # background mode before the first render; no context current
        return False
    return True


def _context_current() -> bool:
    """Whether a GPU context is current on this thread (in the interface, a window's, made current when it
    draws; none after a window closed until the next redraw)."""
    try:
        gpu.types.GPUTexture((1, 1), format="RGBA8")
    except (RuntimeError, SystemError):
        return False
    return True


def ensure_gpu_context() -> None:
    """Make the gpu module usable. In background mode, rendering one tiny Workbench frame creates
    Blender's GPU context, which then lives for the rest of the session. In the interface, work outside a
    draw callback (a timer, an operator) finds whichever window drew last current, or none right after a
    window closed: a redraw of the main window makes its context current."""
    global _ready
    if not bpy.app.background:
        if not _context_current():
            win = bpy.context.window_manager.windows[0]
            with bpy.context.temp_override(window=win, screen=win.screen):
                bpy.ops.wm.redraw_timer(type="DRAW_WIN", iterations=1)
            if not _context_current():
                raise NubisError("no GPU context is current on Blender's main thread: redraw the window and try again")
        return
    # Once made, the context is not always current: EEVEE's render of a frame leaves none current on the
    # main thread, so frame 2 of a Render Animation found no context; the same tiny render makes it
    # current again.
    if _ready and _context_current():
        return
    if _gpu_works():
        _ready = True
        return
    with camera_scene(".nubis_gpu_init") as (scene, _cam):
        scene.render.engine = "BLENDER_WORKBENCH"
        scene.render.resolution_x = scene.render.resolution_y = 4
        try:
            bpy.ops.render.render(scene=scene.name)
        except RuntimeError as err:
            raise NubisError(f"Blender could not render in background mode ({err}): {_EGL_HINT}") from None
    if not _gpu_works():
        raise NubisError(f"no GPU context in background mode: {_EGL_HINT}")
    _ready = True


@contextlib.contextmanager
def camera_scene(name: str):
    """A scene of its own with a camera as its camera, (scene, camera object), removed afterwards with its
    camera whatever happens: for renders the artist's scenes must not see."""
    scene = bpy.data.scenes.new(name)
    cam_data = bpy.data.cameras.new(name)
    cam = bpy.data.objects.new(name, cam_data)
    try:
        scene.collection.objects.link(cam)
        scene.camera = cam
        yield scene, cam
    finally:
        bpy.data.objects.remove(cam)
        bpy.data.cameras.remove(cam_data)
        bpy.data.scenes.remove(scene)


_EGL_HINT = (
    "install Mesa's EGL and OpenGL drivers (Debian: apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri) "
    "or run on a machine with a GPU"
)


def renderer_name() -> str:
    return f"{gpu.platform.renderer_get()} ({gpu.platform.backend_type_get()})"
