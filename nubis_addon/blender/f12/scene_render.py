"""Final renders with the clouds, in EEVEE and Cycles, with no manual step (F12, `bpy.ops.render.render()`,
`blender -b FILE.blend -f N`), and the `panorama` command.

Before each frame renders (the `render_pre` handler) the clouds are made for that frame with the same
GLSL the viewport draws, and the scene's World is swapped for a copy that shows them:

- camera rays see the clouds rendered from the scene camera at the render's size over the World's
  own sky (a screen-space image, so the scene's objects stand in front of them);
- every other ray (diffuse, glossy, EEVEE's world probe) sees a panorama of the clouds from the camera
  over the World: the clouds light the scene and darken its sky light;
- a horizontal plane just above the scene's objects, invisible to camera and indirect rays, carries
  the clouds' transmittance towards the sun, so the Sun lamp's shadows hold the clouds' shadows and move
  with the wind.

After the frame (`render_post`, `render_cancel`) the artist's World is put back. What this cannot do
is in docs/limits.md.
"""

from __future__ import annotations

import hashlib
import os
import time
import traceback
from pathlib import Path

import bpy
import numpy as np

from ...core import imageio
from ...core import sky as skymath
from ...core.errors import NubisError
from ...core.fsutil import check_output_path
from ...core.staging import output_set
from ...render import engine
from ..host import handlers, mainthread, runtime
from ..jobs import pipeline
from ..scene import cloudstate, cycles_setup, sky, skycapture, vdbclouds
from . import composition, shadows
from .composition import write_image

RENDER_WORLD = "Nubis Render World"
CAMERA_IMAGE = "Nubis Camera Clouds"
PANORAMA_IMAGE = "Nubis Panorama Clouds"
PANORAMA_ALPHA = "Nubis Panorama Alpha"  # the Environment Texture node has no alpha output
ENGINES = ("CYCLES", "BLENDER_EEVEE", "BLENDER_EEVEE_NEXT")

_swapped: dict[str, str] = {}  # scene name -> the World it had before the render
_frames: dict[str, int] = {}  # scene name -> the frames the running render has prepared so far
last_error: list[str] = []
last_seconds: dict[str, float] = {}  # what the last frame's clouds took, part by part (tests/benchmarks/bench_f12.py)


def wants_clouds(scene) -> bool:
    """Whether a render of this scene gets the clouds through the World: a cloudscape with F12 clouds on,
    EEVEE or Cycles, and no baked VDB volume rendering the clouds already."""
    s = getattr(scene, "nubis", None)
    if s is None or s.field_a is None or not s.sky_render_clouds or runtime.own_render_running():
        return False
    if scene.render.engine not in ENGINES or scene.camera is None:
        return False
    vdb = scene.objects.get(cycles_setup.VOLUME_NAME)
    return vdb is None or vdb.hide_render


# ---- the frame's clouds ------------------------------------------------------------------------------


def render_size(scene) -> tuple[int, int]:
    """The frame's size in pixels as Blender makes it: the resolution times the percentage, truncated
    (101 x 57 at 33 % is 33 x 18), so the clouds' image has the frame's pixels exactly."""
    r = scene.render
    pct = r.resolution_percentage
    return max(1, r.resolution_x * pct // 100), max(1, r.resolution_y * pct // 100)


_noted: set[str] = set()


def _note_once(text: str) -> None:
    """A documented fallback, said once per session on the console."""
    if text not in _noted:
        _noted.add(text)
        print(f"Nubis: {text}")


def prepare_frame(scene) -> None:
    """Make this frame's clouds for a render: the camera's view, the panorama, the shadow map and its
    caster. Runs on the main thread (the GPU module's context lives there)."""
    start = time.perf_counter()
    sky.sync_sun(scene)
    pipeline.check_scene(scene)
    w, h = render_size(scene)
    shot = pipeline.viewport_shot(scene, w, h)
    s = scene.nubis
    clouds = runtime.cloud_gpu(s.noise_seed)
    why_not = composition.fallback(scene)
    if why_not:
        _note_once(why_not)
        composition.stow_veil(scene)
        rgba = pipeline.render_shot(shot)  # top row first
    else:
        rgba = composition.split_clouds(scene, shot, clouds)
    write_image(CAMERA_IMAGE, rgba[::-1])
    last_seconds.clear()
    last_seconds["camera view"] = time.perf_counter() - start
    if not why_not:  # its parts: the depth pre-pass, the split march, the veil and the images it fills
        parts = composition.last_frame
        last_seconds.update(depth=parts["depth_s"], march=parts["march_s"], veil=parts["veil_s"])
    t = time.perf_counter()
    state = cloudstate.state_from_scene(scene)
    clouds.update(state)
    eye = cloudstate.camera_eye(scene)
    pw = s.sky_environment_width
    pano = engine.render_panorama(clouds, eye, pw, max(pw // 2, 2))
    write_image(PANORAMA_IMAGE, pano)
    alpha = np.repeat(pano[..., 3:4], 4, axis=-1)
    alpha[..., 3] = 1.0
    write_image(PANORAMA_ALPHA, alpha)
    last_seconds["panorama"] = time.perf_counter() - t
    t = time.perf_counter()
    if s.sky_shadows:
        shadows.update_shadow(scene, state, clouds)
        last_seconds["shadow map"] = time.perf_counter() - t
    else:
        shadows.stow_casters(scene)


# ---- the render World -------------------------------------------------------------------------------


_MADE_FROM = "nubis_made_from"  # the render World's ID property: the fingerprint of the World it was built on


def render_world(base) -> bpy.types.World:
    """A copy of the World `base` (or none) with the clouds composited over it: camera rays see the
    camera's clouds image (window coordinates), other rays the clouds panorama; both are premultiplied, so
    the World's own shader is kept where the clouds let it through and their light is added.

    The previous frame's render World is kept when `base` has not changed since it was built: its images
    are refilled in place, and a new World would make EEVEE compile its shader again, for every frame of
    an animation (minutes each on a software rasterizer)."""
    old = bpy.data.worlds.get(RENDER_WORLD)
    made_from = hashlib.sha1(repr(skycapture.fingerprint(base)).encode()).hexdigest()
    if old is not None and old.get(_MADE_FROM) == made_from and old.node_tree is not None:
        used = {n.image.name for n in old.node_tree.nodes if getattr(n, "image", None) is not None}
        if {CAMERA_IMAGE, PANORAMA_IMAGE, PANORAMA_ALPHA} <= used:
            return old
    world = base.copy() if base is not None else bpy.data.worlds.new(RENDER_WORLD)
    if old is not None:  # the previous frame's (copied first: a file saved mid-render may have it as base)
        bpy.data.worlds.remove(old)
    world.name = RENDER_WORLD
    world[_MADE_FROM] = made_from
    if sky.MARKER in world:
        del world[sky.MARKER]
    if world.node_tree is None:
        world.use_nodes = True
    nt = world.node_tree
    out = next((n for n in nt.nodes if n.type == "OUTPUT_WORLD" and n.is_active_output), None)
    out = out or next((n for n in nt.nodes if n.type == "OUTPUT_WORLD"), None)
    if out is None:
        out = nt.nodes.new("ShaderNodeOutputWorld")
    source = out.inputs["Surface"].links[0].from_socket if out.inputs["Surface"].is_linked else None
    if source is None:  # a World without nodes: its colour
        bg = nt.nodes.new("ShaderNodeBackground")
        bg.inputs["Color"].default_value = (*world.color, 1.0)
        source = bg.outputs[0]
    coords = nt.nodes.new("ShaderNodeTexCoord")
    path = nt.nodes.new("ShaderNodeLightPath")
    cam = nt.nodes.new("ShaderNodeTexImage")
    cam.image = bpy.data.images[CAMERA_IMAGE]
    cam.extension = "EXTEND"
    nt.links.new(coords.outputs["Window"], cam.inputs["Vector"])
    pano = nt.nodes.new("ShaderNodeTexEnvironment")
    pano.image = bpy.data.images[PANORAMA_IMAGE]
    pano_alpha = nt.nodes.new("ShaderNodeTexEnvironment")
    pano_alpha.image = bpy.data.images[PANORAMA_ALPHA]
    colour = _mix_rgb(nt, path.outputs["Is Camera Ray"], pano.outputs["Color"], cam.outputs["Color"])
    alpha = _mix_rgb(nt, path.outputs["Is Camera Ray"], pano_alpha.outputs["Color"], cam.outputs["Alpha"])
    # (1 - alpha) x the World + the clouds' light.
    hidden = nt.nodes.new("ShaderNodeMixShader")
    black = nt.nodes.new("ShaderNodeBackground")
    black.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    nt.links.new(alpha, hidden.inputs["Fac"])
    nt.links.new(source, hidden.inputs[1])
    nt.links.new(black.outputs[0], hidden.inputs[2])
    light = nt.nodes.new("ShaderNodeBackground")
    light.inputs["Strength"].default_value = 1.0
    nt.links.new(colour, light.inputs["Color"])
    add = nt.nodes.new("ShaderNodeAddShader")
    nt.links.new(hidden.outputs[0], add.inputs[0])
    nt.links.new(light.outputs[0], add.inputs[1])
    nt.links.new(add.outputs[0], out.inputs["Surface"])
    return world


def _mix_rgb(nt, fac, a, b):
    """A colour mix node (the Mix node of 3.4+ in RGBA mode): `a` where fac is 0, `b` where it is 1."""
    mix = nt.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    mix.blend_type = "MIX"
    nt.links.new(fac, mix.inputs["Factor"])
    nt.links.new(a, mix.inputs[6])
    nt.links.new(b, mix.inputs[7])
    return mix.outputs[2]


def attach(scene) -> None:
    """Prepare the frame and show the clouds through the render World (until detach). The artist's World
    is remembered once: a frame whose render World is still in place (an animation's next frame, a render
    that ended without render_post) is built on it again, never on the render World."""
    prepare_frame(scene)
    if scene.name not in _swapped:
        _swapped[scene.name] = scene.world.name if scene.world is not None else ""
    name = _swapped[scene.name]
    scene.world = render_world(bpy.data.worlds.get(name) if name else None)
    composition.lend_bounces(scene, shadows.stacked(scene))
    vdbclouds.step_aside(scene)  # the VDB clouds are in the clouds' image: not rendered twice


def detach(scene) -> None:
    """After a frame: give the scene its own World and Cycles settings back (render objects' visibility
    waits for the render's end: finish)."""
    composition.give_back(scene)
    name = _swapped.pop(scene.name, None)
    if name is None:
        return
    scene.world = bpy.data.worlds.get(name) if name else None


def _before_frame(scene) -> None:
    """On the main thread, before a frame renders: the clouds of the frame the render is at, shown through
    the render World; a render without them gets no stale shadow."""
    if not wants_clouds(scene):
        # An earlier frame's shadow must not fall on a render without the clouds (or on the VDB's).
        shadows.stow_casters(scene)
        composition.stow_veil(scene)
        return
    # An animation moves the scene's frame under the main thread's evaluated scene (the camera, the objects,
    # the sun, keyed settings), which follows it here. Its frame number alone cannot tell: a change of the
    # scene during a frame copies the new number into it without evaluating the animation (an object keyed
    # into the clouds at frame 2 stayed where frame 1 had it), so every frame after a render's first is
    # evaluated. The first only when its number differs: frame_set writes the animation over an artist's
    # unkeyed edit, which a still F12 keeps.
    evaluated = bpy.context.evaluated_depsgraph_get().scene_eval
    moved = (evaluated.frame_current, evaluated.frame_subframe) != (scene.frame_current, scene.frame_subframe)
    if moved or _frames.get(scene.name, 0) > 0:
        scene.frame_set(scene.frame_current, subframe=scene.frame_subframe)
    _frames[scene.name] = _frames.get(scene.name, 0) + 1
    attach(scene)


@bpy.app.handlers.persistent
def on_render_pre(scene, _depsgraph=None) -> None:
    """Every frame of every render, on the thread that renders it. In the interface that is a job thread
    without a GPU context: the frame is prepared on the main thread (blender/host/mainthread.py) while the
    render thread waits, before its engine reads the scene."""
    if skycapture.capturing():
        return
    try:
        mainthread.call(lambda: _before_frame(scene))
    except NubisError as err:
        last_error[:] = [str(err)]
        mainthread.report(f"no clouds in the render of frame {scene.frame_current}: {err}")
    except Exception as err:  # noqa: BLE001 - a handler must not fail silently; the artist is told
        traceback.print_exc()
        last_error[:] = [str(err)]
        mainthread.report(
            f"no clouds in the render of frame {scene.frame_current}: internal error "
            f"({type(err).__name__}: {err}); the console has the details"
        )


def begin(scene) -> None:
    """When a render starts (a still or a whole animation), before Blender builds the dependency graph its
    frames share: every object whose render visibility the clouds change is changed now, once, and not
    again until the render ends (docs/sky.md#render-animation): the veil and the shadow casters shown
    (stowed until a frame places them), the VDB clouds stepped aside."""
    _frames[scene.name] = 0
    if not wants_clouds(scene):
        return
    composition.ready(scene)
    shadows.ready_casters(scene)
    vdbclouds.step_aside(scene)


def finish(scene) -> None:
    """When the render has ended, completed, cancelled or failed: the artist's World and settings back,
    Nubis's render objects out of renders and the VDB clouds rendering as the artist left them."""
    _frames.pop(scene.name, None)
    detach(scene)
    composition.put_away_veil(scene)
    shadows.put_away_casters(scene)
    vdbclouds.step_back(scene)


def _on_main_thread(fn, scene) -> None:
    """`fn(scene)` on the main thread when it responds, else here (Blender quitting: the main thread takes
    no work)."""
    if skycapture.capturing():
        return
    try:
        mainthread.call(lambda: fn(scene), timeout=60.0)
    except NubisError:
        fn(scene)


@bpy.app.handlers.persistent
def on_render_init(scene, _depsgraph=None) -> None:
    try:
        _on_main_thread(begin, scene)
    except Exception as err:  # noqa: BLE001 - a handler must not fail silently; the artist is told
        traceback.print_exc()
        mainthread.report(f"the clouds could not prepare the render: {type(err).__name__}: {err}")


@bpy.app.handlers.persistent
def on_render_post(scene, _depsgraph=None) -> None:
    """After a frame: the artist's World back."""
    _on_main_thread(detach, scene)


@bpy.app.handlers.persistent
def on_render_end(scene, _depsgraph=None) -> None:
    """After the render (completed, cancelled by Esc, or failed: a frame that could not be written)."""
    _on_main_thread(finish, scene)


HANDLERS = (
    (bpy.app.handlers.render_init, on_render_init),
    (bpy.app.handlers.render_pre, on_render_pre),
    (bpy.app.handlers.render_post, on_render_post),
    (bpy.app.handlers.render_complete, on_render_end),
    (bpy.app.handlers.render_cancel, on_render_end),
)


def register() -> None:
    mainthread.register()
    handlers.add(HANDLERS)


def unregister() -> None:
    handlers.remove(HANDLERS)
    mainthread.unregister()


# ---- the panorama command --------------------------------------------------------------------------


def panorama(scene, out: str | os.PathLike, width: int) -> Path:
    """An equirectangular HDR of the clouds over the World's sky from the scene camera's position (or the
    origin without a camera), W x W/2, scene-linear RGB in a 32-bit float EXR, written atomically. Its
    layout is Blender's Environment Texture's: set it as a World's environment and it lights a scene
    as the cloudscape would (without the sun's disc: pair it with the Sun lamp)."""
    path = check_output_path(out, (".exr",))
    height = max(width // 2, 2)
    sky.sync_sun(scene)
    pipeline.check_scene(scene)
    state = cloudstate.state_from_scene(scene)
    clouds = runtime.cloud_gpu(scene.nubis.noise_seed)
    clouds.update(state)
    eye = cloudstate.camera_eye(scene) if scene.camera is not None else (0.0, 0.0, 2.0, 1.0)
    rgba = engine.render_panorama(clouds, eye, width, height)  # bottom row first
    # The sky behind the clouds is the World's (the ambient colour, when set, only lights the clouds).
    flat = skycapture.flat_colour(scene.world) if scene.world is not None else (0.0, 0.0, 0.0)
    if flat is not None:
        background = np.broadcast_to(np.asarray(flat, np.float32), (height, width, 3))
    else:
        env = skycapture.capture_world(scene, min(width, skycapture.BACKGROUND_WIDTH * 2), samples=4)
        background = skymath.sample(env, skymath.directions(width, height)).astype(np.float32)
    image = rgba[..., :3] + (1.0 - rgba[..., 3:4]) * background
    with output_set() as outputs:
        imageio.write_image(outputs.stage(path), np.ascontiguousarray(image[::-1], dtype=np.float32))
    return path
