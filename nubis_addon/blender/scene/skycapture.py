"""A World captured for the clouds' sky light: rendered by Cycles into an equirectangular image (kept in
the cache by the World's fingerprint), or read off a World of one colour; the environment the clouds are
lit by, with a capture refreshed off the draw when it is out of date."""

from __future__ import annotations

import hashlib
import math
import os
from pathlib import Path

import bpy
import numpy as np

from ...core import imageio, interrupt
from ...core import sky as skymath
from ...core.errors import NubisError
from ...render import gpu_context
from ..host import mainthread, runtime
from ..host.ui import redraw_views
from . import skyground

# The clouds' sky-light environment: fine enough that the bright band just above the horizon is not smeared
# into the ground below it, which would misplace the light the clouds receive from low in the sky
# (docs/measurements.md#sky-capture).
ENV_WIDTH = 128
ENV_SAMPLES = 4  # Cycles samples per pixel of a capture: a sky is smooth
BACKGROUND_WIDTH = 512  # the sky behind the clouds in pictures (render's PNG, panorama)
_captures: dict = {}  # (fingerprint, width, samples) -> a capture made this session
_busy = [False]  # a capture is rendering (the handlers leave the scene alone meanwhile)
_uniforms: dict[tuple, np.ndarray] = {}
_latest: dict[str, np.ndarray] = {}  # the last capture of each World, for the viewport's draw


def keep(world, env: np.ndarray) -> None:
    """Keep `env` as the capture of `world` as it stands now, at the clouds' size (build_world has just
    rendered it, so the clouds' first draw needs no second render)."""
    _captures[(fingerprint(world), ENV_WIDTH, ENV_SAMPLES)] = env


def fingerprint(world) -> tuple:
    """What a World's radiance depends on, for the capture cache: every node's settings and inputs."""
    if world is None:
        return ()
    items: list = [world.name, tuple(world.color)]
    if world.node_tree is not None:
        for node in world.node_tree.nodes:
            items.append(node.bl_idname)
            items.append(node.name)
            for prop in node.bl_rna.properties:
                ident = prop.identifier
                if prop.is_readonly or ident in _UI_PROPS:
                    continue
                value = getattr(node, ident, None)
                if isinstance(value, bpy.types.ID):
                    value = (value.name, getattr(value, "filepath", ""))
                elif hasattr(value, "__len__") and not isinstance(value, str):
                    value = tuple(value)
                items.append((ident, value))
            # RGB and Value nodes keep their value on their output.
            for sock in (*node.inputs, *node.outputs):
                value = getattr(sock, "default_value", None)
                if hasattr(value, "__len__") and not isinstance(value, str):
                    value = tuple(value)
                items.append((sock.identifier, value, sock.is_linked))
        for link in world.node_tree.links:
            items.append(
                (link.from_node.name, link.from_socket.identifier, link.to_node.name, link.to_socket.identifier)
            )
    return tuple(str(i) for i in items)


_UI_PROPS = {"name", "label", "location", "width", "height", "select", "show_options", "show_preview", "hide"}
_UI_PROPS |= {"mute", "show_texture", "parent", "use_custom_color", "color", "width_hidden", "location_absolute"}
_UI_PROPS |= {"bl_idname", "bl_label", "bl_description", "bl_icon", "warning_propagation", "color_tag"}


def capture_world(scene, width: int = ENV_WIDTH, samples: int = ENV_SAMPLES, world=None) -> np.ndarray:
    """The World's radiance in every direction as an equirectangular image (H = W / 2, RGB, bottom row
    first): Cycles renders the World alone through a panoramic camera in a scratch scene. Cached by the
    World's settings, so a still sky costs nothing after the first call (about a second on 2 cores)."""
    world = world if world is not None else scene.world
    if world is None:
        return skymath.uniform((0.0, 0.0, 0.0))
    key = (fingerprint(world), width, samples)
    hit = _captures.get(key)
    if hit is not None:
        return hit
    env = skyground.capture_ground(scene, world, _stored_render(world, width, max(width // 2, 1), samples))
    if len(_captures) > 16:
        _captures.clear()
    # Under the key it was asked by, and under the World as it is now (the ground may have changed).
    _captures[key] = _captures[(fingerprint(world), width, samples)] = env
    return env


def _stored_render(world, width: int, height: int, samples: int) -> np.ndarray:
    """_render_world, kept in the user's cache between sessions: every headless command (a farm's every
    frame) otherwise renders the same sky again, about a second each time. Keyed by the World's settings
    and Blender's version (its Cycles); Worlds that read an image are rendered each session (the file may
    change under the same name). An unreadable or unwritable cache only costs the render."""
    if any(isinstance(getattr(n, "image", None), bpy.types.Image) for n in getattr(world.node_tree, "nodes", ())):
        return _render_world(world, width, height, samples)
    key = repr((fingerprint(world), width, height, samples, bpy.app.version_string))
    try:
        path = runtime.cache_dir() / "worlds" / f"{hashlib.sha1(key.encode()).hexdigest()}.npy"
    except NubisError:
        return _render_world(world, width, height, samples)
    try:
        env = np.load(path, allow_pickle=False)
        if env.shape == (height, width, 3) and env.dtype == np.float32 and np.isfinite(env).all():
            return env
    except (OSError, ValueError):
        pass
    env = _render_world(world, width, height, samples)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.npy")
    try:
        path.parent.mkdir(exist_ok=True)
        np.save(tmp, env)
        os.replace(tmp, path)
        _evict(path.parent)
    except OSError:
        tmp.unlink(missing_ok=True)
    return env


STORED_MAX = 64  # sky captures kept in the cache (an animated sun makes one per frame), the newest


def _evict(folder: Path) -> None:
    files = sorted(folder.glob("*.npy"), key=lambda p: p.stat().st_mtime_ns, reverse=True)
    for old in files[STORED_MAX:]:
        old.unlink(missing_ok=True)


def clear_stored() -> int:
    """Delete the sky captures kept in the cache (Clear Cache); how many were deleted."""
    folder = runtime.cache_dir() / "worlds"
    count = 0
    for path in folder.glob("*.npy") if folder.is_dir() else ():
        try:
            path.unlink()
            count += 1
        except FileNotFoundError:
            continue
        except OSError as err:
            raise NubisError(
                f"cannot delete the cached sky '{path}' ({err.strerror}): check the folder's permissions"
            ) from None
    return count


def _render_world(world, width: int, height: int, samples: int) -> np.ndarray:
    with gpu_context.camera_scene("Nubis World Capture") as (tmp_scene, cam):
        cam_data = cam.data
        tmp_scene.world = world
        cam_data.type = "PANO"
        if hasattr(cam_data, "panorama_type"):
            cam_data.panorama_type = "EQUIRECTANGULAR"
        else:
            cam_data.cycles.panorama_type = "EQUIRECTANGULAR"
        # Looking along +X with +Z up: the panorama then has the Environment Texture's layout.
        cam.rotation_euler = (math.pi / 2, 0.0, -math.pi / 2)
        r = tmp_scene.render
        r.engine = "CYCLES"
        tmp_scene.cycles.device = "CPU"
        tmp_scene.cycles.samples = samples
        tmp_scene.cycles.use_adaptive_sampling = False
        tmp_scene.cycles.use_denoising = False
        # Each texel the mean over its own area (a box of one pixel): a wider filter, such as Cycles' default
        # 1.5 pixels, blurs the bright horizon into the ground's row below it.
        tmp_scene.cycles.pixel_filter_type = "BOX"
        tmp_scene.cycles.filter_width = 1.0
        r.resolution_x, r.resolution_y, r.resolution_percentage = width, height, 100
        r.film_transparent = False
        r.use_compositing = False
        r.use_sequencer = False
        r.image_settings.file_format = "OPEN_EXR"
        r.image_settings.color_depth = "32"
        r.image_settings.color_mode = "RGB"
        # A private folder: an interrupt ends the process at once and removes it (renamed away first,
        # so the render cannot write anything under its name afterwards: core/interrupt.py).
        with interrupt.temporary_dir("nubis-world-") as tmp:
            path = Path(tmp) / "world.exr"
            r.filepath = str(path)
            _without_nubis_handlers(lambda: bpy.ops.render.render(write_still=True, scene=tmp_scene.name))
            rgba = imageio.read_image(path)
    # read_image gives the top row first; environments are stored bottom row first.
    return np.ascontiguousarray(rgba[::-1, :, :3], dtype=np.float32)


def capturing() -> bool:
    """True on the main thread while a capture renders there: the handlers it runs must leave that render
    alone. A render job of the interface may end on its own thread meanwhile; its handlers see False."""
    return _busy[0] and mainthread.on_main_thread()


def _without_nubis_handlers(fn):
    _busy[0] = True
    try:
        return fn()
    finally:
        _busy[0] = False


def _uniform(colour) -> np.ndarray:
    key = tuple(round(float(c), 7) for c in colour)
    env = _uniforms.get(key)
    if env is None:
        if len(_uniforms) > 64:
            _uniforms.clear()
        env = _uniforms[key] = skymath.uniform(key)
    return env


def flat_colour(world) -> tuple[float, float, float] | None:
    """The radiance of a World that is one colour everywhere (a Background node with an unlinked colour
    feeding the output, or no nodes at all), else None."""
    if world.node_tree is None:
        return tuple(world.color)
    out = next((n for n in world.node_tree.nodes if n.type == "OUTPUT_WORLD" and n.is_active_output), None)
    out = out or next((n for n in world.node_tree.nodes if n.type == "OUTPUT_WORLD"), None)
    if out is None or not out.inputs["Surface"].is_linked:
        return (0.0, 0.0, 0.0) if out is not None else tuple(world.color)
    bg = out.inputs["Surface"].links[0].from_node
    if bg.type != "BACKGROUND" or bg.inputs["Color"].is_linked or bg.inputs["Strength"].is_linked:
        return None
    c, s = bg.inputs["Color"].default_value, bg.inputs["Strength"].default_value
    return (c[0] * s, c[1] * s, c[2] * s)


def environment(scene, wait: bool = True) -> np.ndarray:
    """The environment the clouds are lit by: the World's radiance, or the scene's ambient colour when
    the artist chose one (ambient source: Colour). A World of one colour needs no capture. With `wait`
    False a World whose capture is out of date gives its last capture now and a new one soon after
    (a timer, outside the viewport's draw)."""
    s = scene.nubis
    if s.ambient_source == "COLOR":
        return _uniform(tuple(s.ambient_color))
    world = scene.world
    if world is None:
        return _uniform((0.0, 0.0, 0.0))
    flat = flat_colour(world)
    if flat is not None:
        return _uniform(flat)
    key = (fingerprint(world), ENV_WIDTH, ENV_SAMPLES)
    hit = _captures.get(key)
    if hit is None and not wait:
        _pending.append(scene.name)
        if not bpy.app.timers.is_registered(_capture_pending):
            bpy.app.timers.register(_capture_pending, first_interval=0.1)
        last = _latest.get(world.name)
        return last if last is not None else _uniform(tuple(world.color))
    env = hit if hit is not None else capture_world(scene, ENV_WIDTH)
    _latest[world.name] = env
    return env


_pending: list[str] = []


def _capture_pending():
    names = set(_pending)
    _pending.clear()
    for name in names:
        scene = bpy.data.scenes.get(name)
        if scene is not None and scene.world is not None:
            _latest[scene.world.name] = capture_world(scene, ENV_WIDTH)
    redraw_views()
    return None
