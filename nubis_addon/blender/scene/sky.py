"""The physically based sky: a World made of Blender's own Sky Texture (the model Cycles and EEVEE
render) whose sun follows the Sun lamp, and the World's radiance captured as a small equirectangular
environment for the clouds' sky light and aerial perspective.

Blender 4.5's Sky Texture calls its physical model NISHITA and its aerosols `dust_density`; 5.0 has
SINGLE_SCATTERING and MULTIPLE_SCATTERING and calls them `aerosol_density`. Both are handled here.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator

import bpy
import numpy as np

from ...core import metrics
from ...core import sky as skymath
from ..host import handlers, mainthread
from . import skycapture, skyground

WORLD_NAME = "Nubis Sky"
SKY_NODE = "Nubis Sky Texture"
BACKGROUND_NODE = "Nubis Sky Background"
MARKER = "nubis_sky"  # custom property on a World that Nubis built (and so may keep in step with the sun)


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
    skyground.build_ground(nt, tex, bg, out)
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
    skyground.sync_ground(scene, sun)
    reference, ref_env = _hemisphere_at(scene, tex, REFERENCE_SUN)
    env = skycapture.capture_world(scene, skycapture.ENV_WIDTH)
    above, _below = skymath.hemisphere_radiance(env)
    target = float(metrics.luminance(np.array(cfg["color"], np.float32))) * cfg["strength"]
    have = float(metrics.luminance(np.array(reference, np.float32)))
    strength = float(target / have) if have > 1e-9 else cfg["strength"]
    bg.inputs["Strength"].default_value = strength
    world[FLANK_KEY] = _flank_balance_at_reference(scene, tex, sun, ref_env * np.float32(strength))
    # The sky's light is linear in its strength; the ground's sun term is not (sync_ground).
    skyground.sky_irradiance[world.name] = np.array(above, np.float64) * strength
    skyground.sync_ground(scene, sun)
    lit = (env * np.float32(strength)).astype(np.float32)
    ground = skyground.ground_radiance(scene, sun)
    skycapture.keep(world, skymath.with_ground(lit, ground, skyground.HORIZON_BAND))
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
        env = skycapture.capture_world(scene, skycapture.ENV_WIDTH)
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
    env = skymath.with_ground(env, ground, skyground.HORIZON_BAND)
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
    sun = sun if sun is not None else skyground.find_sun(scene)
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
    return skyground.sync_ground(scene, sun) or changed


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def sky_rotation(azimuth: float) -> float:
    """The Sky Texture's `sun_rotation` for a sun at `azimuth` (atan2(y, x)): the texture measures its
    rotation from +Y clockwise seen from above (measured: tests/test_sky.py renders the sky with a sun
    disc and finds it where the lamp points)."""
    return math.pi / 2.0 - azimuth


# ---- keeping the sky in step with the lamp ---------------------------------------------------------------


@bpy.app.handlers.persistent
def on_update(scene, _depsgraph=None) -> None:
    """Turning the Sun lamp (by hand, by animation) moves the Nubis sky's sun and recolours the lamp. An
    animation rendered from the interface changes frames on its render thread: the frame's render handler
    syncs the sun on the main thread then (blender/f12/scene_render.py)."""
    if skycapture.capturing() or getattr(scene, "nubis", None) is None or not mainthread.on_main_thread():
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
