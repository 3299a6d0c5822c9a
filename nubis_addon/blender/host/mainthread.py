"""Work that must run on Blender's main thread, asked for from another thread, and errors reported to the
artist from anywhere.

The real application renders F12 and Render Animation in a job on its own thread, and runs the render
handlers there. That thread has no GPU context, and the `gpu` module must not be called from it. The
render handlers therefore hand the frame's cloud work to the main thread through :func:`call` and wait for
it: a timer on the main thread (the pump) runs queued work between the interface's events, while the
render thread is parked before the engine reads the scene. Blender as a module, and `blender -b`, render
on the main thread, where :func:`call` runs the work directly.

The pump only runs while the interface runs (it is registered when the extension is, outside background
mode). If the main thread does not take the work in time (a modal dialog, Blender quitting and joining
the render thread), the caller gets a NubisError instead of waiting forever.
"""

from __future__ import annotations

import queue
import sys
import threading
from collections.abc import Callable
from typing import Any

import bpy

from ...core.errors import NubisError

PUMP_IDLE_S = 0.5  # how often the pump looks for work when no render job runs
PUMP_BUSY_S = 0.05  # ... and while one runs (every frame of an animation asks it)
PICKUP_TIMEOUT_S = 60.0  # how long a render thread waits for the main thread to start its work

_work: queue.Queue = queue.Queue()
_reports: queue.Queue = queue.Queue()


class _Item:
    def __init__(self, fn: Callable[[], Any]):
        self.fn = fn
        self.started = threading.Event()
        self.done = threading.Event()
        self.result: Any = None
        self.error: BaseException | None = None


def on_main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def call(fn: Callable[[], Any], timeout: float = 1800.0) -> Any:
    """Run `fn()` on the main thread and return its result (its exception is raised here). On the main
    thread it runs at once."""
    if on_main_thread():
        return fn()
    if bpy.app.background or not bpy.app.timers.is_registered(_pump):
        raise NubisError("Blender's main thread takes no work now (no interface): render from the main thread")
    item = _Item(fn)
    _work.put(item)
    if not item.started.wait(PICKUP_TIMEOUT_S):
        item.fn = None  # the pump skips it if it comes later
        raise NubisError(f"Blender's main thread did not respond within {PICKUP_TIMEOUT_S:.0f} s")
    if not item.done.wait(timeout):
        raise NubisError(f"the work on Blender's main thread took more than {timeout:.0f} s")
    if item.error is not None:
        raise item.error
    return item.result


def _pump():
    """Timer on the main thread: runs the queued work and shows queued reports."""
    while True:
        try:
            item = _work.get_nowait()
        except queue.Empty:
            break
        if item.fn is None:
            continue
        item.started.set()
        try:
            item.result = item.fn()
        except BaseException as err:  # noqa: BLE001 - handed to the waiting thread, which raises it
            item.error = err
        finally:
            item.done.set()
    _show_reports()
    return PUMP_BUSY_S if bpy.app.is_job_running("RENDER") else PUMP_IDLE_S


# ---- reports ----------------------------------------------------------------------------------------------


def report(message: str, level: str = "ERROR") -> None:
    """Tell the artist: on stderr (the console, a farm's log), in the sidebar's error line, and in the
    interface in the status bar and the Info editor (from the main thread, the next time the pump runs).
    Safe from any thread."""
    from . import status

    if level == "ERROR":
        status.set_error(message)
    print(f"Nubis {level.lower()}: {message}", file=sys.stderr, flush=True)  # the console and farm logs
    if bpy.app.background or not bpy.app.timers.is_registered(_pump):
        return
    _reports.put((level, message))
    if on_main_thread():
        _show_reports()


def _show_reports() -> None:
    while True:
        try:
            level, message = _reports.get_nowait()
        except queue.Empty:
            return
        try:
            bpy.ops.nubis.report(level=level, message=f"Nubis: {message}")
        except RuntimeError:
            pass  # an error report raises in the caller too; it is in the status bar and the Info editor
        except AttributeError:
            pass  # unregistered meanwhile; the console has it


class NUBIS_OT_report(bpy.types.Operator):
    """Shows a message from Nubis's background work in the status bar and the Info editor"""

    bl_idname = "nubis.report"
    bl_label = "Nubis Report"
    bl_options = {"INTERNAL"}

    level: bpy.props.EnumProperty(items=[(k, k.title(), "") for k in ("ERROR", "WARNING", "INFO")])
    message: bpy.props.StringProperty()

    def execute(self, _context):
        self.report({self.level}, self.message)
        return {"FINISHED"}


def register() -> None:
    bpy.utils.register_class(NUBIS_OT_report)
    if not bpy.app.background and not bpy.app.timers.is_registered(_pump):
        bpy.app.timers.register(_pump, first_interval=PUMP_IDLE_S, persistent=True)


def unregister() -> None:
    if bpy.app.timers.is_registered(_pump):
        bpy.app.timers.unregister(_pump)
    bpy.utils.unregister_class(NUBIS_OT_report)
