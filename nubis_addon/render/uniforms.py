"""Pack a CloudState into the NubisParams uniform block declared in shaders/nubis_params.glsl.

The layout is read from the GLSL struct itself, so Python and the shaders cannot drift apart.
"""

from __future__ import annotations

import math
import re
from functools import cache

import numpy as np

from ..core import march, storms
from ..core.errors import NubisError
from ..core.state import CloudState, wind_vector
from .sources import read_shader


@cache
def struct_fields() -> tuple[tuple[str, int], ...]:
    """(name, array length or 0) of each NubisParams member, in order."""
    src = read_shader("nubis_params.glsl")
    body = re.search(r"struct\s+NubisParams\s*{(.*?)};", src, re.S)
    if body is None:
        raise RuntimeError("nubis_params.glsl no longer declares struct NubisParams")
    text = re.sub(r"/\*.*?\*/", "", body.group(1), flags=re.S)
    members = re.findall(r"(\w+)\s+(\w+)\s*(?:\[(\d+)\])?\s*;", text)
    bad = [name for typ, name, _n in members if typ != "vec4"]
    if bad:
        raise RuntimeError(f"NubisParams members must be vec4 or vec4 arrays, not: {bad}")
    return tuple((name, int(n) if n else 0) for _typ, name, n in members)


def param_vectors(state: CloudState) -> dict[str, tuple[float, float, float, float]]:
    p = state.params
    shell_lo, shell_hi = state.shell()
    wx, wy = wind_vector(p["wind_direction"])
    cwind = wind_vector(p["cirrus_wind_direction"])
    field_size = p["field_size"]
    return {
        "layer": (p["layer_planet_radius"], p["layer_bottom"], p["layer_top"], p["layer_draw_radius"]),
        "shell": (shell_lo, shell_hi, 0.0, 0.0),
        "field": (p["field_origin_x"], p["field_origin_y"], field_size, 1.0 / field_size),
        "draw": (*state.draw_center, 0.05 * p["layer_draw_radius"], 0.0),
        "noise": (p["noise_lf_period"], p["noise_hf_period"], p["noise_curl_period"], p["noise_curl_strength"]),
        "wind": (wx, wy, p["wind_speed"] * state.time, p["wind_detail_speed"]),
        "wind2": (p["wind_top_offset"], p["wind_upward_bias"], state.time, 0.0),
        "density": (
            p["density_sigma"],
            p["density_coverage"],
            p["density_erosion"],
            1.0 if p["density_multiply_coverage"] else 0.0,
        ),
        "sun_dir": (*_normalized(state.sun_direction), 0.0),
        "sun_rad": (*state.sun_radiance, 0.0),
        "ambient": (*(c * p["lighting_ambient"] for c in state.ambient), p["lighting_ambient_bottom"]),
        "ambient_below": (
            *(c * p["lighting_ambient"] for c in (state.ambient_below or state.ambient)),
            p["lighting_ambient"],
        ),
        "phase": (
            p["lighting_phase_g0"],
            p["lighting_phase_g1"],
            p["lighting_phase_mix"],
            p["lighting_rain_absorption"],
        ),
        "march": (
            float(p["march_steps_min"]),
            float(p["march_steps_max"]),
            p["march_light_step"],
            float(p["march_light_samples"]),
        ),
        "scatter": (
            float(p["lighting_ms_octaves"]),
            p["lighting_ms_attenuation"],
            p["lighting_ms_contribution"],
            p["lighting_ms_eccentricity"],
        ),
        "scatter2": (p["lighting_powder"], p["lighting_fade_distance"], 0.0, 0.0),
        "cirrus": (p["cirrus_altitude"], p["cirrus_coverage"], 1.0 / p["cirrus_period"], p["cirrus_opacity"]),
        "cirrus2": (
            *(c * p["cirrus_wind_speed"] * state.time for c in cwind),
            state.cirrus_slab or p["cirrus_thickness"],
            0.0,
        ),
        "storm_info": (float(len(state.storms)), p["storm_twist"], p["storm_glow_height"], p["storm_anvil_shift"]),
        "storm_shape": [(s.x, s.y, s.radius, s.blend) for s in state.storms],
        "storm_light": [(s.spin, s.darkening, s.glow, s.ambient_boost) for s in state.storms],
        "storm_glow": [(*s.glow_color, s.flash) for s in state.storms],
        "storm_flash": [
            (s.flash_x, s.flash_y, s.flash_ground, _storm_time(_vortex_time(state, s), s.spin)) for s in state.storms
        ],
        # motion_dt is already in simulated seconds (time scale included).
        "motion": (state.motion_dt, p["wind_speed"], 0.0, 0.0),
        "clip_box": state.clip_box or (1.0, 1.0, -1.0, -1.0),
        "options": (
            1.0 if state.jitter else 0.0,
            1.0 if p["storm_jittered_rings"] else 0.0,
            float(state.jitter_pass),
            0.0,
        ),
        "view": (state.pixel_angle, state.pixel_size, float(p["march_mip"]), float(state_max_steps(state))),
        "light_taps": [
            tuple(t) for t in march.light_taps(state.sun_direction, p["march_light_step"], p["march_light_samples"])
        ],
    }


def pack(state: CloudState) -> np.ndarray:
    """The block as float32 rows of four (std140 lays vec4 members and vec4 arrays out densely)."""
    vectors = param_vectors(state)
    fields = struct_fields()
    names = {n for n, _count in fields}
    missing, extra = names - set(vectors), set(vectors) - names
    if missing or extra:
        raise RuntimeError(f"NubisParams and param_vectors disagree: missing {missing}, unknown {extra}")
    rows = []
    for name, count in fields:
        value = vectors[name]
        if count:
            if len(value) > count:
                raise ValueError(f"{name} holds at most {count} entries, got {len(value)}")
            value = list(value) + [(0.0, 0.0, 0.0, 0.0)] * (count - len(value))
            rows.extend(value)
        else:
            rows.append(value)
    data = np.array(rows, dtype=np.float32)
    if not np.all(np.isfinite(data)):
        raise NubisError("non-finite cloud settings: check the scene's Nubis values for NaN or infinity")
    return data


def state_max_steps(state: CloudState) -> int:
    """The view steps this state's march may take within the shader loop limit (core/march.py)."""
    p = state.params
    return march.max_steps(p["march_light_samples"], len(state.storms), state.light_mode == 1)


def _vortex_time(state: CloudState, storm) -> float:
    if storm.vortex_time is not None:
        return storm.vortex_time
    return state.time * float(storms.vortex_fade(storm.blend))


def _storm_time(time: float, spin: float) -> float:
    """Time wrapped (in float64, before float32 upload) to a period after which every ring's angle
    (spin x (6 - ring) / 6 x time) has turned by whole turns, so long animations keep their precision."""
    if abs(spin) < 1e-12:
        return 0.0
    return math.fmod(time, 12.0 * math.pi / abs(spin))


def _normalized(v) -> tuple[float, float, float]:
    a = np.asarray(v, dtype=np.float64)
    n = float(np.linalg.norm(a))
    return tuple(float(x) for x in (a / n if n > 0 else np.array([0.0, 0.0, 1.0])))
