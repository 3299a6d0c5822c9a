"""The physically based sky: a World made of Blender's own Sky Texture (the model Cycles and EEVEE
render) whose sun follows the Sun lamp, and the World's radiance captured as a small equirectangular
environment for the clouds' sky light and aerial perspective.

Blender 4.5's Sky Texture calls its physical model NISHITA and its aerosols `dust_density`; 5.0 has
SINGLE_SCATTERING and MULTIPLE_SCATTERING and calls them `aerosol_density`. Both are handled here.
"""

from __future__ import annotations

import contextlib
import hashlib
import math
import os
from collections.abc import Iterator
from pathlib import Path

import bpy
import numpy as np

from ...core import imageio, interrupt, metrics
from ...core import sky as skymath
from ...core.errors import NubisError
from ...render import gpu_context
from ..host import handlers, mainthread, runtime
from ..host.ui import redraw_views

WORLD_NAME = "Nubis Sky"
SKY_NODE = "Nubis Sky Texture"
BACKGROUND_NODE = "Nubis Sky Background"
MARKER = "nubis_sky"  # custom property on a World that Nubis built (and so may keep in step with the sun)
# The clouds' sky-light environment: fine enough that the bright band just above the horizon is not smeared
# into the ground below it, which would misplace the light the clouds receive from low in the sky
# (docs/measurements.md#sky-capture).
ENV_WIDTH = 128
ENV_SAMPLES = 4  # Cycles samples per pixel of a capture: a sky is smooth
BACKGROUND_WIDTH = 512  # the sky behind the clouds in pictures (render's PNG, panorama)


def sky_type() -> str:
    return "MULTIPLE_SCATTERING" if bpy.app.version >= (5, 0, 0) else "NISHITA"


STRENGTH_KEY = "nubis_sky_strength"
# The flank light's balance at REFERENCE_SUN (core/sky.py flank_balance), kept on the World with its
# calibration so a saved file keeps it.
FLANK_KEY = "nubis_flank_balance"


def atmosphere(world) -> dict:
    """A Nubis sky's preset values: [world] color, strength, air, aerosol, ozone (sky = true)."""
    tex = sky_node(world)
    return {
        "sky": True,
        "color": list(world.color),
        "strength": float(world.get(STRENGTH_KEY, 1.0)),
        "air": float(tex.air_density),
        "aerosol": float(getattr(tex, _aerosol_attr())),
        "ozone": float(tex.ozone_density),
    }


def _aerosol_attr() -> str:
    return "aerosol_density" if bpy.app.version >= (5, 0, 0) else "dust_density"


def is_nubis_sky(world) -> bool:
    return world is not None and bool(world.get(MARKER)) and sky_node(world) is not None


def sky_node(world):
    if world is None or world.node_tree is None:
        return None
    node = world.node_tree.nodes.get(SKY_NODE)
    return node if node is not None and node.bl_idname == "ShaderNodeTexSky" else None


def build_world(scene, cfg: dict, sun) -> bpy.types.World:
    """A new World 'Nubis Sky' holding a Sky Texture, made the scene's World. The World it replaces is
    kept (with a fake user, so saving does not drop it): an artist's sky is never edited or lost.
    `cfg` is the preset's [world] table; its colour x strength sets how bright the sky light is at the
    preset's sun, so presets tuned on a flat sky keep their balance."""
    old = scene.world
    if old is not None and not is_nubis_sky(old):
        old.use_fake_user = True
    world = old if is_nubis_sky(old) else bpy.data.worlds.new(WORLD_NAME)
    world[MARKER] = True
    if world.node_tree is None:
        world.use_nodes = True
    nt = world.node_tree
    nt.nodes.clear()
    tex = nt.nodes.new("ShaderNodeTexSky")
    tex.name = tex.label = SKY_NODE
    tex.sky_type = sky_type()
    # The Sun lamp is the sun: a disc in the sky as well would light Cycles' scene twice.
    tex.sun_disc = False
    tex.air_density = cfg.get("air", 1.0)
    setattr(tex, _aerosol_attr(), cfg.get("aerosol", 1.0))
    tex.ozone_density = cfg.get("ozone", 1.0)
    tex.altitude = 0.0
    bg = nt.nodes.new("ShaderNodeBackground")
    bg.name = bg.label = BACKGROUND_NODE
    out = nt.nodes.new("ShaderNodeOutputWorld")
    nt.links.new(tex.outputs["Color"], bg.inputs["Color"])
    tex.location, bg.location, out.location = (-300, 0), (0, 0), (450, 0)
    _build_ground(nt, tex, bg, out)
    world.color = cfg["color"]
    world[STRENGTH_KEY] = float(cfg["strength"])  # the preset's, before calibration: saving a preset reads it
    scene.world = world
    if bpy.context.view_layer is not None:
        bpy.context.view_layer.update()  # the lamp's matrix_world after a script turned it
    sync_sun(scene, sun, force=True)
    # Calibrate the sky's strength once, with the sun at REFERENCE_SUN: its upper-hemisphere radiance then
    # has the luminance of the preset's flat sky colour there. At any other sun, the preset's own
    # included, the sky is as bright as the atmosphere makes it: a preset set at sunset gets twilight's
    # sky, not a daytime-bright one (docs/sky.md#the-sun-each-cloud-sees).
    bg.inputs["Strength"].default_value = 1.0
    sync_ground(scene, sun)
    reference, ref_env = _hemisphere_at(scene, tex, REFERENCE_SUN)
    env = capture_world(scene, ENV_WIDTH)
    above, _below = skymath.hemisphere_radiance(env)
    target = float(metrics.luminance(np.array(cfg["color"], np.float32))) * cfg["strength"]
    have = float(metrics.luminance(np.array(reference, np.float32)))
    strength = float(target / have) if have > 1e-9 else cfg["strength"]
    bg.inputs["Strength"].default_value = strength
    world[FLANK_KEY] = _flank_balance_at_reference(scene, tex, sun, ref_env * np.float32(strength))
    # The sky's light is linear in its strength; the ground's sun term is not (sync_ground).
    _sky_irradiance[world.name] = np.array(above, np.float64) * strength
    sync_ground(scene, sun)
    _captures[(fingerprint(world), ENV_WIDTH, ENV_SAMPLES)] = skymath.with_ground(
        (env * np.float32(strength)).astype(np.float32), ground_radiance(scene, sun), HORIZON_BAND
    )
    return world


# The sun's elevation at which a preset's [world] colour x strength is the sky's luminance from above.
REFERENCE_SUN = math.radians(30.0)


def _hemisphere_at(scene, tex, elevation: float) -> tuple[tuple, np.ndarray]:
    """The sky's radiance from above (E / pi) with its sun at `elevation`, at the World's strength now,
    and the capture it came from; the sun is put back. The capture is cached like every other
    (capture_world)."""
    own = tex.sun_elevation
    tex.sun_elevation = elevation
    try:
        env = capture_world(scene, ENV_WIDTH)
        above, _below = skymath.hemisphere_radiance(env)
    finally:
        tex.sun_elevation = own
    return above, env


def _flank_balance_at_reference(scene, tex, sun, env: np.ndarray) -> float:
    """core/sky.py flank_balance of the sky at REFERENCE_SUN (`env`: its capture at the calibrated
    strength), the ground below it lit as that sun and that sky would light it."""
    sun_light = None
    if sun is not None and not sun.hide_render:
        air = (tex.altitude, tex.air_density, getattr(tex, _aerosol_attr()), tex.ozone_density)
        sun_light = (skymath.transmittance(REFERENCE_SUN, *air), sun.data.energy, math.sin(REFERENCE_SUN))
    ground = skymath.ground_light(scene.nubis.sky_ground, skymath.hemisphere_radiance(env)[0], sun_light)
    env = skymath.with_ground(env, ground, HORIZON_BAND)
    top, _below = skymath.hemisphere_radiance(env)
    return skymath.flank_balance(top, skymath.flank_radiance(env))


def flank_light(scene, above, flank) -> tuple[float, float, float]:
    """The light through a cloud's flank the clouds take: the environment's own (core/sky.py
    flank_radiance) at the balance a Nubis sky measured at its calibration's sun; a World of any other
    kind (or an ambient colour) keeps the luminance from above and takes the flank's colour."""
    world = scene.world
    balance = None
    if scene.nubis.ambient_source != "COLOR" and is_nubis_sky(world):
        balance = world.get(FLANK_KEY)
    if balance is None:
        balance = skymath.flank_balance(above, flank)
    return tuple(float(c) * float(balance) for c in flank)


def find_sun(scene):
    """The Sun lamp of the clouds and of the sky: the cloudscape's own (Lighting > Sun), else the scene's
    first Sun lamp that renders."""
    settings = getattr(scene, "nubis", None)
    chosen = getattr(settings, "sun", None) if settings is not None else None
    if chosen is not None and chosen.type == "LIGHT" and chosen.data.type == "SUN" and chosen.name in scene.objects:
        return chosen
    for obj in scene.objects:
        if obj.type == "LIGHT" and obj.data.type == "SUN" and not obj.hide_render:
            return obj
    return None


def sun_air(scene) -> tuple[float, float, float] | None:
    """The air the clouds see the sun through (air, aerosol and ozone densities): a Nubis sky's, when it
    sets the Sun lamp's colour (Sun Color on; the lamp then has the ground's transmittance and the clouds
    each their own, docs/sky.md#the-sun-each-cloud-sees). None: the lamp's colour lights every cloud."""
    world = scene.world
    if not is_nubis_sky(world) or not scene.nubis.sky_sun_color:
        return None
    tex = sky_node(world)
    return (float(tex.air_density), float(getattr(tex, _aerosol_attr())), float(tex.ozone_density))


_held: list = []  # lamps whose colour a Cycles render of the bake holds (blender/jobs/sun_air.py)


@contextlib.contextmanager
def lamp_colour_held(lamp, colour) -> Iterator[None]:
    """The lamp in `colour` for the block (the sun above the air while Cycles renders the bake), not
    recoloured by sync_sun meanwhile, and put back after."""
    own = tuple(lamp.data.color)
    lamp.data.color = colour
    _held.append(lamp)
    try:
        yield
    finally:
        _held.remove(lamp)
        lamp.data.color = own


def sync_sun(scene, sun=None, force: bool = False) -> bool:
    """Keep a Nubis sky's sun where the Sun lamp points and the lamp's colour at the atmosphere's
    transmittance for that elevation. Returns whether anything changed. Only Worlds that Nubis built
    are touched; an artist's World is left alone."""
    world = scene.world
    if not is_nubis_sky(world) or _held:  # (the lamp shines from above the air for a Cycles render)
        return False
    sun = sun if sun is not None else find_sun(scene)
    if sun is None:
        return False
    tex = sky_node(world)
    direction = sun.matrix_world.to_3x3().col[2]
    elevation, azimuth = skymath.elevation_azimuth(direction)
    rotation = sky_rotation(azimuth)
    changed = force or abs(tex.sun_elevation - elevation) > 1e-6 or abs(_wrap(tex.sun_rotation - rotation)) > 1e-6
    if changed:
        tex.sun_elevation = elevation
        tex.sun_rotation = rotation % (2.0 * math.pi)
    if scene.nubis.sky_sun_color:
        colour = skymath.transmittance(
            elevation,
            tex.altitude,
            tex.air_density,
            getattr(tex, _aerosol_attr()),
            tex.ozone_density,
        )
        if force or max(abs(a - b) for a, b in zip(sun.data.color, colour, strict=True)) > 1e-5:
            sun.data.color = colour
            changed = True
    return sync_ground(scene, sun) or changed


# ---- the ground below the horizon -----------------------------------------------------------------------
#
# (docs/sky.md#ground) The Sky Texture is black below the horizon, so without a ground every picture had a black
# band and the clouds' light from below was black. The Nubis sky's World shows a diffuse ground instead, lit by
# the sun and the sky: its radiance is albedo x (E_sun sin(elevation) + E_sky) / pi (Lambert), E_sky the sky's
# irradiance on a horizontal plane, integrated exactly over the upper half of each capture of the World. One RGB
# node holds the radiance, so Cycles and EEVEE pay one colour for it. Between the horizon and HORIZON_BAND below
# it the sky's horizon (the texture mirrored at the horizon) fades into the ground: a soft haze, not an edge. The
# ground is not shadowed by the clouds: it stands for the land around the scene, not under a cloud.
GROUND_NODE = "Nubis Ground"
HORIZON_BAND = 0.04  # the sine of the elevation below the horizon where the ground is fully shown
_sky_irradiance: dict[str, np.ndarray] = {}  # E_sky / pi of each Nubis sky's latest capture, by World name


def _build_ground(nt, tex, bg, out) -> None:
    """The ground's nodes (above): the direction's elevation mirrors the sky at the horizon and blends to
    the ground's Background below it."""
    nodes, links = nt.nodes, nt.links
    coord = nodes.new("ShaderNodeTexCoord")
    unit = nodes.new("ShaderNodeVectorMath")
    unit.operation = "NORMALIZE"
    split = nodes.new("ShaderNodeSeparateXYZ")
    up = nodes.new("ShaderNodeMath")
    up.operation = "ABSOLUTE"
    mirrored = nodes.new("ShaderNodeCombineXYZ")
    links.new(coord.outputs["Generated"], unit.inputs[0])
    links.new(unit.outputs["Vector"], split.inputs[0])
    links.new(split.outputs["Z"], up.inputs[0])
    for axis in ("X", "Y"):
        links.new(split.outputs[axis], mirrored.inputs[axis])
    links.new(up.outputs["Value"], mirrored.inputs["Z"])
    links.new(mirrored.outputs["Vector"], tex.inputs["Vector"])
    blend = nodes.new("ShaderNodeMapRange")
    blend.interpolation_type = "SMOOTHSTEP"
    blend.clamp = True
    blend.inputs["From Min"].default_value = 0.0
    blend.inputs["From Max"].default_value = -HORIZON_BAND
    links.new(split.outputs["Z"], blend.inputs["Value"])
    radiance = nodes.new("ShaderNodeRGB")
    radiance.name = radiance.label = GROUND_NODE
    ground = nodes.new("ShaderNodeBackground")
    ground.inputs["Strength"].default_value = 1.0
    links.new(radiance.outputs["Color"], ground.inputs["Color"])
    mix = nodes.new("ShaderNodeMixShader")
    links.new(blend.outputs["Result"], mix.inputs["Fac"])
    links.new(bg.outputs["Background"], mix.inputs[1])
    links.new(ground.outputs["Background"], mix.inputs[2])
    links.new(mix.outputs["Shader"], out.inputs["Surface"])
    placed = {
        coord: (-1300, 200), unit: (-1100, 200), split: (-900, 200), up: (-700, 150), mirrored: (-500, 200),
        blend: (0, 250), radiance: (-200, -250), ground: (0, -200), mix: (250, 0),
    }  # fmt: skip
    for node, where in placed.items():
        node.location = where


def ground_radiance(scene, sun=None, world=None) -> tuple[float, float, float] | None:
    """The ground's radiance for the scene's sun and the World's last captured sky (None: no ground)."""
    world = world if world is not None else scene.world
    if world is None or world.node_tree is None or world.node_tree.nodes.get(GROUND_NODE) is None:
        return None
    sun = sun if sun is not None else find_sun(scene)
    sun_light = None
    if sun is not None and not sun.hide_render:
        sine = max(0.0, float(sun.matrix_world.to_3x3().col[2].normalized().z))
        sun_light = (tuple(sun.data.color), sun.data.energy, sine)
    return skymath.ground_light(scene.nubis.sky_ground, _sky_irradiance.get(world.name, np.zeros(3)), sun_light)


def sync_ground(scene, sun=None) -> bool:
    """Keep the ground's radiance in step with the Sun lamp and the scene's Ground albedo (with the sky
    of the World's last capture; the next capture brings its own sky). A World made before the ground
    existed has none and is left as it is. Returns whether anything changed."""
    colour = ground_radiance(scene, sun)
    if colour is None:
        return False
    socket = scene.world.node_tree.nodes[GROUND_NODE].outputs["Color"]
    if all(abs(a - b) <= 1e-6 * max(1.0, abs(b)) for a, b in zip(socket.default_value[:3], colour, strict=True)):
        return False
    socket.default_value = (*colour, 1.0)
    return True


def _capture_ground(scene, world, env: np.ndarray) -> np.ndarray:
    """After a capture of a Nubis sky: its sky's irradiance sets the ground (the node, when it changed),
    and the capture's lower half is made what the World now shows there (no second render)."""
    if scene is None or world.node_tree is None or world.node_tree.nodes.get(GROUND_NODE) is None:
        return env
    _sky_irradiance[world.name] = np.array(skymath.hemisphere_radiance(env)[0])  # E_sky / pi
    colour = ground_radiance(scene, world=world)
    if scene.world == world:
        sync_ground(scene)
    return skymath.with_ground(env, colour, HORIZON_BAND)


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def sky_rotation(azimuth: float) -> float:
    """The Sky Texture's `sun_rotation` for a sun at `azimuth` (atan2(y, x)): the texture measures its
    rotation from +Y clockwise seen from above (measured: tests/test_sky.py renders the sky with a sun
    disc and finds it where the lamp points)."""
    return math.pi / 2.0 - azimuth


# ---- capturing a World --------------------------------------------------------------------------------

_captures: dict = {}


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
    env = _capture_ground(scene, world, _stored_render(world, width, max(width // 2, 1), samples))
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


_busy = [False]


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


_uniforms: dict[tuple, np.ndarray] = {}
_latest: dict[str, np.ndarray] = {}  # the last capture of each World, for the viewport's draw


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


# ---- keeping the sky in step with the lamp ---------------------------------------------------------------


@bpy.app.handlers.persistent
def on_update(scene, _depsgraph=None) -> None:
    """Turning the Sun lamp (by hand, by animation) moves the Nubis sky's sun and recolours the lamp. An
    animation rendered from the interface changes frames on its render thread: the frame's render handler
    syncs the sun on the main thread then (blender/f12/scene_render.py)."""
    if capturing() or getattr(scene, "nubis", None) is None or not mainthread.on_main_thread():
        return
    sync_sun(scene)


HANDLERS = (
    (bpy.app.handlers.depsgraph_update_post, on_update),
    (bpy.app.handlers.frame_change_post, on_update),
)


def register() -> None:
    handlers.add(HANDLERS)


def unregister() -> None:
    handlers.remove(HANDLERS)
