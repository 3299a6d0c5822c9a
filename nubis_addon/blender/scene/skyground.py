"""The ground below a Nubis sky's horizon: its node in the World, its radiance (the Ground albedo lit by
the Sun lamp and by the sky's last capture), kept in step with both, and the Sun lamp the sky and the
clouds follow (find_sun)."""

from __future__ import annotations

import numpy as np

from ...core import sky as skymath


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


sky_irradiance: dict[str, np.ndarray] = {}  # E_sky / pi of each Nubis sky's latest capture, by World name


def build_ground(nt, tex, bg, out) -> None:
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
    return skymath.ground_light(scene.nubis.sky_ground, sky_irradiance.get(world.name, np.zeros(3)), sun_light)


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


def capture_ground(scene, world, env: np.ndarray) -> np.ndarray:
    """After a capture of a Nubis sky: its sky's irradiance sets the ground (the node, when it changed),
    and the capture's lower half is made what the World now shows there (no second render)."""
    if scene is None or world.node_tree is None or world.node_tree.nodes.get(GROUND_NODE) is None:
        return env
    sky_irradiance[world.name] = np.array(skymath.hemisphere_radiance(env)[0])  # E_sky / pi
    colour = ground_radiance(scene, world=world)
    if scene.world == world:
        sync_ground(scene)
    return skymath.with_ground(env, colour, HORIZON_BAND)
