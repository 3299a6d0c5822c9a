"""What a change triggers (the schema's `trigger` column, core/schema.py), and Blender's handlers.

- "redraw": the clouds are drawn again; the viewport's temporal history restarts by itself when the
  uniform block changes (render/temporal.py).
- "field": the data field is composited again from the layer stack, the rules and the storms, then drawn.
Painting an image layer re-composites after a short pause, so a fast brush does not on every dab; frame
changes re-composite when storms are animated.
"""

from __future__ import annotations

import bpy

from ..core.errors import NubisError
from . import scene_io, status, viewport


def changed(scene, trigger: str) -> None:
    """Apply what a change with this trigger needs; errors go to the sidebar, never raise into Blender."""
    if trigger == "none" or scene_io.in_batch_edit():
        return
    if trigger == "field" and scene_io.has_cloudscape(scene):
        try:
            scene_io.generate_fields(scene)
            status.clear_error()
        except NubisError as err:
            status.set_error(str(err))
    viewport.invalidate()
    scene_io.redraw_views()


def update_callback(trigger: str):
    """The `update=` function of a property whose change has this trigger."""

    def update(_self, context) -> None:
        changed(getattr(context, "scene", None), trigger)

    update.__name__ = f"nubis_update_{trigger}"
    return update


_pending_images: set[str] = set()
_scene_updates = [0]  # counts depsgraph updates: the scene's geometry (and so its depth) may have changed


def scene_updates() -> int:
    return _scene_updates[0]


@bpy.app.handlers.persistent
def on_load(*_args) -> None:
    """A new file: forget cached pixels and any paint regeneration pending for the old one."""
    viewport.invalidate()
    _pending_images.clear()
    if bpy.app.timers.is_registered(_regenerate_after_paint):
        bpy.app.timers.unregister(_regenerate_after_paint)


@bpy.app.handlers.persistent
def on_frame_change(scene, _depsgraph=None) -> None:
    """Animated storms (lifecycle blend, a moving Empty) change the field: re-composite on frame changes."""
    settings = getattr(scene, "nubis", None)
    if not scene_io.has_cloudscape(scene) or not settings.storms:
        return
    if scene_io.storms_animated(settings):
        try:
            scene_io.generate_fields(scene)
        except NubisError as err:
            status.set_error(str(err))


@bpy.app.handlers.persistent
def on_depsgraph_update(scene, depsgraph) -> None:
    """Strokes on an image layer arrive as image updates; a short timer gathers them. Any update may
    move geometry, so the viewport reads its depth again."""
    _scene_updates[0] += 1
    viewport.geometry_changed(_scene_updates[0])
    if not scene_io.has_cloudscape(scene):
        return
    used = scene_io.layer_images(scene.nubis)
    edited = {u.id.name for u in depsgraph.updates if isinstance(u.id, bpy.types.Image) and u.id.name in used}
    if edited:
        _pending_images.update(edited)
        if not bpy.app.timers.is_registered(_regenerate_after_paint):
            bpy.app.timers.register(_regenerate_after_paint, first_interval=0.25)


def _regenerate_after_paint():
    _pending_images.clear()
    scene = bpy.context.scene
    if scene_io.has_cloudscape(scene):
        try:
            scene_io.generate_fields(scene)
        except NubisError as err:
            status.set_error(str(err))
        scene_io.redraw_views()
    return None


_HANDLERS = (
    (bpy.app.handlers.load_post, on_load),
    (bpy.app.handlers.depsgraph_update_post, on_depsgraph_update),
    (bpy.app.handlers.frame_change_post, on_frame_change),
)


def register() -> None:
    for handlers, fn in _HANDLERS:
        if fn not in handlers:
            handlers.append(fn)


def unregister() -> None:
    for handlers, fn in _HANDLERS:
        if fn in handlers:
            handlers.remove(fn)
    _pending_images.clear()
    if bpy.app.timers.is_registered(_regenerate_after_paint):
        bpy.app.timers.unregister(_regenerate_after_paint)
