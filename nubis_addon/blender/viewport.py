"""The 3D viewport draw: the same cloud shader as the headless render, at reduced resolution."""

from __future__ import annotations

import bpy
import gpu
import mathutils
from gpu.types import GPUShaderCreateInfo, GPUStageInterfaceInfo
from gpu_extras.batch import batch_for_shader

from ..core import camera
from ..core.errors import NubisError
from ..render import engine
from ..render.sources import read_shader
from . import runtime, scene_io

_handle = None
_fields_cache: dict = {"key": None, "fields": None}
_offscreen: dict = {"size": None, "buffer": None}
_composite: dict = {}
_last_error: list[str] = []


@bpy.app.handlers.persistent
def mark_dirty(*_args) -> None:
    """Forget the cached field pixels (on file loads and setting edits)."""
    _fields_cache["key"] = None


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
    updates; a short timer gathers them so a fast brush does not re-composite on every dab."""
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


def _composite_shader():
    if "shader" not in _composite:
        iface = GPUStageInterfaceInfo("nubis_composite_iface")
        iface.smooth("VEC2", "uv")
        info = GPUShaderCreateInfo()
        info.sampler(0, "FLOAT_2D", "cloud_buffer")
        info.vertex_in(0, "VEC2", "pos")
        info.vertex_out(iface)
        info.fragment_out(0, "VEC4", "color")
        info.vertex_source(read_shader("nubis_background_vert.glsl"))
        info.fragment_source(read_shader("nubis_composite_frag.glsl"))
        sh = gpu.shader.create_from_info(info)
        _composite["shader"] = sh
        _composite["batch"] = batch_for_shader(sh, "TRIS", {"pos": ((-1, -1), (3, -1), (-1, 3))})
    return _composite["shader"], _composite["batch"]


def _state(scene, view_origin):
    """Settings, sun and sky are read every redraw (cheap); the field pixels only when they changed."""
    s = scene.nubis
    images = (s.field_a, s.field_b, s.field_cirrus)
    key = (scene.as_pointer(), s.field_resolution, scene_io.field_generation()) + tuple(
        img.as_pointer() if img else 0 for img in images
    )
    if _fields_cache["key"] != key:
        _fields_cache["fields"] = scene_io.read_fields(s)
        _fields_cache["key"] = key
    return scene_io.state_from_scene(scene, camera_location=view_origin, fields=_fields_cache["fields"])


def draw_view(scene, inv_view_proj, view_origin, width: int, height: int, perspective: bool = True) -> None:
    """March the clouds into a buffer of 1/N the size and composite it over the background."""
    settings = scene.nubis
    # Creating an offscreen rebinds framebuffers; remember the target so the composite lands there.
    target = gpu.state.active_framebuffer_get()
    state = _state(scene, view_origin)
    clouds = runtime.cloud_gpu(settings.noise_seed)
    clouds.update(state)
    n = max(1, settings.viewport_scale)
    size = (max(1, width // n), max(1, height // n))
    if _offscreen["size"] != size:
        if _offscreen["buffer"] is not None:
            _offscreen["buffer"].free()
        _offscreen["buffer"] = gpu.types.GPUOffScreen(*size, format="RGBA16F")
        _offscreen["size"] = size
    buffer = _offscreen["buffer"]
    with buffer.bind():
        gpu.state.active_framebuffer_get().clear(color=(0.0, 0.0, 0.0, 0.0))
        gpu.state.blend_set("NONE")
        gpu.state.depth_test_set("NONE")
        eye = (*view_origin[:3], 1.0) if perspective else (0.0, 0.0, 0.0, 0.0)
        engine.draw_clouds(clouds, inv_view_proj, eye)
    sh, batch = _composite_shader()
    with target.bind():
        gpu.state.blend_set("ALPHA_PREMULT")
        gpu.state.depth_test_set("LESS_EQUAL")
        gpu.state.depth_mask_set(False)
        sh.bind()
        sh.uniform_sampler("cloud_buffer", buffer.texture_color)
        batch.draw(sh)
    # Leave Blender's default state behind: a disabled depth mask would also stop later depth clears.
    gpu.state.depth_mask_set(True)
    gpu.state.depth_test_set("NONE")
    gpu.state.blend_set("NONE")


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
        draw_view(
            scene,
            mathutils.Matrix(camera.ray_inverse_view_projection(rv3d.window_matrix, rv3d.view_matrix).tolist()),
            rv3d.view_matrix.inverted().translation,
            region.width,
            region.height,
            rv3d.is_perspective,
        )
        _last_error.clear()
    except NubisError as err:
        # A draw callback cannot report; remember the message for the sidebar instead of spamming the console.
        if not _last_error or _last_error[0] != str(err):
            _last_error[:] = [str(err)]


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
    if _offscreen["buffer"] is not None:
        _offscreen["buffer"].free()
    _offscreen.update(size=None, buffer=None)
    _composite.clear()
    _fields_cache.update(key=None, fields=None)
    _pending_images.clear()
    if bpy.app.timers.is_registered(_regenerate_after_paint):
        bpy.app.timers.unregister(_regenerate_after_paint)


def is_registered() -> bool:
    return _handle is not None
