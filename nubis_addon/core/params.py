"""The cloud settings, declared once.

This table is the single source of truth for the Scene property group (blender/properties.py), preset
validation (core/presets.py) and the shader's uniform block (render/uniforms.py). A setting's flat
name is ``<section>_<name>``; presets write it as ``[section] name = value``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class Param:
    section: str
    name: str
    kind: str  # "float" | "int" | "bool" | "color" | "enum"
    default: Any
    min: float | None = None
    max: float | None = None
    description: str = ""
    unit: str = "NONE"  # Blender property unit: NONE, LENGTH, ROTATION, TIME
    soft_max: float | None = None
    items: tuple[str, ...] = field(default_factory=tuple)

    @property
    def key(self) -> str:
        return f"{self.section}_{self.name}"


P = Param
PARAMS: tuple[Param, ...] = (
    # SPEC 1.1: low layer 1500-4000 m (S15, GPU Pro 7); S15 draw radius 35 km; planet radius is ours to choose.
    P("layer", "bottom", "float", 1500.0, 0.0, 20000.0, "Altitude of the cloud layer's base above sea level", "LENGTH"),
    P(
        "layer",
        "top",
        "float",
        4000.0,
        100.0,
        30000.0,
        "Altitude of the cloud layer's top (cumulonimbus reach 8 km)",
        "LENGTH",
    ),
    P(
        "layer",
        "planet_radius",
        "float",
        6371000.0,
        10000.0,
        1e8,
        "Planet radius: shrink it to make clouds fall into the horizon sooner (S15)",
        "LENGTH",
    ),
    P(
        "layer",
        "draw_radius",
        "float",
        35000.0,
        1000.0,
        500000.0,
        "Clouds are drawn within this distance of the camera",
        "LENGTH",
    ),
    P("field", "size", "float", 70000.0, 100.0, 1e7, "World-space width of the square data field", "LENGTH"),
    P("field", "origin_x", "float", 0.0, -1e7, 1e7, "Centre of the data field (X)", "LENGTH"),
    P("field", "origin_y", "float", 0.0, -1e7, 1e7, "Centre of the data field (Y)", "LENGTH"),
    P("field", "resolution", "int", 512, 16, 4096, "Pixels per side of the data-field images"),
    P("noise", "seed", "int", 0, 0, 2**31 - 1, "Seed of the 3D noise volumes"),
    P("noise", "lf_period", "float", 12000.0, 100.0, 1e6, "Tile size of the low-frequency shape noise", "LENGTH"),
    P("noise", "hf_period", "float", 1600.0, 10.0, 1e5, "Tile size of the high-frequency detail noise", "LENGTH"),
    P(
        "noise",
        "curl_period",
        "float",
        6000.0,
        10.0,
        1e6,
        "Tile size of the curl noise that swirls cloud bases",
        "LENGTH",
    ),
    P(
        "noise",
        "curl_strength",
        "float",
        250.0,
        0.0,
        10000.0,
        "How far curl noise displaces the detail at cloud bases",
        "LENGTH",
    ),
    # SPEC 1.6.5 / 2.12: one extinction coefficient shared by the viewport and the VDB's Cycles material.
    P(
        "density",
        "sigma",
        "float",
        0.04,
        0.0,
        10.0,
        "Extinction per metre at density 1 (shared with Cycles)",
        soft_max=0.5,
    ),
    P("density", "coverage", "float", 1.0, 0.0, 2.0, "Multiplier on the coverage field"),
    P("density", "erosion", "float", 0.2, 0.0, 1.0, "Strength of the detail erosion (GPU Pro 7: 0.2)"),
    P("density", "multiply_coverage", "bool", True, description="Make small clouds lighter (GPU Pro 7 x coverage)"),
    P("wind", "direction", "float", 0.0, -6.2832, 6.2832, "Wind heading, 0 = towards +X", "ROTATION"),
    P("wind", "speed", "float", 10.0, 0.0, 500.0, "Wind speed in metres per second (GPU Pro 7: 10)"),
    P(
        "wind",
        "top_offset",
        "float",
        500.0,
        -10000.0,
        10000.0,
        "How far cloud tops lean downwind (GPU Pro 7: 500)",
        "LENGTH",
    ),
    P("wind", "upward_bias", "float", 0.1, -1.0, 1.0, "Upward drift relative to the wind (GPU Pro 7: 0.1)"),
    P("wind", "detail_speed", "float", 2.0, 0.0, 20.0, "Detail-noise speed relative to the shape noise"),
    P("wind", "time_offset", "float", 0.0, -1e7, 1e7, "Seconds added to the frame time", "TIME"),
    P("wind", "time_scale", "float", 1.0, 0.0, 1e4, "Simulated seconds per second of animation"),
    # SPEC 2.3: GDC22 eccentricity 0.2; a second lobe for the silver lining.
    P("lighting", "phase_g0", "float", 0.2, -0.99, 0.99, "Eccentricity of the main phase lobe (GDC22: 0.2)"),
    P("lighting", "phase_g1", "float", 0.8, -0.99, 0.99, "Eccentricity of the silver-lining lobe"),
    P("lighting", "phase_mix", "float", 0.2, 0.0, 1.0, "Weight of the silver-lining lobe"),
    P("lighting", "ambient", "float", 1.3, 0.0, 10.0, "Strength of the sky's ambient light"),
    P("lighting", "ambient_bottom", "float", 0.3, 0.0, 1.0, "Ambient at the cloud base relative to the top (S15)"),
    P(
        "lighting",
        "cycles_mie",
        "bool",
        False,
        description="Cycles uses its Mie phase for water droplets instead of the viewport's two HG lobes",
    ),
    P("lighting", "droplet_size", "float", 20.0, 5.0, 50.0, "Droplet diameter for Cycles' Mie phase (micrometres)"),
    P("lighting", "rain_absorption", "float", 3.0, 1.0, 20.0, "Extra light absorption of raining clouds (GPU Pro 7)"),
    # Not from the Guerrilla sources: Wrenninge's multiple-scattering octaves (SPEC 2.9, an extension).
    # Ambient, octave and powder defaults were tuned against Cycles with 8 volume bounces over every
    # preset (tests/pictures/tune_lighting.py, README "Parity with Cycles"); the search put powder at 0,
    # it stays at 0.25 so the sun-facing edges still darken as GPU Pro 7 intends.
    P("lighting", "ms_octaves", "int", 3, 1, 8, "Multiple-scattering octaves (1 = single scattering; not in Nubis)"),
    P("lighting", "ms_attenuation", "float", 0.2, 0.0, 1.0, "Optical-depth scale per octave (Wrenninge a)"),
    P("lighting", "ms_contribution", "float", 0.85, 0.0, 1.0, "Energy per octave (Wrenninge b)"),
    P("lighting", "ms_eccentricity", "float", 0.0, 0.0, 1.0, "Phase eccentricity scale per octave (Wrenninge c)"),
    P("lighting", "powder", "float", 0.25, 0.0, 1.0, "Dark edges with the sun behind you (GPU Pro 7 powder)"),
    P(
        "lighting",
        "fade_distance",
        "float",
        0.0,
        0.0,
        1e7,
        "Distance over which clouds fade into the sky colour (0: off)",
        "LENGTH",
    ),
    # SPEC 1.8: the high 2D layer (GPU Pro 7, GDC22), above the volumetric one.
    P("cirrus", "altitude", "float", 8000.0, 1000.0, 30000.0, "Altitude of the cirrus layer", "LENGTH"),
    P("cirrus", "coverage", "float", 1.0, 0.0, 2.0, "Multiplier on the cirrus coverage field"),
    P("cirrus", "period", "float", 24000.0, 100.0, 1e6, "Tile size of the cirrus texture", "LENGTH"),
    P("cirrus", "opacity", "float", 1.0, 0.0, 20.0, "Optical depth of a fully dense cirrus"),
    P("cirrus", "wind_direction", "float", 0.5, -6.2832, 6.2832, "Cirrus wind heading", "ROTATION"),
    P("cirrus", "wind_speed", "float", 25.0, 0.0, 500.0, "Cirrus wind speed in metres per second"),
    P("cirrus", "thickness", "float", 400.0, 10.0, 5000.0, "Thickness of the cirrus slab in the VDB bake", "LENGTH"),
    # SPEC 1.9.5: the vortex twist at ring boundaries and the height of the internal glow (GDC22).
    P("storm", "twist", "float", 0.6, 0.0, 6.2832, "Twist of the outer rings' noise about the storm centre"),
    P(
        "storm",
        "jittered_rings",
        "bool",
        False,
        description="Cheaper vortex: one noise sample with a jittered ring boundary (GDC22's PS4 path)",
    ),
    P(
        "storm",
        "anvil_shift",
        "float",
        6000.0,
        0.0,
        100000.0,
        "How far the anvil streams downwind at its top",
        "LENGTH",
    ),
    P("storm", "glow_height", "float", 0.3, 0.0, 3.0, "Height of the internal glow, in layer thicknesses"),
    P("march", "steps_min", "int", 64, 8, 1024, "View samples looking straight up (GPU Pro 7: 64)"),
    P("march", "steps_max", "int", 128, 8, 2048, "View samples towards the horizon (GPU Pro 7: 128)"),
    P("march", "light_step", "float", 200.0, 1.0, 5000.0, "Length of a light-march step", "LENGTH"),
    # GDC22's platform table: 6 light samples and noise MIP 1 on PS4, 10 and MIP 0 on PS5.
    P(
        "march",
        "light_samples",
        "int",
        6,
        2,
        16,
        "Light-march samples: a cone towards the sun plus one long-distance sample (GDC22: 6 on PS4, 10 on PS5)",
    ),
    P("march", "mip", "int", 0, 0, 2, "Base mip level of the 3D noise (GDC22: 1 on PS4, 0 on PS5)"),
    # The temporal viewport (docs/viewport.md).
    P(
        "viewport",
        "resolution",
        "float",
        1.0,
        0.25,
        1.0,
        "Resolution of the viewport's converged image relative to the view (GDC22: 1/2 on PS4, 1 on PS5)",
    ),
    P(
        "viewport",
        "blur",
        "float",
        1.0,
        1.0,
        2.0,
        "Width of the upscale filter in pixels of the converged image (GDC22: 2x on PS4, 1x on PS5)",
    ),
    P(
        "viewport",
        "samples",
        "int",
        8,
        1,
        256,
        "Samples per pixel the still viewport converges to (16 redraws each), then it stops redrawing",
    ),
    P("bake", "voxel_size", "float", 100.0, 1.0, 10000.0, "Edge of a voxel in the OpenVDB bake", "LENGTH"),
    # ---- Production VDB export (docs/bake.md): the Bake panel's options, as the command line's flags ----
    P("bake", "camera_only", "bool", False, description="Bake only what the scene camera sees (finer voxels fit)"),
    P("bake", "half", "bool", False, description="Store the grids as half floats (OpenVDB saveFloatAsHalf)"),
    P("bake", "velocity", "bool", False, description="Add a velocity grid from the wind and storms, for motion blur"),
)
del P

PARAMS_BY_KEY: dict[str, Param] = {p.key: p for p in PARAMS}


def defaults() -> dict[str, Any]:
    return {p.key: p.default for p in PARAMS}
