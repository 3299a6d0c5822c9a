"""The sun through the air in Cycles: what the real-time clouds do per sample (each lit by the sun at its
own altitude, Earth's shadow included; docs/sky.md#the-sun-each-cloud-sees), done per shadow ray when Cycles
renders the bake.

While Nubis renders the bake in Cycles (`compare`, the Cycles reference), the Sun lamp shines with the sun's
light above the atmosphere, and a large sphere around the scene that only shadow rays see (the shell) takes
away what the air takes: its Transparent BSDF's colour is the atmosphere's transmittance towards the sun from
where each shadow ray started. The ray's start is the shell's hit point back along the ray by the ray's
length (Light Path > Ray Length, which Cycles gives shadow rays too); its altitude and the sun's angle over
the planet's curve there index the same table the shaders read (core/sky.py air_table), and the planet's
shadow is told by geometry, as in nubis_air_transmittance. Shadow rays towards anything but the sun (the
World's) pass the shell untouched. Measured on Blender 5.0's Cycles by the issue that asked for it: a shell
seen by shadow rays only costs nothing measurable, where an absorbing volume seen by them costs about 300x.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator

import bpy
import numpy as np

from ...core import sky as skymath
from ..scene import sky, skyground

SHELL_NAME = "Nubis Air Shell"
TABLE_NAME = "Nubis Air Table"
# The shell's radius: every shadow ray Cycles traces from the clouds or the scene starts inside it.
SHELL_RADIUS = 2.0e6
# Shadow rays within this angle of the sun's direction cross the air towards it (the sun's disc is 0.53
# degrees wide; the lamp's angle, if wider, is taken).
_SUN_GATE = math.radians(2.0)


def _table_image(air: tuple[float, float, float]) -> bpy.types.Image:
    """The transmittance table as a float image Cycles reads linearly (non-colour data)."""
    table = skymath.air_table(*air)
    rows, cols = table.shape[:2]
    image = bpy.data.images.get(TABLE_NAME)
    if image is None or tuple(image.size) != (cols, rows):
        if image is not None:
            bpy.data.images.remove(image)
        image = bpy.data.images.new(TABLE_NAME, cols, rows, alpha=True, float_buffer=True)
    image.colorspace_settings.name = "Non-Color"
    image.pixels.foreach_set(np.ascontiguousarray(table, np.float32).ravel())
    image.update()
    return image


class _Nodes:
    """Shorthand for building the shell's arithmetic out of Math and Vector Math nodes."""

    def __init__(self, nt):
        self.nt = nt

    def _link(self, value, socket) -> None:
        if isinstance(value, bpy.types.NodeSocket):
            self.nt.links.new(value, socket)
        else:
            socket.default_value = value

    def math(self, op: str, a, b=0.0):
        node = self.nt.nodes.new("ShaderNodeMath")
        node.operation = op
        self._link(a, node.inputs[0])
        self._link(b, node.inputs[1])
        return node.outputs[0]

    def vector(self, op: str, a, b=None, scale=None):
        node = self.nt.nodes.new("ShaderNodeVectorMath")
        node.operation = op
        self._link(a, node.inputs[0])
        if b is not None:
            self._link(b, node.inputs[1])
        if scale is not None:
            self._link(scale, node.inputs["Scale"])
        return node.outputs["Value" if op in ("DOT_PRODUCT", "LENGTH") else "Vector"]


def _ray_start(n: _Nodes, planet: float):
    """The shadow ray's start relative to the planet's centre (0, 0, -planet) and its direction."""
    geometry = n.nt.nodes.new("ShaderNodeNewGeometry")
    path = n.nt.nodes.new("ShaderNodeLightPath")
    back = n.vector("SCALE", geometry.outputs["Incoming"], scale=path.outputs["Ray Length"])
    start = n.vector("ADD", geometry.outputs["Position"], back)
    centred = n.vector("ADD", start, (0.0, 0.0, planet))
    towards = n.vector("SCALE", geometry.outputs["Incoming"], scale=-1.0)
    return centred, towards


def build_shell_material(air, planet: float, sun_dir, gate_cos: float) -> bpy.types.Material:
    """The shell's material: transparent with the air's transmittance for shadow rays towards the sun."""
    mat = bpy.data.materials.get(SHELL_NAME) or bpy.data.materials.new(SHELL_NAME)
    if mat.node_tree is None:
        mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    n = _Nodes(nt)
    ground, top, span = skymath.EARTH_RADIUS, skymath.ATMOSPHERE_TOP, skymath.AIR_SPAN
    centred, towards = _ray_start(n, planet)
    radius_l = n.vector("LENGTH", centred)
    mu = n.math("DIVIDE", n.vector("DOT_PRODUCT", towards, centred), radius_l)
    h = n.math("MINIMUM", n.math("MAXIMUM", n.math("SUBTRACT", radius_l, planet), 0.0), top - ground)
    r = n.math("ADD", h, ground)
    r2mu2 = n.math("MULTIPLY", n.math("MULTIPLY", r, r), n.math("MULTIPLY", mu, mu))
    rho2 = n.math("MULTIPLY", h, n.math("ADD", r, ground))  # r^2 - R^2
    # The ray meets the ground when mu < 0 and r^2 mu^2 >= r^2 - R^2 (as nubis_air_transmittance).
    below = n.math("LESS_THAN", mu, 0.0)
    meets = n.math("MULTIPLY", below, n.math("GREATER_THAN", n.math("SUBTRACT", r2mu2, rho2), -1e-3))
    rho = n.math("SQRT", n.math("MAXIMUM", rho2, 0.0))
    to_top2 = n.math("MULTIPLY", n.math("SUBTRACT", top, r), n.math("ADD", top, r))  # top^2 - r^2
    to_top = n.math("SQRT", n.math("MAXIMUM", n.math("ADD", r2mu2, to_top2), 0.0))
    d = n.math("MAXIMUM", n.math("SUBTRACT", to_top, n.math("MULTIPLY", r, mu)), 0.0)
    d_min = n.math("SUBTRACT", top, r)
    d_range = n.math("MAXIMUM", n.math("SUBTRACT", n.math("ADD", rho, span), d_min), 1e-3)
    along = n.math("DIVIDE", n.math("SUBTRACT", d, d_min), d_range)
    along = n.math("MINIMUM", n.math("MAXIMUM", along, 0.0), 1.0)
    x = n.math("SUBTRACT", 1.0, n.math("SQRT", n.math("SUBTRACT", 1.0, along)))
    y = n.math("DIVIDE", rho, span)
    coords = nt.nodes.new("ShaderNodeCombineXYZ")
    n._link(x, coords.inputs["X"])
    n._link(y, coords.inputs["Y"])
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = _table_image(air)
    tex.interpolation = "Linear"
    tex.extension = "EXTEND"
    nt.links.new(coords.outputs["Vector"], tex.inputs["Vector"])
    # Towards the sun: the table, nothing in the planet's shadow; any other direction: untouched.
    to_sun = n.math("GREATER_THAN", n.vector("DOT_PRODUCT", towards, tuple(sun_dir)), gate_cos)
    keep = n.math("MULTIPLY", to_sun, n.math("SUBTRACT", 1.0, meets))
    passing = n.math("SUBTRACT", 1.0, to_sun)
    grey = nt.nodes.new("ShaderNodeCombineXYZ")
    for axis in "XYZ":
        n._link(passing, grey.inputs[axis])
    colour = n.vector("ADD", n.vector("SCALE", tex.outputs["Color"], scale=keep), grey.outputs["Vector"])
    bsdf = nt.nodes.new("ShaderNodeBsdfTransparent")
    nt.links.new(colour, bsdf.inputs["Color"])
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    out.target = "CYCLES"
    nt.links.new(bsdf.outputs[0], out.inputs["Surface"])
    for i, node in enumerate(nt.nodes):
        node.location = (220 * (i // 8), -160 * (i % 8))
    return mat


def _shell_mesh(radius: float) -> bpy.types.Mesh:
    """An icosphere of `radius` (5120 faces: its facets sit within 0.2 % of the radius, which matters
    not at all: a ray's start is found from where it met the facet)."""
    import bmesh

    mesh = bpy.data.meshes.new(SHELL_NAME)
    bm = bmesh.new()
    try:
        bmesh.ops.create_icosphere(bm, subdivisions=4, radius=radius)
        bm.to_mesh(mesh)
    finally:
        bm.free()
    return mesh


@contextlib.contextmanager
def above_the_air(scene) -> Iterator[bool]:
    """Around a Cycles render of the bake: when the sky has air (blender/scene/sky.py sun_air) the Sun lamp
    shines with the sun above the atmosphere and the shell gives every shadow ray towards it the air's
    transmittance from where it started; both are put back afterwards, whatever happens. Yields whether
    the air is in."""
    air, lamp = sky.sun_air(scene), skyground.find_sun(scene)
    if air is None or lamp is None:
        yield False
        return
    sun_dir = np.array(lamp.matrix_world.to_3x3().col[2], np.float64)
    sun_dir /= max(float(np.linalg.norm(sun_dir)), 1e-12)
    gate = math.cos(max(_SUN_GATE, float(getattr(lamp.data, "angle", 0.0))))
    centre = scene.camera.matrix_world.translation if scene.camera is not None else (0.0, 0.0, 0.0)
    material = build_shell_material(air, float(scene.nubis.layer_planet_radius), sun_dir, gate)
    mesh = _shell_mesh(SHELL_RADIUS)
    mesh.materials.append(material)
    shell = bpy.data.objects.new(SHELL_NAME, mesh)
    shell.location = (float(centre[0]), float(centre[1]), 0.0)
    for ray in ("camera", "diffuse", "glossy", "transmission", "volume_scatter"):
        setattr(shell, f"visible_{ray}", False)
    scene.collection.objects.link(shell)
    try:
        with sky.lamp_colour_held(lamp, (1.0, 1.0, 1.0)):
            yield True
    finally:
        bpy.data.objects.remove(shell)
        for block, data in ((mesh, bpy.data.meshes), (material, bpy.data.materials)):
            if block.users == 0:
                data.remove(block)
        image = bpy.data.images.get(TABLE_NAME)
        if image is not None and image.users == 0:
            bpy.data.images.remove(image)
