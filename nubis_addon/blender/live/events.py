"""What a change triggers (the schema's `trigger` column, core/schema.py), and Blender's handlers.

- "redraw": the clouds are drawn again; the viewport's temporal history restarts by itself when the
  uniform block changes (render/temporal.py).
- "field": the data field owes a composite. In the interface it is made a moment after the last of a
  burst of edits (a slider drag, a brush stroke, an Empty dragged in the viewport), so dragging stays
  fluid; renders, bakes and the command line make it at once when they read the field.
Frame changes re-composite when anything feeding the field is animated. The field images are packed
into the .blend when it is saved, and undo or redo re-composites from the restored settings.
"""

from __future__ import annotations

import bpy

from ...core import schema
from ...core.errors import NubisError
from ..host import handlers, mainthread, status, ui
from ..scene import datafield, sceneparams, superstorms
from . import viewport

# Seconds of quiet after the last edit before the field is composited again.
DEBOUNCE_S = 0.15


def changed(scene, trigger: str, key: str = "") -> None:
    """Apply what a change of `key` with this trigger needs; errors go to the sidebar, never raise into
    Blender."""
    if trigger == "none" or sceneparams.in_batch_edit() or scene is None:
        return
    if key:
        enforce_limits(scene.nubis, key)
    if trigger == "field" and ui.has_cloudscape(scene):
        request_composite(scene)
    viewport.invalidate()
    ui.redraw_views()


def update_callback(trigger: str, key: str = ""):
    """The `update=` function of a property whose change has this trigger."""

    def update(_self, context) -> None:
        changed(getattr(context, "scene", None), trigger, key)

    update.__name__ = f"nubis_update_{trigger}"
    return update


def cloud_layer_callback(trigger: str, key: str = ""):
    """The `update=` function of a further cloud layer's own setting: its limits kept on the layer itself,
    then what the trigger asks of the scene."""

    def update(layer, context) -> None:
        scene = getattr(context, "scene", None)
        if scene is None or sceneparams.in_batch_edit():
            return
        if key:
            enforce_limits(layer, key)
        changed(scene, trigger)

    update.__name__ = f"nubis_cloud_layer_update_{trigger}"
    return update


def enforce_limits(settings, key: str) -> None:
    """Keep the schema's cross-field limits (a layer top above its bottom, ...): dragging one setting past
    the other carries the other along, as the preset loader would otherwise refuse the file."""
    for rule in schema.CROSS_LIMITS:
        if key not in (rule.low, rule.high) or not hasattr(settings, rule.low):
            continue
        low, high = getattr(settings, rule.low), getattr(settings, rule.high)
        if high - low >= rule.gap:
            continue
        with sceneparams.batch_edit():
            if key == rule.low:
                setattr(settings, rule.high, type(high)(low + rule.gap))
            else:
                setattr(settings, rule.low, type(low)(high - rule.gap))


def request_composite(scene) -> None:
    """The field owes a composite: made after DEBOUNCE_S of quiet, or by the next render that reads it."""
    sceneparams.mark_field_stale(scene)
    if bpy.app.background:
        return  # no timers run without the interface: readers composite when they need the field
    if bpy.app.timers.is_registered(composite_stale):
        bpy.app.timers.unregister(composite_stale)  # restart the wait: a drag composites once, at its end
    bpy.app.timers.register(composite_stale, first_interval=DEBOUNCE_S)


def composite_stale():
    """Composite every scene that owes one (what the debounce timer runs)."""
    for scene in sceneparams.stale_scenes():
        if not ui.has_cloudscape(scene):
            continue
        try:
            datafield.generate_fields(scene)
            status.clear_error()
        except NubisError as err:
            sceneparams.forget_stale()
            status.set_error(str(err))
    viewport.invalidate()
    ui.redraw_views()
    return None


_scene_updates = [0]  # counts depsgraph updates: the scene's geometry (and so its depth) may have changed


@bpy.app.handlers.persistent
def on_load(*_args) -> None:
    """A new file: forget cached pixels and any composite owed by the old one."""
    viewport.invalidate()
    sceneparams.forget_stale()
    if bpy.app.timers.is_registered(composite_stale):
        bpy.app.timers.unregister(composite_stale)


@bpy.app.handlers.persistent
def on_frame_change(scene, _depsgraph=None) -> None:
    """Keyed layers, rules, storms and field settings change the field: composite for the new frame. (An
    animation rendered from the interface changes frames on its render thread; the frame's render handler
    sets the frame again on the main thread, which composites then: blender/f12/scene_render.py.)"""
    if not mainthread.on_main_thread():
        return
    if not ui.has_cloudscape(scene) or not sceneparams.field_animated(scene.nubis):
        return
    try:
        datafield.generate_fields(scene)
        status.clear_error()
    except NubisError as err:
        status.set_error(str(err))


@bpy.app.handlers.persistent
def on_depsgraph_update(scene, depsgraph) -> None:
    """Strokes on an image layer and moves of a storm's Empty owe a composite. Any update may move
    geometry, so the viewport reads its depth again."""
    _scene_updates[0] += 1
    viewport.geometry_changed(_scene_updates[0])
    if not ui.has_cloudscape(scene):
        return
    settings = scene.nubis
    used = datafield.layer_images(settings)
    for u in depsgraph.updates:
        if isinstance(u.id, bpy.types.Image) and u.id.name in used:
            request_composite(scene)
        elif isinstance(u.id, bpy.types.Object) and getattr(u, "is_updated_transform", True):
            if superstorms.storm_of_object(settings, u.id) is not None:
                request_composite(scene)


@bpy.app.handlers.persistent
def on_save_pre(*_args) -> None:
    """Pack the field images into the file being saved (composites leave them unpacked)."""
    for scene in bpy.data.scenes:
        if ui.has_cloudscape(scene):
            if sceneparams.field_stale(scene):
                try:
                    datafield.generate_fields(scene)
                except NubisError as err:
                    status.set_error(str(err))
            with sceneparams.batch_edit():  # the file keeps the multiplier its Coverage gives
                scene.nubis.density_coverage = datafield.coverage_multiplier(scene)
            datafield.pack_fields(scene.nubis)


@bpy.app.handlers.persistent
def on_undo_redo(*_args) -> None:
    """Undo and redo restore the settings, not necessarily the field's pixels: composite from them."""
    for scene in bpy.data.scenes:
        if ui.has_cloudscape(scene):
            request_composite(scene)
    viewport.invalidate()


_HANDLERS = (
    (bpy.app.handlers.load_post, on_load),
    (bpy.app.handlers.depsgraph_update_post, on_depsgraph_update),
    (bpy.app.handlers.frame_change_post, on_frame_change),
    (bpy.app.handlers.save_pre, on_save_pre),
    (bpy.app.handlers.undo_post, on_undo_redo),
    (bpy.app.handlers.redo_post, on_undo_redo),
)


def register() -> None:
    handlers.add(_HANDLERS)


def unregister() -> None:
    handlers.remove(_HANDLERS)
    sceneparams.forget_stale()
    if bpy.app.timers.is_registered(composite_stale):
        bpy.app.timers.unregister(composite_stale)
