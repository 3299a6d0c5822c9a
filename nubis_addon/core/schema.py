"""Every setting of a cloudscape, declared once.

Each `Setting` gives its key, type, default, range, unit, label, description, the sidebar panel that
draws it (or why none does), what a change triggers and whether it reaches the GPU. Generated from
this table: the PropertyGroups (blender/sidebar/properties.py), the one preset validator (core/presets.py),
the sidebar panels (blender/sidebar/panels.py), the quality levels' columns (core/quality.py) and the shaders'
uniform block, whose members are named after the keys (render/uniforms.py).

Groups and their keys:
- ``scene``: a scene's cloud settings. The key is ``<section>_<name>`` (``lighting_powder``) and a preset
  writes it as ``[section] name = value``. A few are Blender state only (``in_preset=False``).
- ``layer``: one field layer (``[[field.layers]]``); ``storm``: one superstorm (``[[storms]]``).
- ``sun``, ``world``, ``camera``, ``render``, ``preset``: preset sections that set Blender's own
  objects (the Sun lamp, the World, the camera, the render settings): Blender's own panels draw them.

Labels and descriptions are in Blender's US English. Sources are cited as in docs/sources.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

TAU = 2.0 * math.pi

# Sidebar panels, in the order an artist works (blender/sidebar/panels.py draws them in this order).
PANELS: tuple[tuple[str, str], ...] = (
    ("field", "Data Field"),
    ("altitude", "Altitude"),
    ("shape", "Shape"),
    ("wind", "Wind"),
    ("lighting", "Lighting"),
    ("sky", "Sky and Final Renders"),
    ("cirrus", "Cirrus"),
    ("storms", "Superstorms"),
    ("march", "Ray March"),
    ("viewport", "Viewport"),
    ("bake", "Bake"),
)
PANEL_IDS = tuple(p for p, _label in PANELS)

# What a change triggers (blender/live/events.py): nothing beyond Blender's own redraw, a redraw of the
# clouds, or a re-composite of the data field and then a redraw.
TRIGGERS = ("none", "redraw", "field")


@dataclass(frozen=True)
class Setting:
    group: str
    section: str  # the preset table: "layer", "field", ... for scene settings; the group otherwise
    name: str  # the key inside that table
    kind: str  # float | int | bool | enum | string | vector | color | image | object
    default: Any
    label: str
    description: str
    min: float | None = None
    max: float | None = None
    soft_min: float | None = None
    soft_max: float | None = None
    unit: str = "NONE"  # Blender's: NONE, LENGTH, ROTATION, TIME_ABSOLUTE, VELOCITY
    items: tuple[tuple[str, str, str], ...] = ()  # enum choices: (id as in presets, label, description)
    size: int = 0  # vector and color length
    panel: str = ""  # a PANEL_IDS entry, or "" with `internal` saying why no panel draws it
    internal: str = ""
    trigger: str = "redraw"
    gpu: bool = False  # a member of the shaders' uniform block, named after the key
    in_preset: bool = True  # presets read and write it
    quality: str = ""  # its column in presets/quality/quality.toml, if a quality level sets it
    key_override: str = ""
    object_type: str = ""  # for object settings: the kind of object allowed ("SUN": Sun lamps, "EMPTY")
    # Each cloud layer of a layered sky holds its own value (core/cloudlayers.py); the others are the sky's.
    cloud_layer: bool = False
    # A cloud layer's number on the GPU (a float, int or bool, packed as a float): its member of NubisLayer
    # (render/uniforms.py; "" none).
    layer_member: str = ""

    @property
    def key(self) -> str:
        if self.key_override:
            return self.key_override
        return f"{self.section}_{self.name}" if self.group == "scene" else self.name

    @property
    def choices(self) -> tuple[str, ...]:
        return tuple(i[0] for i in self.items)


def _items(*names: str, **labels: str) -> tuple[tuple[str, str, str], ...]:
    return tuple((n, labels.get(n, n.replace("_", " ").title()), "") for n in names)


def _scene(section: str, name: str, kind: str, default, label: str, description: str, **kw) -> Setting:
    return Setting("scene", section, name, kind, default, label, description, **kw)


_BLENDER_OBJECTS = "set on Blender's own objects and settings, drawn by Blender's own panels"

SCENE: tuple[Setting, ...] = (
    # -- altitude: low layer 1500-4000 m (S15, GPU Pro 7); S15 draws clouds within 35 km. The planet
    #    radius is ours to choose (docs/sources.md#planet-radius).
    _scene(
        "layer",
        "bottom",
        "float",
        1500.0,
        "Base Altitude",
        "Altitude of the cloud layer's base above sea level",
        min=0.0,
        max=20000.0,
        soft_max=10000.0,
        unit="LENGTH",
        panel="altitude",
        gpu=True,
        trigger="field",
        cloud_layer=True,
    ),
    _scene(
        "layer",
        "top",
        "float",
        4000.0,
        "Top Altitude",
        "Altitude of the cloud layer's top (cumulonimbus reach 8 km)",
        min=100.0,
        max=30000.0,
        soft_max=15000.0,
        unit="LENGTH",
        panel="altitude",
        gpu=True,
        trigger="field",
        cloud_layer=True,
    ),
    _scene(
        "layer",
        "planet_radius",
        "float",
        6371000.0,
        "Planet Radius",
        "Planet radius: shrink it to make clouds fall into the horizon sooner (S15)",
        min=10000.0,
        max=1e8,
        soft_min=100000.0,
        soft_max=2e7,
        unit="LENGTH",
        panel="altitude",
        gpu=True,
    ),
    _scene(
        "layer",
        "draw_radius",
        "float",
        35000.0,
        "Draw Distance",
        "Clouds are drawn within this distance of the camera",
        min=1000.0,
        max=500000.0,
        soft_max=150000.0,
        unit="LENGTH",
        panel="altitude",
        gpu=True,
    ),
    # -- the data field
    _scene(
        "field",
        "size",
        "float",
        70000.0,
        "Field Size",
        "World-space width of the square data field",
        min=100.0,
        max=1e7,
        soft_max=500000.0,
        unit="LENGTH",
        panel="field",
        gpu=True,
        trigger="field",
    ),
    _scene(
        "field",
        "origin_x",
        "float",
        0.0,
        "Center X",
        "Center of the data field (X)",
        min=-1e7,
        max=1e7,
        soft_min=-200000.0,
        soft_max=200000.0,
        unit="LENGTH",
        panel="field",
        gpu=True,
        trigger="field",
    ),
    _scene(
        "field",
        "origin_y",
        "float",
        0.0,
        "Center Y",
        "Center of the data field (Y)",
        min=-1e7,
        max=1e7,
        soft_min=-200000.0,
        soft_max=200000.0,
        unit="LENGTH",
        panel="field",
        gpu=True,
        trigger="field",
    ),
    _scene(
        "field",
        "resolution",
        "int",
        512,
        "Resolution",
        "Pixels per side of the data-field images",
        min=16,
        max=4096,
        soft_max=2048,
        panel="field",
        trigger="field",
    ),
    # -- shape: noise and density (GPU Pro 7)
    _scene(
        "noise",
        "seed",
        "int",
        0,
        "Noise Seed",
        "Seed of the 3D noise volumes",
        min=0,
        max=2**31 - 1,
        soft_max=1000,
        panel="shape",
    ),
    _scene(
        "noise",
        "lf_period",
        "float",
        12000.0,
        "Shape Size",
        "Tile size of the low-frequency shape noise",
        min=100.0,
        max=1e6,
        soft_max=50000.0,
        unit="LENGTH",
        panel="shape",
        gpu=True,
        cloud_layer=True,
    ),
    _scene(
        "noise",
        "hf_period",
        "float",
        1600.0,
        "Detail Size",
        "Tile size of the high-frequency detail noise",
        min=10.0,
        max=1e5,
        soft_max=10000.0,
        unit="LENGTH",
        panel="shape",
        cloud_layer=True,
    ),
    _scene(
        "noise",
        "curl_period",
        "float",
        6000.0,
        "Curl Size",
        "Tile size of the curl noise that swirls cloud bases",
        min=10.0,
        max=1e6,
        soft_max=50000.0,
        unit="LENGTH",
        panel="shape",
        cloud_layer=True,
    ),
    _scene(
        "noise",
        "curl_strength",
        "float",
        250.0,
        "Curl Strength",
        "How far curl noise displaces the detail at cloud bases",
        min=0.0,
        max=10000.0,
        soft_max=2000.0,
        unit="LENGTH",
        panel="shape",
        cloud_layer=True,
    ),
    # One extinction coefficient, shared by the viewport and the VDB's Cycles material.
    _scene(
        "density",
        "sigma",
        "float",
        0.04,
        "Extinction",
        "Extinction per meter at density 1 (shared with Cycles)",
        min=0.0,
        max=10.0,
        soft_max=0.5,
        panel="shape",
        gpu=True,
        cloud_layer=True,
    ),
    _scene(
        "density",
        "cover",
        "float",
        0.2834,
        "Coverage",
        "Fraction of the sky the low clouds cover, seen from above: 0 clear, 1 overcast (the multiplier on the "
        "coverage field that gives it is found for the scene's field)",
        min=0.0,
        max=1.0,
        panel="shape",
        trigger="field",
        cloud_layer=True,
    ),
    _scene(
        "density",
        "coverage",
        "float",
        1.0,
        "Coverage Multiplier",
        "Multiplier on the coverage field: found from Coverage for the scene's field when it is composited; "
        "a preset that sets it without `cover` (written before Coverage was a fraction) keeps it and is read "
        "as the fraction it covers",
        min=0.0,
        max=50.0,
        internal="derived from density.cover for the scene's field (core/coverage.py)",
        cloud_layer=True,
        layer_member="coverage",
    ),
    _scene(
        "density",
        "erosion",
        "float",
        0.2,
        "Erosion",
        "Strength of the detail erosion (GPU Pro 7: 0.2)",
        min=0.0,
        max=1.0,
        panel="shape",
        cloud_layer=True,
        layer_member="erosion",
    ),
    _scene(
        "density",
        "multiply_coverage",
        "bool",
        True,
        "Thin Edges",
        "Make small clouds lighter by multiplying the density by the coverage (GPU Pro 7)",
        panel="shape",
        cloud_layer=True,
        layer_member="multiply_coverage",
    ),
    # -- wind (GPU Pro 7: 10 m/s, 500 m top offset, 0.1 upward bias)
    _scene(
        "wind",
        "direction",
        "float",
        0.0,
        "Direction",
        "Wind heading, 0 = towards +X",
        min=-TAU,
        max=TAU,
        unit="ROTATION",
        panel="wind",
        cloud_layer=True,
    ),
    _scene(
        "wind",
        "speed",
        "float",
        10.0,
        "Speed",
        "Wind speed (GPU Pro 7: 10 m/s)",
        min=0.0,
        max=500.0,
        soft_max=60.0,
        unit="VELOCITY",
        panel="wind",
        gpu=True,
        cloud_layer=True,
    ),
    _scene(
        "wind",
        "top_offset",
        "float",
        500.0,
        "Top Offset",
        "How far cloud tops lean downwind (GPU Pro 7: 500 m)",
        min=-10000.0,
        max=10000.0,
        soft_min=-3000.0,
        soft_max=3000.0,
        unit="LENGTH",
        panel="wind",
        cloud_layer=True,
        layer_member="top_offset",
    ),
    _scene(
        "wind",
        "upward_bias",
        "float",
        0.1,
        "Upward Bias",
        "Upward drift relative to the wind (GPU Pro 7: 0.1)",
        min=-1.0,
        max=1.0,
        panel="wind",
        gpu=True,
        cloud_layer=True,
        layer_member="upward_bias",
    ),
    _scene(
        "wind",
        "detail_speed",
        "float",
        2.0,
        "Detail Speed",
        "Detail-noise speed relative to the shape noise",
        min=0.0,
        max=20.0,
        soft_max=5.0,
        panel="wind",
        cloud_layer=True,
        layer_member="detail_speed",
    ),
    _scene(
        "wind",
        "time_offset",
        "float",
        0.0,
        "Time Offset",
        "Seconds added to the frame time",
        min=-1e7,
        max=1e7,
        soft_min=-3600.0,
        soft_max=3600.0,
        unit="TIME_ABSOLUTE",
        panel="wind",
    ),
    _scene(
        "wind",
        "time_scale",
        "float",
        1.0,
        "Time Scale",
        "Simulated seconds per second of animation",
        min=0.0,
        max=1e4,
        soft_max=100.0,
        panel="wind",
    ),
    # -- lighting: GDC22's eccentricity 0.2, a second lobe for the silver lining
    _scene(
        "lighting",
        "phase_g0",
        "float",
        0.2,
        "Forward",
        "Eccentricity of the main phase lobe (GDC22: 0.2)",
        min=-0.99,
        max=0.99,
        panel="lighting",
        gpu=True,
    ),
    _scene(
        "lighting",
        "phase_g1",
        "float",
        0.8,
        "Silver Lining",
        "Eccentricity of the silver-lining lobe",
        min=-0.99,
        max=0.99,
        panel="lighting",
        gpu=True,
    ),
    _scene(
        "lighting",
        "phase_mix",
        "float",
        0.2,
        "Silver Weight",
        "Weight of the silver-lining lobe",
        min=0.0,
        max=1.0,
        panel="lighting",
        gpu=True,
    ),
    _scene(
        "lighting",
        "ambient",
        "float",
        1.30,
        "Ambient",
        "Strength of the sky's ambient light",
        min=0.0,
        max=10.0,
        soft_max=4.0,
        panel="lighting",
        gpu=True,
    ),
    _scene(
        "lighting",
        "ambient_bottom",
        "float",
        1.0,
        "Base Ambient",
        "Ambient light at the cloud base relative to the top (S15's art-directed gradient; 1 leaves the "
        "base to the sky light's own diffusion)",
        min=0.0,
        max=1.0,
        panel="lighting",
        gpu=True,
    ),
    _scene(
        "lighting",
        "sky_occlusion",
        "float",
        2.97,
        "Sky Occlusion",
        "How much the cloud above and below a point dims its sky light: the share of that cloud's optical "
        "depth the light diffuses through (docs/viewport.md#light-model)",
        min=0.0,
        max=4.0,
        panel="lighting",
        gpu=True,
    ),
    _scene(
        "lighting",
        "ms_buildup",
        "float",
        0.81,
        "Build-up",
        "Light scatters many times only inside enough cloud: how fast the optical depth of the point's "
        "column builds up the octaves beyond the first (0: everywhere alike; docs/viewport.md#light-model)",
        min=0.0,
        max=8.0,
        panel="lighting",
        gpu=True,
    ),
    _scene(
        "lighting",
        "diffusion_edge",
        "float",
        0.975,
        "Slab Edge",
        "How far past the cloud's top and base the sky light's diffusion extends (in optical depths times "
        "Sky Occlusion): larger lets more sky light through thin cloud (docs/viewport.md#light-model)",
        min=0.01,
        max=10.0,
        panel="lighting",
        gpu=True,
    ),
    _scene(
        "lighting",
        "side_light",
        "float",
        1.02,
        "Side Light",
        "How much sky light reaches a point sideways, through the cloud beside it rather than above it: "
        "the flanks of towers (0: from above and below only; docs/viewport.md#light-model)",
        min=0.0,
        max=8.0,
        panel="lighting",
        gpu=True,
    ),
    _scene(
        "lighting",
        "cycles_mie",
        "bool",
        False,
        "Cycles Mie",
        "Cycles uses its Mie phase for water droplets instead of the viewport's two Henyey-Greenstein lobes",
        panel="lighting",
        trigger="none",
    ),
    _scene(
        "lighting",
        "droplet_size",
        "float",
        20.0,
        "Droplet Size",
        "Droplet diameter for Cycles' Mie phase, micrometers",
        min=5.0,
        max=50.0,
        panel="lighting",
        trigger="none",
    ),
    _scene(
        "lighting",
        "rain_absorption",
        "float",
        3.0,
        "Rain Dimming",
        "Extra light absorption of raining clouds (GPU Pro 7)",
        min=1.0,
        max=20.0,
        panel="lighting",
        gpu=True,
    ),
    # Not from the Guerrilla sources: Wrenninge et al.'s multiple-scattering octaves. The lighting defaults
    # are fitted against converged Cycles references (docs/viewport.md#fitted-to-converged-cycles).
    _scene(
        "lighting",
        "ms_octaves",
        "int",
        3,
        "Octaves",
        "Multiple-scattering octaves; 1 is single scattering (Wrenninge et al. 2017, not in Nubis)",
        min=1,
        max=8,
        panel="lighting",
        gpu=True,
    ),
    _scene(
        "lighting",
        "ms_attenuation",
        "float",
        0.355,
        "Attenuation",
        "Optical-depth scale per octave (Wrenninge et al.'s a)",
        min=0.0,
        max=1.0,
        panel="lighting",
        gpu=True,
    ),
    _scene(
        "lighting",
        "ms_contribution",
        "float",
        0.753,
        "Contribution",
        "Energy per octave (Wrenninge et al.'s b)",
        min=0.0,
        max=1.0,
        panel="lighting",
        gpu=True,
    ),
    _scene(
        "lighting",
        "ms_eccentricity",
        "float",
        0.0,
        "Eccentricity",
        "Phase eccentricity scale per octave (Wrenninge et al.'s c)",
        min=0.0,
        max=1.0,
        panel="lighting",
        gpu=True,
    ),
    _scene(
        "lighting",
        "powder",
        "float",
        0.25,
        "Powder",
        "Dark edges with the sun behind you (GPU Pro 7's powder effect)",
        min=0.0,
        max=1.0,
        panel="lighting",
        gpu=True,
    ),
    _scene(
        "lighting",
        "fade_distance",
        "float",
        0.0,
        "Fade Distance",
        "Distance over which clouds fade into the sky color (0: off)",
        min=0.0,
        max=1e7,
        soft_max=200000.0,
        unit="LENGTH",
        panel="lighting",
        gpu=True,
    ),
    # -- the high 2D cirrus layer (GPU Pro 7, GDC22), above the volumetric one
    _scene(
        "cirrus",
        "altitude",
        "float",
        8000.0,
        "Altitude",
        "Altitude of the cirrus layer",
        min=1000.0,
        max=30000.0,
        soft_max=15000.0,
        unit="LENGTH",
        panel="cirrus",
        gpu=True,
    ),
    _scene(
        "cirrus",
        "coverage",
        "float",
        1.0,
        "Coverage",
        "Multiplier on the cirrus coverage field",
        min=0.0,
        max=2.0,
        panel="cirrus",
        gpu=True,
    ),
    _scene(
        "cirrus",
        "period",
        "float",
        24000.0,
        "Texture Size",
        "Tile size of the cirrus texture",
        min=100.0,
        max=1e6,
        soft_max=100000.0,
        unit="LENGTH",
        panel="cirrus",
    ),
    _scene(
        "cirrus",
        "opacity",
        "float",
        1.0,
        "Opacity",
        "Optical depth of a fully dense cirrus",
        min=0.0,
        max=20.0,
        soft_max=5.0,
        panel="cirrus",
        gpu=True,
    ),
    _scene(
        "cirrus",
        "wind_direction",
        "float",
        0.5,
        "Wind Angle",
        "Cirrus wind heading",
        min=-TAU,
        max=TAU,
        unit="ROTATION",
        panel="cirrus",
    ),
    _scene(
        "cirrus",
        "wind_speed",
        "float",
        25.0,
        "Wind Speed",
        "Cirrus wind speed",
        min=0.0,
        max=500.0,
        soft_max=100.0,
        unit="VELOCITY",
        panel="cirrus",
    ),
    _scene(
        "cirrus",
        "thickness",
        "float",
        400.0,
        "Thickness",
        "Thickness of the cirrus slab in the VDB bake",
        min=10.0,
        max=5000.0,
        soft_max=2000.0,
        unit="LENGTH",
        panel="cirrus",
    ),
    # -- superstorms (GDC22): the vortex twist at ring boundaries, the anvil and the internal glow
    _scene(
        "storm",
        "twist",
        "float",
        0.6,
        "Vortex Twist",
        "Twist of the outer rings' noise about the storm center",
        min=0.0,
        max=TAU,
        unit="ROTATION",
        panel="storms",
        gpu=True,
    ),
    _scene(
        "storm",
        "jittered_rings",
        "bool",
        False,
        "Ring Jitter",
        "Cheaper vortex: one noise sample with a jittered ring boundary (GDC22's PS4 path)",
        panel="storms",
        gpu=True,
        quality="jittered_rings",
    ),
    _scene(
        "storm",
        "anvil_shift",
        "float",
        6000.0,
        "Anvil Shift",
        "How far the anvil streams downwind at its top",
        min=0.0,
        max=100000.0,
        soft_max=30000.0,
        unit="LENGTH",
        panel="storms",
        gpu=True,
    ),
    _scene(
        "storm",
        "glow_height",
        "float",
        0.3,
        "Glow Height",
        "Height of the internal glow, in layer thicknesses",
        min=0.0,
        max=3.0,
        panel="storms",
        gpu=True,
    ),
    # -- the ray march (GPU Pro 7: 64 view samples looking up, 128 towards the horizon; GDC22's platform
    #    table: 6 light samples and noise mip 1 on PS4, 10 and mip 0 on PS5)
    _scene(
        "march",
        "steps_min",
        "int",
        64,
        "Min Steps",
        "View samples looking straight up (GPU Pro 7: 64)",
        min=8,
        max=1024,
        soft_max=256,
        panel="march",
        gpu=True,
        quality="steps_min",
    ),
    _scene(
        "march",
        "steps_max",
        "int",
        128,
        "Max Steps",
        "View samples towards the horizon (GPU Pro 7: 128)",
        min=8,
        max=2048,
        soft_max=512,
        panel="march",
        gpu=True,
        quality="steps_max",
    ),
    _scene(
        "march",
        "light_step",
        "float",
        200.0,
        "Light Step",
        "Length of a light-march step",
        min=1.0,
        max=5000.0,
        soft_max=1000.0,
        unit="LENGTH",
        panel="march",
    ),
    _scene(
        "march",
        "light_samples",
        "int",
        6,
        "Light Samples",
        "Light-march samples: a cone towards the sun plus one long-distance sample (GDC22: 6 on PS4, 10 on PS5)",
        min=2,
        max=16,
        panel="viewport",
        gpu=True,
        quality="light_samples",
    ),
    _scene(
        "march",
        "mip",
        "int",
        0,
        "Noise Mip",
        "Base mip level of the 3D noise (GDC22: 1 on PS4, 0 on PS5)",
        min=0,
        max=2,
        panel="viewport",
        gpu=True,
        quality="mip",
    ),
    # -- the temporal viewport (docs/viewport.md)
    _scene(
        "viewport",
        "resolution",
        "float",
        1.0,
        "Resolution",
        "Resolution of the viewport's converged image relative to the view (GDC22: 1/2 on PS4, 1 on PS5)",
        min=0.25,
        max=1.0,
        panel="viewport",
        quality="resolution",
    ),
    _scene(
        "viewport",
        "blur",
        "float",
        1.0,
        "Upscale Blur",
        "Width of the upscale filter in pixels of the converged image (GDC22: 2x on PS4, 1x on PS5)",
        min=1.0,
        max=2.0,
        panel="viewport",
        quality="blur",
    ),
    _scene(
        "viewport",
        "samples",
        "int",
        8,
        "Samples",
        "Samples per pixel the still viewport converges to (16 redraws each), then it stops redrawing",
        min=1,
        max=256,
        soft_max=64,
        panel="viewport",
    ),
    _scene(
        "viewport",
        "solid_sky",
        "bool",
        True,
        "Sky in Solid",
        "In Solid shading, draw the World's sky behind the clouds, so they sit in the sky that lights them "
        "(Material Preview and Rendered show the World themselves)",
        panel="viewport",
    ),
    # -- the sky and final renders: a physically based World (Blender's Sky Texture), the clouds in F12
    #    renders through the World (camera background and lighting environment), cloud shadows
    _scene(
        "sky",
        "sun_color",
        "bool",
        True,
        "Sun Color",
        "A Nubis sky sets the Sun lamp's color to the atmosphere's transmittance at its elevation",
        panel="sky",
        trigger="redraw",
    ),
    _scene(
        "sky",
        "ground",
        "color",
        (0.2, 0.19, 0.16),
        "Ground",
        "Albedo of the ground a Nubis sky shows below the horizon, lit by the sun and the sky; it also lights "
        "the clouds from below",
        min=0.0,
        max=1.0,
        size=3,
        panel="sky",
        trigger="redraw",
    ),
    _scene(
        "sky",
        "render_clouds",
        "bool",
        True,
        "In Renders",
        "EEVEE and Cycles renders (F12) show the clouds: behind the scene, as its light and its shadows",
        panel="sky",
        trigger="none",
    ),
    _scene(
        "sky",
        "shadows",
        "bool",
        True,
        "Cloud Shadows",
        "The clouds cast their shadows on the scene's objects in renders",
        panel="sky",
        trigger="none",
    ),
    _scene(
        "sky",
        "shadow_resolution",
        "int",
        512,
        "Shadow Map",
        "Pixels per side of the cloud-shadow map",
        min=16,
        max=4096,
        soft_max=2048,
        panel="sky",
        trigger="none",
    ),
    _scene(
        "sky",
        "shadow_size",
        "float",
        0.0,
        "Shadow Size",
        "Width of the ground the cloud shadows cover (0: the scene's objects, at most 20 km)",
        min=0.0,
        max=1e6,
        soft_max=50000.0,
        unit="LENGTH",
        panel="sky",
        trigger="none",
    ),
    _scene(
        "sky",
        "environment_width",
        "int",
        512,
        "Env Width",
        "Width of the clouds' panorama that lights renders (the height is half)",
        min=16,
        max=8192,
        soft_max=2048,
        panel="sky",
        trigger="none",
    ),
    # -- the bake
    _scene(
        "bake",
        "voxel_size",
        "float",
        100.0,
        "Voxel Size",
        "Edge of a voxel in the OpenVDB bake",
        min=1.0,
        max=10000.0,
        soft_max=500.0,
        unit="LENGTH",
        panel="bake",
        trigger="none",
    ),
    # Production VDB export (docs/bake.md): the Bake panel's options, as the command line's flags.
    _scene(
        "bake",
        "camera_only",
        "bool",
        False,
        "Camera Only",
        "Bake only what the scene camera sees (finer voxels fit)",
        panel="bake",
        trigger="none",
    ),
    _scene(
        "bake",
        "half",
        "bool",
        False,
        "Half Float",
        "Store the grids as half floats (OpenVDB saveFloatAsHalf)",
        panel="bake",
        trigger="none",
    ),
    _scene(
        "bake",
        "velocity",
        "bool",
        False,
        "Velocity",
        "Add a velocity grid from the wind and storms, for motion blur",
        panel="bake",
        trigger="none",
    ),
    # -- the weather rules, applied after the layer stack (GPU Pro 7, S15)
    _scene(
        "rules",
        "rain",
        "bool",
        False,
        "Rain Rule",
        "Where it rains, turn clouds to cumulonimbus covering at least 70% (GPU Pro 7)",
        panel="field",
        trigger="field",
        key_override="rule_rain",
        cloud_layer=True,
    ),
    _scene(
        "rules",
        "horizon",
        "bool",
        False,
        "Horizon Rule",
        "Blend towards cumulus at about 50% coverage far from the camera (S15)",
        panel="field",
        trigger="field",
        key_override="rule_horizon",
        cloud_layer=True,
    ),
    _scene(
        "rules",
        "cumulonimbus_top",
        "float",
        2.6,
        "Storm Top",
        "Max height, in layer thicknesses, of fully raining clouds",
        min=0.0,
        max=8.0,
        panel="field",
        trigger="field",
        key_override="rule_cumulonimbus_top",
        cloud_layer=True,
    ),
    _scene(
        "rules",
        "horizon_start",
        "float",
        15000.0,
        "Horizon Start",
        "Distance from the camera where the horizon rule begins (S15: 15 km)",
        min=0.0,
        max=1e6,
        soft_max=100000.0,
        unit="LENGTH",
        panel="field",
        trigger="field",
        key_override="rule_horizon_start",
        cloud_layer=True,
    ),
    # -- Blender state only, never in a preset
    _scene(
        "",
        "enabled",
        "bool",
        True,
        "Show Clouds",
        "Draw the clouds in the 3D viewport",
        panel="viewport",
        in_preset=False,
        key_override="enabled",
    ),
    _scene(
        "",
        "preset",
        "string",
        "default",
        "Preset",
        "The preset this cloudscape came from",
        internal="a record of where the cloudscape came from, shown in the benchmark",
        in_preset=False,
        trigger="none",
        key_override="preset",
    ),
    _scene(
        "",
        "sun",
        "object",
        None,
        "Sun",
        "The Sun lamp that lights the clouds and the sky: rotate it to change the time of day "
        "(New Cloudscape sets its own)",
        panel="lighting",
        in_preset=False,
        key_override="sun",
        object_type="SUN",
    ),
    _scene(
        "",
        "ambient_source",
        "enum",
        "world",
        "Ambient",
        "Where the clouds' sky light comes from",
        panel="lighting",
        in_preset=False,
        key_override="ambient_source",
        items=(
            ("world", "World", "Sky light from the World's radiance in every direction (an HDRI, a sky, a color)"),
            ("color", "Color", "Sky light from an explicit color"),
        ),
    ),
    _scene(
        "",
        "ambient_color",
        "color",
        (0.3, 0.45, 0.8),
        "Ambient Color",
        "The sky light when Ambient is Color",
        min=0.0,
        soft_max=1.0,
        size=3,
        panel="lighting",
        in_preset=False,
        key_override="ambient_color",
    ),
    _scene(
        "",
        "viewport_quality",
        "string",
        "standard",
        "Quality",
        "The quality level last applied (presets/quality/quality.toml)",
        internal="drawn as the Quality menu of the Viewport panel",
        in_preset=False,
        trigger="none",
        key_override="viewport_quality",
    ),
    _scene(
        "",
        "field_a",
        "image",
        None,
        "Field A",
        "Coverage, precipitation, cloud type, bottom type",
        internal="written by Generate Field",
        in_preset=False,
        key_override="field_a",
    ),
    _scene(
        "",
        "field_b",
        "image",
        None,
        "Field B",
        "Storm coverage, min height, max height, density multiplier",
        internal="written by Generate Field",
        in_preset=False,
        key_override="field_b",
    ),
    _scene(
        "",
        "field_cirrus",
        "image",
        None,
        "Cirrus Field",
        "Cirrus coverage and type",
        internal="written by Generate Field",
        in_preset=False,
        key_override="field_cirrus",
    ),
    _scene(
        "",
        "active_layer",
        "int",
        0,
        "Active Layer",
        "The layer the list has selected",
        internal="the layer list's selection",
        in_preset=False,
        trigger="none",
        key_override="active_layer",
    ),
    _scene(
        "",
        "active_storm",
        "int",
        0,
        "Active Storm",
        "The storm the list has selected",
        internal="the storm list's selection",
        in_preset=False,
        trigger="none",
        key_override="active_storm",
    ),
)

LAYER_KINDS = ("perlin", "worley", "perlin_worley", "gradient", "constant", "image", "paint")
FIELD_CHANNELS = (
    "coverage",
    "precipitation",
    "type",
    "bottom_type",
    "storm",
    "min_height",
    "max_height",
    "density",
    "cirrus_coverage",
    "cirrus_type",
    "none",
)
BLEND_MODES = ("replace", "add", "multiply", "min", "max")
GRADIENT_SHAPES = ("linear", "radial")


def _table(group: str, section: str, rows: list[tuple]) -> tuple[Setting, ...]:
    out = []
    for name, kind, default, label, description, kw in rows:
        out.append(Setting(group, section, name, kind, default, label, description, **kw))
    return tuple(out)


# A field layer's setting: drawn in the Data Field panel, a change re-composites the field.
_LAYER_KW = {"panel": "field", "trigger": "field"}
FIELD_LAYER: tuple[Setting, ...] = _table(
    "layer",
    "field.layers",
    [
        ("name", "string", "", "Name", "The layer's name; masks refer to layers by it", _LAYER_KW),
        (
            "kind",
            "enum",
            "perlin",
            "Kind",
            "What the layer generates",
            {**_LAYER_KW, "items": _items(*LAYER_KINDS, perlin_worley="Perlin-Worley")},
        ),
        (
            "channel",
            "enum",
            "coverage",
            "Channel",
            "The data-field channel the layer writes",
            {**_LAYER_KW, "items": _items(*FIELD_CHANNELS)},
        ),
        (
            "blend",
            "enum",
            "replace",
            "Blend",
            "How the layer combines with the layers above it",
            {**_LAYER_KW, "items": _items(*BLEND_MODES)},
        ),
        ("enabled", "bool", True, "Enabled", "Include the layer in the composite", _LAYER_KW),
        (
            "opacity",
            "float",
            1.0,
            "Opacity",
            "How much of the layer's result is blended in",
            {**_LAYER_KW, "min": 0.0, "max": 1.0},
        ),
        ("mask", "string", "", "Mask", "An earlier layer whose value scales this one's opacity", _LAYER_KW),
        ("invert_mask", "bool", False, "Invert Mask", "Use one minus the mask", _LAYER_KW),
        (
            "scale",
            "float",
            8000.0,
            "Scale",
            "Feature size of the noise",
            {**_LAYER_KW, "min": 1.0, "max": 1e7, "soft_max": 100000.0, "unit": "LENGTH"},
        ),
        ("seed", "int", 0, "Seed", "Seed of the noise", {**_LAYER_KW, "min": 0, "max": 2**31 - 1, "soft_max": 1000}),
        ("octaves", "int", 4, "Octaves", "Octaves of the fractal noise", {**_LAYER_KW, "min": 1, "max": 10}),
        (
            "remap",
            "vector",
            (0.0, 1.0, 0.0, 1.0),
            "Remap",
            "Input low and high, output low and high: the layer's value mapped linearly",
            {**_LAYER_KW, "size": 4},
        ),
        (
            "value",
            "float",
            1.0,
            "Value",
            "The constant layer's value",
            {**_LAYER_KW, "min": -1e6, "max": 1e6, "soft_min": -2.0, "soft_max": 2.0},
        ),
        (
            "gradient",
            "enum",
            "linear",
            "Gradient",
            "Shape of the gradient",
            {**_LAYER_KW, "items": _items(*GRADIENT_SHAPES)},
        ),
        (
            "angle",
            "float",
            0.0,
            "Angle",
            "Direction of a linear gradient, in degrees",
            {**_LAYER_KW, "min": -360.0, "max": 360.0},
        ),
        ("center", "vector", (0.0, 0.0), "Center", "Center of the gradient in meters", {**_LAYER_KW, "size": 2}),
        (
            "radius",
            "float",
            10000.0,
            "Radius",
            "Radius of a radial gradient",
            {**_LAYER_KW, "min": 1.0, "max": 1e7, "soft_max": 200000.0, "unit": "LENGTH"},
        ),
        ("image", "image", "", "Image", "Painted image for image layers", _LAYER_KW),
    ],
)

# A superstorm's settings, drawn in its panel: those of its stencil re-composite the field, those of its
# light and motion only redraw the clouds.
_STORM_FIELD_KW = {"panel": "storms", "trigger": "field"}
_STORM_REDRAW_KW = {"panel": "storms", "trigger": "redraw"}
_POSITION = "the storm's Empty holds its position; move it in the viewport"
_KEYED = "keyframed by Add Lightning"
STORM: tuple[Setting, ...] = _table(
    "storm",
    "storms",
    [
        ("name", "string", "Superstorm", "Name", "The storm's name", {**_STORM_FIELD_KW, "trigger": "none"}),
        (
            "x",
            "float",
            0.0,
            "X",
            "Storm center X",
            {"min": -1e7, "max": 1e7, "internal": _POSITION, "trigger": "field"},
        ),
        (
            "y",
            "float",
            0.0,
            "Y",
            "Storm center Y",
            {"min": -1e7, "max": 1e7, "internal": _POSITION, "trigger": "field"},
        ),
        (
            "radius",
            "float",
            12000.0,
            "Radius",
            "Radius of the storm's stencil",
            {**_STORM_FIELD_KW, "min": 100.0, "max": 1e6, "soft_max": 50000.0, "unit": "LENGTH"},
        ),
        (
            "coverage",
            "float",
            1.0,
            "Coverage",
            "Coverage inside the storm",
            {**_STORM_FIELD_KW, "min": 0.0, "max": 1.0},
        ),
        (
            "blend",
            "float",
            1.0,
            "Blend",
            "Lifecycle blend factor: animate it for the storm to form and dissipate (GDC22)",
            {**_STORM_FIELD_KW, "min": 0.0, "max": 1.0},
        ),
        (
            "height",
            "float",
            3.0,
            "Height",
            "Top of the storm at its center, in layer thicknesses",
            {**_STORM_FIELD_KW, "min": 0.1, "max": 8.0},
        ),
        (
            "base",
            "float",
            -0.1,
            "Base",
            "Height of the storm's flat foot, in layer thicknesses (negative lowers it)",
            {**_STORM_FIELD_KW, "min": -1.0, "max": 1.0},
        ),
        (
            "bottom_type",
            "float",
            0.85,
            "Bottom Type",
            "Raggedness of the underside",
            {**_STORM_FIELD_KW, "min": 0.0, "max": 1.0},
        ),
        (
            "seed",
            "int",
            0,
            "Seed",
            "Seed of the storm's shape noise",
            {**_STORM_FIELD_KW, "min": 0, "max": 2**31 - 1, "soft_max": 1000},
        ),
        (
            "spin",
            "float",
            0.02,
            "Spin",
            "Vortex rotation at the center in radians per second; outer rings turn slower",
            {**_STORM_REDRAW_KW, "min": -10.0, "max": 10.0, "soft_min": -0.2, "soft_max": 0.2},
        ),
        (
            "darkening",
            "float",
            3.0,
            "Darkening",
            "Optical-depth scale of the light reaching the storm's center",
            {**_STORM_REDRAW_KW, "min": 1.0, "max": 50.0, "soft_max": 10.0},
        ),
        (
            "glow",
            "float",
            0.0,
            "Glow",
            "Intensity of the internal glow",
            {**_STORM_REDRAW_KW, "min": 0.0, "max": 1e4, "soft_max": 20.0},
        ),
        (
            "glow_color",
            "color",
            (1.0, 0.08, 0.03),
            "Glow Color",
            "Color of the internal glow",
            {**_STORM_REDRAW_KW, "size": 3, "min": 0.0},
        ),
        (
            "ambient_boost",
            "float",
            1.5,
            "Ambient Boost",
            "Ambient light under the storm relative to the other clouds",
            {**_STORM_REDRAW_KW, "min": 0.0, "max": 20.0, "soft_max": 5.0},
        ),
        (
            "anvil_offset",
            "float",
            12000.0,
            "Anvil Offset",
            "How far downwind the cirrus anvil sits",
            {**_STORM_FIELD_KW, "min": -1e6, "max": 1e6, "soft_min": -50000.0, "soft_max": 50000.0, "unit": "LENGTH"},
        ),
        # Blender state of a storm, keyframed by the operators; never in a preset.
        (
            "empty",
            "object",
            None,
            "Position",
            "An Empty whose location is the storm's center; move it in the viewport",
            {"object_type": "EMPTY", **_STORM_FIELD_KW, "in_preset": False},
        ),
        (
            "flash",
            "float",
            0.0,
            "Flash",
            "Lightning flash intensity; keyframed by Add Lightning",
            {**_STORM_REDRAW_KW, "min": 0.0, "max": 1e6, "soft_max": 500.0, "in_preset": False},
        ),
        (
            "flash_x",
            "float",
            0.0,
            "Flash X",
            "Where the flash is, relative to the storm center",
            {"unit": "LENGTH", "internal": _KEYED, "in_preset": False},
        ),
        (
            "flash_y",
            "float",
            0.0,
            "Flash Y",
            "Where the flash is, relative to the storm center",
            {"unit": "LENGTH", "internal": _KEYED, "in_preset": False},
        ),
        (
            "flash_ground",
            "float",
            0.0,
            "Ground Flash",
            "1 while the flash is a ground discharge (adds the external flash)",
            {"min": 0.0, "max": 1.0, "internal": _KEYED, "in_preset": False},
        ),
    ],
)

_OBJ = {"internal": _BLENDER_OBJECTS, "trigger": "none"}
EXTRA: tuple[Setting, ...] = (
    *_table(
        "preset",
        "preset",
        [
            ("name", "string", "Untitled", "Name", "The preset's name in the New Cloudscape menu", _OBJ),
            ("description", "string", "", "Description", "One sentence on the preset, its tooltip", _OBJ),
        ],
    ),
    *_table(
        "sun",
        "sun",
        [
            ("elevation", "float", 35.0, "Elevation", "Sun elevation in degrees", {**_OBJ, "min": -90.0, "max": 90.0}),
            (
                "azimuth",
                "float",
                135.0,
                "Azimuth",
                "Sun azimuth in degrees from north (+Y) towards east (+X)",
                {**_OBJ, "min": -360.0, "max": 360.0},
            ),
            ("color", "vector", (1.0, 0.96, 0.9), "Color", "The Sun lamp's color", {**_OBJ, "size": 3}),
            ("strength", "float", 4.0, "Strength", "The Sun lamp's strength", {**_OBJ, "min": 0.0, "max": 1e5}),
            (
                "angle",
                "float",
                0.53,
                "Angle",
                "The sun's angular diameter in degrees",
                {**_OBJ, "min": 0.0, "max": 180.0},
            ),
        ],
    ),
    *_table(
        "world",
        "world",
        [
            ("color", "vector", (0.35, 0.5, 0.8), "Color", "The World's background color", {**_OBJ, "size": 3}),
            ("strength", "float", 1.0, "Strength", "The World's background strength", {**_OBJ, "min": 0.0, "max": 1e5}),
            # A physically based World (Blender's Sky Texture) whose sky light has the luminance of color x
            # strength at the preset's sun; false keeps the flat color. Air, aerosol and ozone are multiples
            # of the standard atmosphere (the Sky Texture's densities).
            ("sky", "bool", True, "Physical Sky", "Build the World from Blender's Sky Texture", _OBJ),
            ("air", "float", 1.0, "Air", "Air density, in standard atmospheres", {**_OBJ, "min": 0.0, "max": 10.0}),
            (
                "aerosol",
                "float",
                1.0,
                "Aerosol",
                "Aerosol density, in standard atmospheres",
                {**_OBJ, "min": 0.0, "max": 10.0},
            ),
            (
                "ozone",
                "float",
                1.0,
                "Ozone",
                "Ozone density, in standard atmospheres",
                {**_OBJ, "min": 0.0, "max": 10.0},
            ),
        ],
    ),
    *_table(
        "camera",
        "camera",
        [
            ("location", "vector", (0.0, 0.0, 2.0), "Location", "Camera location in meters", {**_OBJ, "size": 3}),
            (
                "rotation",
                "vector",
                (80.0, 0.0, 0.0),
                "Rotation",
                "Camera XYZ Euler rotation in degrees",
                {**_OBJ, "size": 3},
            ),
            ("lens", "float", 24.0, "Focal Length", "Focal length in millimeters", {**_OBJ, "min": 1.0, "max": 5000.0}),
            (
                "clip_end",
                "float",
                200000.0,
                "Clip End",
                "Camera far clip distance in meters",
                {**_OBJ, "min": 10.0, "max": 1e8},
            ),
        ],
    ),
    *_table(
        "render",
        "render",
        [
            ("width", "int", 640, "Width", "Render width in pixels", {**_OBJ, "min": 4, "max": 16384}),
            ("height", "int", 360, "Height", "Render height in pixels", {**_OBJ, "min": 4, "max": 16384}),
            ("samples", "int", 64, "Samples", "Cycles samples", {**_OBJ, "min": 1, "max": 65536}),
            ("volume_bounces", "int", 8, "Volume Bounces", "Cycles volume bounces", {**_OBJ, "min": 0, "max": 1024}),
            (
                "view_transform",
                "enum",
                "AgX",
                "View Transform",
                "The scene's view transform",
                {**_OBJ, "items": tuple((v, v, "") for v in ("AgX", "Standard", "Filmic", "Khronos PBR Neutral"))},
            ),
            ("frame", "int", 1, "Frame", "The current frame", {**_OBJ, "min": -1048574, "max": 1048574}),
        ],
    ),
)

ALL: tuple[Setting, ...] = SCENE + FIELD_LAYER + STORM + EXTRA
BY_KEY: dict[str, Setting] = {s.key: s for s in SCENE}
PRESET_SCENE: tuple[Setting, ...] = tuple(s for s in SCENE if s.in_preset)
EXTRA_SECTIONS: dict[str, dict[str, Setting]] = {}
for _s in EXTRA:
    EXTRA_SECTIONS.setdefault(_s.section, {})[_s.name] = _s
FIELD_LAYER_BY_NAME: dict[str, Setting] = {s.name: s for s in FIELD_LAYER}
# The settings each cloud layer holds its own value of (their `cloud_layer` flag): its altitudes, noise
# periods, density, wind and weather rules. Every other scene setting is the sky's, shared by its layers.
CLOUD_LAYER_SETTINGS: tuple[Setting, ...] = tuple(s for s in SCENE if s.cloud_layer)
CLOUD_LAYER_KEYS: tuple[str, ...] = tuple(s.key for s in CLOUD_LAYER_SETTINGS)
STORM_BY_NAME: dict[str, Setting] = {s.name: s for s in STORM}
QUALITY_COLUMNS: dict[str, str] = {s.quality: s.key for s in SCENE if s.quality}


def defaults() -> dict[str, Any]:
    """The scene settings a preset holds, at their defaults, by key (vectors as lists, as TOML reads them)."""
    return {s.key: list(s.default) if isinstance(s.default, tuple) else s.default for s in PRESET_SCENE}


def table_defaults(settings) -> dict[str, Any]:
    """One [[field.layers]] or [[storms]] entry (or a preset section) at its defaults; lists are fresh."""
    return {s.name: list(s.default) if isinstance(s.default, tuple) else s.default for s in settings if s.in_preset}


def gpu_settings() -> tuple[Setting, ...]:
    return tuple(s for s in SCENE if s.gpu)


def check_schema() -> None:
    """The table's own consistency (a test calls it): unique keys, known panels and triggers, a panel or a
    reason for every setting, defaults inside their ranges and among their choices."""
    for group in (SCENE, FIELD_LAYER, STORM):
        keys = [s.key for s in group]
        dupes = {k for k in keys if keys.count(k) > 1}
        assert not dupes, f"duplicate keys {dupes}"
    for s in ALL:
        where = f"{s.group}.{s.key}"
        assert (s.panel in PANEL_IDS) != bool(s.internal), f"{where}: needs exactly one of a panel or a reason"
        assert s.trigger in TRIGGERS, where
        assert s.label and s.description, f"{where}: needs a label and a description"
        if s.kind in ("float", "int") and s.min is not None and s.max is not None:
            assert s.min <= s.default <= s.max, f"{where}: default outside its range"
        if s.kind == "enum":
            assert s.default in s.choices, where
        if s.kind in ("vector", "color"):
            assert s.size == len(s.default), where
        assert "colour" not in (s.label + s.description).lower(), f"{where}: US English"


@dataclass(frozen=True)
class CrossLimit:
    """A limit between two settings, enforced by the preset loader and by the sidebar (which moves the
    other setting along when one is dragged past it)."""

    low: str  # the key that must stay below
    high: str  # the key that must stay above
    gap: float  # the least difference
    message: str

    def holds(self, values: dict[str, Any]) -> bool:
        return values[self.high] - values[self.low] >= self.gap

    def stated(self, values: dict[str, Any], places: dict[str, str]) -> str:
        """The two values as they are, every digit shown (5000.000000001 is not 5000), each named by its
        place in `places` (a preset's "layer.top")."""
        return ", ".join(f"{places.get(k, k)} {values[k]!r}" for k in (self.high, self.low))


def cross_limit(low: str, high: str) -> CrossLimit:
    return next(rule for rule in CROSS_LIMITS if (rule.low, rule.high) == (low, high))


CROSS_LIMITS: tuple[CrossLimit, ...] = (
    CrossLimit("layer_bottom", "layer_top", 1e-3, "layer.top must be above layer.bottom"),
    CrossLimit("march_steps_min", "march_steps_max", 0, "march.steps_max must be at least march.steps_min"),
)
