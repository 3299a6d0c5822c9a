"""A path-traced truth for the sun through the air, sharing nothing with what it checks: Cycles renders the
bake with the sun above the atmosphere, and every shadow ray towards the sun carries the transmittance of
the standard atmosphere along its own path, integrated per ray in the shell's own nodes (not the table the
shaders and blender/jobs/sun_air.py read, not core/sky.py's integral: its own constants, its own quadrature).

The atmosphere is Bruneton's (2017): Rayleigh scattering 5.802, 13.558, 33.1 per 1000 km at 680, 550 and
440 nm with a scale height of 8 km; Mie extinction 2e-5 / 0.9 per metre (scattering over its albedo) with
a scale height of 1.2 km; ozone absorbing 0.650, 1.881, 0.085 per 1000 km at its peak, a tent from 10 to 40 km.
Earth's radius 6360 km, the atmosphere's top 60 km above it. Each ray is split at its lowest point (where a
ray towards a sun below the local horizon skims the planet) and each part is sampled more densely towards
that point, where the air is densest.

`installed()` swaps it in for the production shell's material for the length of a block.
"""

from __future__ import annotations

import contextlib
import math

import numpy as np

GROUND = 6360e3
TOP = 6420e3
RAYLEIGH = (5.802e-6, 13.558e-6, 33.1e-6)
RAYLEIGH_HEIGHT = 8000.0
MIE = 2.0e-5 / 0.9
MIE_HEIGHT = 1200.0
OZONE = (0.650e-6, 1.881e-6, 0.085e-6)
OZONE_PEAK, OZONE_HALF_WIDTH = 25e3, 15e3
SAMPLES = 24  # per part of each ray


def _parts(r0, mu):
    """The ray's lowest point's distance and its length to the top (numpy or floats)."""
    lowest = np.maximum(-r0 * mu, 0.0)
    length = -r0 * mu + np.sqrt(np.maximum(r0 * r0 * (mu * mu - 1.0) + TOP * TOP, 0.0))
    return lowest, length


def transmittance(altitude: float, mu: float) -> np.ndarray:
    """The same quadrature in numpy, for checking the nodes and the quadrature's own error."""
    r0 = GROUND + altitude
    lowest, length = _parts(r0, mu)
    u = (np.arange(SAMPLES) + 0.5) / SAMPLES
    t = np.concatenate([lowest - lowest * u * u, lowest + (length - lowest) * u * u])
    dt = np.concatenate([lowest * 2 * u / SAMPLES, (length - lowest) * 2 * u / SAMPLES])
    excess = (r0 - GROUND) * (r0 + GROUND) + t * t + 2.0 * r0 * t * mu
    h = excess / (np.sqrt(excess + GROUND * GROUND) + GROUND)
    sums = [
        np.sum(np.exp(-h / RAYLEIGH_HEIGHT) * dt),
        np.sum(np.exp(-h / MIE_HEIGHT) * dt),
        np.sum(np.maximum(1.0 - np.abs(h - OZONE_PEAK) / OZONE_HALF_WIDTH, 0.0) * dt),
    ]
    tau = np.array(RAYLEIGH) * sums[0] + MIE * sums[1] + np.array(OZONE) * sums[2]
    if mu < 0.0 and r0 * r0 * (mu * mu - 1.0) + GROUND * GROUND >= 0.0:
        return np.zeros(3)
    return np.exp(-tau)


class _Graph:
    def __init__(self, nt):
        self.nt = nt

    def _in(self, value, socket):
        if hasattr(value, "is_output"):
            self.nt.links.new(value, socket)
        else:
            socket.default_value = value

    def op(self, name: str, a, b=0.0):
        node = self.nt.nodes.new("ShaderNodeMath")
        node.operation = name
        self._in(a, node.inputs[0])
        self._in(b, node.inputs[1])
        return node.outputs[0]

    def vec(self, name: str, a, b=None, scale=None):
        node = self.nt.nodes.new("ShaderNodeVectorMath")
        node.operation = name
        self._in(a, node.inputs[0])
        if b is not None:
            self._in(b, node.inputs[1])
        if scale is not None:
            self._in(scale, node.inputs["Scale"])
        return node.outputs["Value" if name in ("DOT_PRODUCT", "LENGTH") else "Vector"]


def _density_sums(g: _Graph, r0, mu, excess0):
    """The three optical-path sums (Rayleigh, Mie, ozone) of the ray, in nodes."""
    lowest = g.op("MAXIMUM", g.op("MULTIPLY", g.op("MULTIPLY", r0, mu), -1.0), 0.0)
    r2mu2 = g.op("MULTIPLY", g.op("MULTIPLY", r0, r0), g.op("MULTIPLY", mu, mu))
    to_top2 = g.op("MULTIPLY", g.op("SUBTRACT", TOP, r0), g.op("ADD", TOP, r0))
    root = g.op("SQRT", g.op("MAXIMUM", g.op("ADD", r2mu2, to_top2), 0.0))
    length = g.op("SUBTRACT", root, g.op("MULTIPLY", r0, mu))
    rest = g.op("SUBTRACT", length, lowest)
    two_r0_mu = g.op("MULTIPLY", g.op("MULTIPLY", r0, mu), 2.0)
    sums = [0.0, 0.0, 0.0]
    for part, span in ((-1.0, lowest), (1.0, rest)):
        for i in range(SAMPLES):
            u = (i + 0.5) / SAMPLES
            t = g.op("ADD", lowest, g.op("MULTIPLY", span, part * u * u))
            dt = g.op("MULTIPLY", span, 2.0 * u / SAMPLES)
            excess = g.op("ADD", excess0, g.op("ADD", g.op("MULTIPLY", t, t), g.op("MULTIPLY", two_r0_mu, t)))
            h = g.op("DIVIDE", excess, g.op("ADD", g.op("SQRT", g.op("ADD", excess, GROUND * GROUND)), GROUND))
            rayleigh = g.op("EXPONENT", g.op("MULTIPLY", h, -1.0 / RAYLEIGH_HEIGHT))
            mie = g.op("EXPONENT", g.op("MULTIPLY", h, -1.0 / MIE_HEIGHT))
            tent = g.op("ABSOLUTE", g.op("SUBTRACT", h, OZONE_PEAK))
            ozone = g.op("MAXIMUM", g.op("SUBTRACT", 1.0, g.op("MULTIPLY", tent, 1.0 / OZONE_HALF_WIDTH)), 0.0)
            for k, density in enumerate((rayleigh, mie, ozone)):
                sums[k] = g.op("ADD", sums[k], g.op("MULTIPLY", density, dt))
    return sums


def build_truth_material(_air, planet: float, sun_dir, gate_cos: float):
    """The truth's shell material (the production builder's signature; the densities are the standard
    atmosphere's, 1, 1, 1)."""
    import bpy

    mat = bpy.data.materials.new("Nubis Air Truth")
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    g = _Graph(nt)
    geometry = nt.nodes.new("ShaderNodeNewGeometry")
    path = nt.nodes.new("ShaderNodeLightPath")
    start = g.vec(
        "ADD",
        geometry.outputs["Position"],
        g.vec("SCALE", geometry.outputs["Incoming"], scale=path.outputs["Ray Length"]),
    )
    centred = g.vec("ADD", start, (0.0, 0.0, planet))
    towards = g.vec("SCALE", geometry.outputs["Incoming"], scale=-1.0)
    radius = g.vec("LENGTH", centred)
    mu = g.op("DIVIDE", g.vec("DOT_PRODUCT", towards, centred), radius)
    height = g.op("MAXIMUM", g.op("SUBTRACT", radius, planet), 0.0)
    r0 = g.op("ADD", height, GROUND)
    excess0 = g.op("MULTIPLY", height, g.op("ADD", r0, GROUND))
    sums = _density_sums(g, r0, mu, excess0)
    channels = []
    for c in range(3):
        tau = g.op("ADD", g.op("MULTIPLY", sums[0], RAYLEIGH[c]), g.op("MULTIPLY", sums[1], MIE))
        tau = g.op("ADD", tau, g.op("MULTIPLY", sums[2], OZONE[c]))
        channels.append(g.op("EXPONENT", g.op("MULTIPLY", tau, -1.0)))
    r2mu2 = g.op("MULTIPLY", g.op("MULTIPLY", r0, r0), g.op("MULTIPLY", mu, mu))
    shadowed = g.op("MULTIPLY", g.op("LESS_THAN", mu, 0.0), g.op("GREATER_THAN", g.op("SUBTRACT", r2mu2, excess0), 0.0))
    to_sun = g.op("GREATER_THAN", g.vec("DOT_PRODUCT", towards, tuple(sun_dir)), gate_cos)
    lit = g.op("MULTIPLY", to_sun, g.op("SUBTRACT", 1.0, shadowed))
    other = g.op("SUBTRACT", 1.0, to_sun)
    colour = nt.nodes.new("ShaderNodeCombineXYZ")
    for c, axis in enumerate("XYZ"):
        g._in(g.op("ADD", g.op("MULTIPLY", channels[c], lit), other), colour.inputs[axis])
    bsdf = nt.nodes.new("ShaderNodeBsdfTransparent")
    nt.links.new(colour.outputs["Vector"], bsdf.inputs["Color"])
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(bsdf.outputs[0], out.inputs["Surface"])
    return mat


@contextlib.contextmanager
def installed():
    """The truth's shell in place of the production one while the block runs."""
    from nubis_addon.blender.jobs import sun_air

    own = sun_air.build_shell_material
    sun_air.build_shell_material = build_truth_material
    try:
        yield
    finally:
        sun_air.build_shell_material = own


def self_check() -> float:
    """The quadrature's largest relative error in the red and green against a 20000-step trapezoid,
    over the cells the benchmark uses (sun 6 to -2 degrees, altitudes 0.5 to 12 km)."""
    worst = 0.0
    for elevation in np.arange(-2.0, 6.01, 0.5):
        for altitude in (500.0, 1500.0, 2500.0, 5000.0, 12000.0):
            mu = math.sin(math.radians(elevation))
            fine = _fine(altitude, mu)
            if fine[1] < 1e-3:
                continue
            got = transmittance(altitude, mu)
            worst = max(worst, float(np.max(np.abs(got[:2] - fine[:2]) / fine[:2])))
    return worst


def _fine(altitude: float, mu: float) -> np.ndarray:
    r0 = GROUND + altitude
    if mu < 0.0 and r0 * r0 * (mu * mu - 1.0) + GROUND * GROUND >= 0.0:
        return np.zeros(3)
    _lowest, length = _parts(r0, mu)
    t = np.linspace(0.0, length, 20001)
    h = np.sqrt(r0 * r0 + t * t + 2.0 * r0 * t * mu) - GROUND
    dens = [
        np.exp(-h / RAYLEIGH_HEIGHT),
        np.exp(-h / MIE_HEIGHT),
        np.maximum(1 - np.abs(h - OZONE_PEAK) / OZONE_HALF_WIDTH, 0),
    ]
    sums = [np.trapezoid(d, t) for d in dens]
    return np.exp(-(np.array(RAYLEIGH) * sums[0] + MIE * sums[1] + np.array(OZONE) * sums[2]))
