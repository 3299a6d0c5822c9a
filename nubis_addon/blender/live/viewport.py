"""The 3D viewport draw: the temporal viewport of render/temporal.py, the same code the `preview` command runs."""

from __future__ import annotations

import time
import traceback
from dataclasses import dataclass

import bpy
import gpu
import numpy as np
from mathutils import Matrix

from ...core import camera
from ...core.errors import NubisError
from ...render import engine, temporal
from ...render.gpu_context import release_at_exit
from ..host import runtime, status, ui
from ..scene import cloudstate, cycles_setup, datafield, vdbclouds

_handle = None
_fields_cache: dict = {}  # scene pointer -> (key, field arrays)
_views: dict = {}  # region pointer -> TemporalViewport
_depth_cache: dict = {}
release_at_exit(_views.clear)
release_at_exit(_depth_cache.clear)
_geometry = [0]  # the scene's geometry generation (blender/live/events.py counts depsgraph updates)


def invalidate() -> None:
    """Forget the cached field pixels (on file loads and setting edits)."""
    _fields_cache.clear()


def geometry_changed(generation: int) -> None:
    """The scene's geometry may have moved: each view reads its depth again on its next redraw."""
    _geometry[0] = generation


def _fields_key(scene) -> tuple:
    s = scene.nubis
    images = (s.field_a, s.field_b, s.field_cirrus)
    return (scene.as_pointer(), s.field_resolution, datafield.field_generation()) + tuple(
        img.as_pointer() if img else 0 for img in images
    )


def field_arrays(scene) -> tuple:
    """The field arrays the viewport draws for `scene`, read from the field images when they changed: a
    live brush stroke edits them in place (blender/sidebar/paint.py)."""
    key = _fields_key(scene)
    # One entry per scene: two windows on two cloudscapes must not re-read each other's fields.
    cached = _fields_cache.get(scene.as_pointer())
    if cached is None or cached[0] != key:
        if len(_fields_cache) >= _MAX_VIEWS:
            _fields_cache.clear()
        # Headless there is no debounce timer: a composite owed is made here. In the interface the
        # timer makes it (blender/live/events.py) and the draw shows the last field until then.
        cached = _fields_cache[scene.as_pointer()] = (key, datafield.read_fields(scene.nubis, flush=bpy.app.background))
    return cached[1]


def _state(scene, view_origin):
    """Settings, sun and sky are read every redraw (cheap); the field pixels only when they changed."""
    fields = field_arrays(scene)
    return cloudstate.state_from_scene(scene, camera_location=view_origin, fields=fields, wait=False)


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


@dataclass(frozen=True)
class ViewDraw:
    """One view to draw: its inverse view-projection and origin (the eye of a perspective view), its size,
    the temporal viewport it accumulates in (`key`), the scene's depth as a float texture with the key of
    what it shows and how it reads as distances (`mapping`, camera.depth_mapping), and whether the World's
    sky goes behind the clouds (Solid shading)."""

    inv_view_proj: object
    view_origin: object
    width: int
    height: int
    perspective: bool = True
    key: object = None
    depth: object = None
    depth_key: object = None
    sky: bool = False
    mapping: object = None


def draw_view(scene, request: ViewDraw, wait_for_noise: bool | None = None) -> temporal.TemporalViewport | None:
    """One redraw of the temporal viewport (render/temporal.py) over the bound framebuffer: march one
    pixel in 16 and resolve the history, unless it has converged, then upscale it. With the request's
    `depth` (and its `mapping`) each pixel the scene's geometry covers holds the clouds in front of that
    surface, laid over it as F12 lays them (docs/viewport.md#clouds-in-front-of-the-scene).

    Noise for a new seed is made synchronously headless, and in the interface (`wait_for_noise` False)
    on a worker thread: meanwhile the previous seed's clouds are drawn, or nothing (None is returned),
    and the sidebar says "Generating noise"; the views redraw when it is ready (blender/host/runtime.py).
    The request's `sky` draws the World's sky behind the clouds first (Solid shading, where Blender
    draws none)."""
    settings = scene.nubis
    if wait_for_noise is None:
        wait_for_noise = bpy.app.background
    if wait_for_noise:
        clouds = runtime.cloud_gpu(settings.noise_seed)
    else:
        clouds = runtime.cloud_gpu_nowait(settings.noise_seed, ui.redraw_views)
        if clouds is None:
            return None
    # Binding the history's framebuffers rebinds; remember the target so the upscale lands there.
    target = gpu.state.active_framebuffer_get()
    r = request
    state = _state(scene, r.view_origin)
    eye = (*r.view_origin[:3], 1.0) if r.perspective else (0.0, 0.0, 0.0, 0.0)
    mapping = r.mapping if r.depth is not None else None
    view = temporal.View.of(np.array(r.inv_view_proj), eye, r.width, r.height, mapping)
    tv = temporal_view(r.key)
    tv.redraw(clouds, state, view, settings.viewport_resolution, settings.viewport_samples, r.depth, r.depth_key)
    with target.bind():
        gpu.state.depth_mask_set(False)
        if r.sky:
            gpu.state.depth_test_set("LESS_EQUAL")  # the sky behind the objects
            gpu.state.blend_set("NONE")
            engine.draw_stage("sky", clouds, {"inv_view_proj": Matrix(view.inv_view_proj), "eye": view.eye})
        # The clouds over everything: each pixel holds what stands in front of its surface. Without the
        # scene's depth, only behind the objects (on the far plane).
        gpu.state.depth_test_set("NONE" if mapping is not None else "LESS_EQUAL")
        gpu.state.blend_set("ALPHA_PREMULT")
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
    ui.redraw_views()
    return 1.0 / 60.0


def _keep_converging() -> None:
    if not bpy.app.timers.is_registered(_converging_tick):
        bpy.app.timers.register(_converging_tick, first_interval=1.0 / 60.0)


# Shading modes the clouds are drawn in: not Wireframe, where they would hide the wires.
DRAWN_SHADING = {"SOLID", "MATERIAL", "RENDERED"}
HIDDEN_KEY = "nubis_hidden_views"  # a Screen's ID property: the indices of its areas that hide the clouds


def view_shows_clouds(context) -> bool:
    """Whether this 3D view draws the live clouds: the scene has them switched on, the view's own toggle
    is on, the shading is not Wireframe, and in Rendered mode no baked Nubis volume stands in for them
    (the render engine draws that one: the clouds would show twice)."""
    scene = context.scene
    if not ui.has_cloudscape(scene) or not scene.nubis.enabled:
        return False
    if not view_toggle(context):
        return False
    shading = getattr(getattr(context, "space_data", None), "shading", None)
    mode = getattr(shading, "type", "SOLID")
    if mode not in DRAWN_SHADING:
        return False
    if mode == "RENDERED":
        baked = scene.objects.get(cycles_setup.VOLUME_NAME)
        if baked is not None and not baked.hide_get() and not baked.hide_viewport:
            return False
    return True


def _area_index(context) -> int | None:
    screen, area = getattr(context, "screen", None), getattr(context, "area", None)
    if screen is None or area is None:
        return None
    return next((i for i, a in enumerate(screen.areas) if a == area), None)


def view_toggle(context) -> bool:
    """This 3D view's own Show Clouds toggle (kept in its screen, so it is saved with the file)."""
    index = _area_index(context)
    if index is None:
        return True
    return index not in list(context.screen.get(HIDDEN_KEY, ()))


def set_view_toggle(context, show: bool) -> None:
    index = _area_index(context)
    if index is None:
        return
    hidden = {int(i) for i in context.screen.get(HIDDEN_KEY, ())} - {index}
    if not show:
        hidden.add(index)
    context.screen[HIDDEN_KEY] = sorted(hidden)


def _draw_callback() -> None:
    draw_in_context(bpy.context)


def draw_in_context(context) -> bool:
    """The draw handler's body: draws this view's clouds if it shows them; returns whether it drew."""
    if not view_shows_clouds(context):
        return False
    scene = context.scene
    region, rv3d = context.region, context.region_data
    if region is None or rv3d is None:
        return False
    try:
        shading = getattr(context.space_data, "shading", None)
        sky = scene.nubis.viewport_solid_sky and shading is not None and shading.type == "SOLID"
        draw_region(scene, region, rv3d, sky)
        left_out = vdbclouds.first_problem()  # a VDB cloud not drawn: the clouds were, without it
        if left_out:
            status.set_error(left_out)
        else:
            status.clear_error()
    except NubisError as err:
        # A draw callback cannot report; remember the message for the sidebar instead of spamming the console.
        status.set_error(str(err))
    except Exception as err:  # noqa: BLE001 - nothing may raise from a draw handler: Blender would print it
        # on every redraw. The sidebar says it, the console once, with what to send in a report.
        detail = " ".join(str(err).split())[:200]
        message = (
            f"the clouds could not be drawn ({type(err).__name__}: {detail}): please report it with the console's text"
        )
        if status.last_error() != message:
            traceback.print_exc()
        status.set_error(message)
    return True


def draw_region(scene, region, rv3d, sky: bool = False) -> temporal.TemporalViewport | None:
    """One redraw of a 3D view's region (`region`: width, height, as_pointer(); `rv3d`: view_matrix,
    window_matrix, is_perspective) over the bound framebuffer, its depth culling the march; asks for
    more redraws while the view converges."""
    fb = gpu.state.active_framebuffer_get()
    view_key = (tuple(map(tuple, rv3d.view_matrix)), tuple(map(tuple, rv3d.window_matrix)), _geometry[0])
    depth = _scene_depth(fb, region.width, region.height, view_key, region.as_pointer())
    # The eye from the same float64 inverse the rays use: mathutils inverts in float32, which puts the
    # eye millimetres off the rays' own origin and turns rays that are only metres long by 0.04 degrees.
    eye = np.linalg.inv(np.array(rv3d.view_matrix, dtype=np.float64))[:3, 3]
    request = ViewDraw(
        camera.ray_inverse_view_projection(rv3d.window_matrix, rv3d.view_matrix),
        eye,
        region.width,
        region.height,
        rv3d.is_perspective,
        key=region.as_pointer(),
        depth=depth,
        depth_key=_geometry[0],
        sky=sky,
        mapping=camera.depth_mapping(rv3d.window_matrix, rv3d.view_matrix),
    )
    tv = draw_view(scene, request)
    if tv is not None and not tv.converged:
        _keep_converging()
    return tv


def register() -> None:
    global _handle
    if _handle is None:
        _handle = bpy.types.SpaceView3D.draw_handler_add(_draw_callback, (), "WINDOW", "POST_VIEW")


def unregister() -> None:
    global _handle
    if _handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_handle, "WINDOW")
        _handle = None
    for tv in _views.values():
        tv.free()
    _views.clear()
    _depth_cache.clear()
    if bpy.app.timers.is_registered(_converging_tick):
        bpy.app.timers.unregister(_converging_tick)
    _fields_cache.clear()


def is_registered() -> bool:
    return _handle is not None
