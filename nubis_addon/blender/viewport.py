"""The 3D viewport draw: the temporal viewport of render/temporal.py, the same code the `preview` command runs."""

from __future__ import annotations

import time

import bpy
import gpu
import numpy as np

from ..core import camera
from ..core.errors import NubisError
from ..render import temporal
from . import runtime, scene_io

_handle = None
_fields_cache: dict = {}  # scene pointer -> (key, field arrays)
_views: dict = {}  # region pointer -> TemporalViewport
_depth_cache: dict = {}
_scene_updates = [0]  # counts depsgraph updates: the scene's geometry (and so its depth) may have changed
_last_error: list[str] = []
last_benchmark: list[str] = []  # the sidebar's Benchmark button's table, line by line


@bpy.app.handlers.persistent
def mark_dirty(*_args) -> None:
    """Forget the cached field pixels (on file loads and setting edits)."""
    _fields_cache.clear()


_pending_images: set[str] = set()


@bpy.app.handlers.persistent
def on_load(*_args) -> None:
    """A new file: forget cached pixels and any paint regeneration pending for the old one."""
    mark_dirty()
    _pending_images.clear()
    if bpy.app.timers.is_registered(_regenerate_after_paint):
        bpy.app.timers.unregister(_regenerate_after_paint)


@bpy.app.handlers.persistent
def on_frame_change(scene, _depsgraph=None) -> None:
    """Animated storms (lifecycle blend, a moving Empty) change the field: re-composite on frame changes."""
    settings = getattr(scene, "nubis", None)
    if settings is None or settings.field_a is None or not settings.storms:
        return
    if scene_io.storms_animated(settings):
        try:
            scene_io.generate_fields(scene)
        except NubisError as err:
            _last_error[:] = [str(err)]


@bpy.app.handlers.persistent
def on_depsgraph_update(scene, depsgraph) -> None:
    """Painting an image layer in the image editor re-composites the field. Strokes arrive as image
    updates; a short timer gathers them so a fast brush does not re-composite on every dab. Any update
    may move geometry, so the viewport reads its depth again."""
    _scene_updates[0] += 1
    settings = getattr(scene, "nubis", None)
    if settings is None or settings.field_a is None:
        return
    used = scene_io.layer_images(settings)
    edited = {u.id.name for u in depsgraph.updates if isinstance(u.id, bpy.types.Image) and u.id.name in used}
    if edited:
        _pending_images.update(edited)
        if not bpy.app.timers.is_registered(_regenerate_after_paint):
            bpy.app.timers.register(_regenerate_after_paint, first_interval=0.25)


def _regenerate_after_paint():
    _pending_images.clear()
    scene = bpy.context.scene
    if getattr(scene, "nubis", None) is not None and scene.nubis.field_a is not None:
        try:
            scene_io.generate_fields(scene)
        except NubisError as err:
            _last_error[:] = [str(err)]
        for window in bpy.context.window_manager.windows:
            for area in window.screen.areas:
                if area.type == "VIEW_3D":
                    area.tag_redraw()
    return None


def _state(scene, view_origin):
    """Settings, sun and sky are read every redraw (cheap); the field pixels only when they changed."""
    s = scene.nubis
    images = (s.field_a, s.field_b, s.field_cirrus)
    key = (scene.as_pointer(), s.field_resolution, scene_io.field_generation()) + tuple(
        img.as_pointer() if img else 0 for img in images
    )
    # One entry per scene: two windows on two cloudscapes must not re-read each other's fields.
    cached = _fields_cache.get(scene.as_pointer())
    if cached is None or cached[0] != key:
        if len(_fields_cache) >= _MAX_VIEWS:
            _fields_cache.clear()
        cached = _fields_cache[scene.as_pointer()] = (key, scene_io.read_fields(s))
    return scene_io.state_from_scene(scene, camera_location=view_origin, fields=cached[1], wait=False)


_MAX_VIEWS = 8  # 3D views with a history of their own; the least recently drawn is freed beyond this
_IDLE_SECONDS = 1.0  # a view not drawn for this long no longer asks for redraws
_FORGET_SECONDS = 60.0  # ... and is freed after this long (a closed area, a hidden workspace)


def temporal_view(key) -> temporal.TemporalViewport:
    """The temporal state of one 3D view (keyed by its region), created on first use."""
    now = time.monotonic()
    tv = _views.pop(key, None) or temporal.TemporalViewport()
    tv.last_drawn = now
    _views[key] = tv  # most recently used last
    for old in [k for k, v in _views.items() if now - getattr(v, "last_drawn", now) > _FORGET_SECONDS]:
        _views.pop(old).free()
        _depth_cache.pop(old, None)
    while len(_views) > _MAX_VIEWS:
        old = next(iter(_views))
        _views.pop(old).free()
        _depth_cache.pop(old, None)
    return tv


def draw_view(
    scene,
    inv_view_proj,
    view_origin,
    width: int,
    height: int,
    perspective: bool = True,
    key=None,
    depth=None,
    depth_key=None,
) -> temporal.TemporalViewport:
    """One redraw of the temporal viewport (render/temporal.py) over the bound framebuffer: march one
    pixel in 16 and resolve the history, unless it has converged, then upscale it behind the scene's
    objects. `depth` (a float texture of the view's depth) lets the march skip what geometry hides."""
    settings = scene.nubis
    # Binding the history's framebuffers rebinds; remember the target so the upscale lands there.
    target = gpu.state.active_framebuffer_get()
    state = _state(scene, view_origin)
    clouds = runtime.cloud_gpu(settings.noise_seed)
    eye = (*view_origin[:3], 1.0) if perspective else (0.0, 0.0, 0.0, 0.0)
    view = temporal.View.of(np.array(inv_view_proj), eye, width, height)
    tv = temporal_view(key)
    tv.redraw(clouds, state, view, settings.viewport_resolution, settings.viewport_samples, depth, depth_key)
    with target.bind():
        gpu.state.blend_set("ALPHA_PREMULT")
        gpu.state.depth_test_set("LESS_EQUAL")
        gpu.state.depth_mask_set(False)
        tv.upscale(clouds, settings.viewport_blur)
    # Leave Blender's default state behind: a disabled depth mask would also stop later depth clears.
    gpu.state.depth_mask_set(True)
    gpu.state.depth_test_set("NONE")
    gpu.state.blend_set("NONE")
    return tv


def _scene_depth(fb, width: int, height: int, key, view=None):
    """The view's depth as a texture, read back only when the view or the scene changed (a CPU round
    trip: Python has no handle on the viewport's depth texture); one entry per 3D view."""
    cached = _depth_cache.get(view)
    if cached is not None and cached[0] == key and cached[1] is not None:
        return cached[1]
    try:
        depth = fb.read_depth(0, 0, width, height)
        texture = gpu.types.GPUTexture((width, height), format="R32F", data=depth)
    except (ValueError, TypeError, SystemError):
        texture = None  # no depth attachment here: march everything
    _depth_cache[view] = (key, texture)
    return texture


def _converging_tick():
    """While a 3D view that is being drawn is still converging, keep asking for redraws (Blender redraws
    only on events); views that stopped drawing (closed, hidden, switched off) do not keep it going."""
    now = time.monotonic()
    if not any(not tv.converged and now - getattr(tv, "last_drawn", 0.0) < _IDLE_SECONDS for tv in _views.values()):
        return None
    wm = getattr(bpy.context, "window_manager", None)
    for window in wm.windows if wm else ():
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()
    return 1.0 / 60.0


def _keep_converging() -> None:
    if not bpy.app.timers.is_registered(_converging_tick):
        bpy.app.timers.register(_converging_tick, first_interval=1.0 / 60.0)


def _draw_callback() -> None:
    context = bpy.context
    scene = context.scene
    settings = getattr(scene, "nubis", None)
    if settings is None or not settings.enabled or settings.field_a is None:
        return
    region, rv3d = context.region, context.region_data
    if region is None or rv3d is None:
        return
    try:
        draw_region(scene, region, rv3d)
        _last_error.clear()
    except NubisError as err:
        # A draw callback cannot report; remember the message for the sidebar instead of spamming the console.
        if not _last_error or _last_error[0] != str(err):
            _last_error[:] = [str(err)]


def draw_region(scene, region, rv3d) -> temporal.TemporalViewport:
    """One redraw of a 3D view's region (`region`: width, height, as_pointer(); `rv3d`: view_matrix,
    window_matrix, is_perspective) over the bound framebuffer, its depth culling the march; asks for
    more redraws while the view converges."""
    fb = gpu.state.active_framebuffer_get()
    view_key = (tuple(map(tuple, rv3d.view_matrix)), tuple(map(tuple, rv3d.window_matrix)), _scene_updates[0])
    depth = _scene_depth(fb, region.width, region.height, view_key, region.as_pointer())
    # The eye from the same float64 inverse the rays use: mathutils inverts in float32, which puts the
    # eye millimetres off the rays' own origin and turns rays that are only metres long by 0.04 degrees.
    eye = np.linalg.inv(np.array(rv3d.view_matrix, dtype=np.float64))[:3, 3]
    tv = draw_view(
        scene,
        camera.ray_inverse_view_projection(rv3d.window_matrix, rv3d.view_matrix),
        eye,
        region.width,
        region.height,
        rv3d.is_perspective,
        key=region.as_pointer(),
        depth=depth,
        depth_key=_scene_updates[0],
    )
    if not tv.converged:
        _keep_converging()
    return tv


def last_error() -> str:
    return _last_error[0] if _last_error else ""


def register() -> None:
    global _handle
    if _handle is None:
        _handle = bpy.types.SpaceView3D.draw_handler_add(_draw_callback, (), "WINDOW", "POST_VIEW")
    if on_load not in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.append(on_load)
    if on_depsgraph_update not in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.append(on_depsgraph_update)
    if on_frame_change not in bpy.app.handlers.frame_change_post:
        bpy.app.handlers.frame_change_post.append(on_frame_change)


def unregister() -> None:
    global _handle
    if _handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_handle, "WINDOW")
        _handle = None
    if on_load in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(on_load)
    if on_depsgraph_update in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.remove(on_depsgraph_update)
    if on_frame_change in bpy.app.handlers.frame_change_post:
        bpy.app.handlers.frame_change_post.remove(on_frame_change)
    for tv in _views.values():
        tv.free()
    _views.clear()
    _depth_cache.clear()
    if bpy.app.timers.is_registered(_converging_tick):
        bpy.app.timers.unregister(_converging_tick)
    _fields_cache.clear()
    _pending_images.clear()
    if bpy.app.timers.is_registered(_regenerate_after_paint):
        bpy.app.timers.unregister(_regenerate_after_paint)


def is_registered() -> bool:
    return _handle is not None
