"""The NubisParams uniform block: its GLSL struct, generated from the settings schema (core/schema.py),
and a CloudState packed into it.

Every setting the schema marks `gpu` is a float member named after its key (`P.lighting_powder`); the
values derived from the scene (sun, time, storms, the view) follow with names of their own. Layout, for
std140 on every backend: vec4 members first, then the floats, padded to whole vec4s, then the vec4
arrays. Integers and switches travel as floats.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache

import numpy as np

from ..core import cloudlayers, lightvolume, march, schema, sky, storms, vdbplacement
from ..core.errors import NubisError
from ..core.state import MAX_STORMS, CloudState, wind_vector


def _volume_row(volume, row: int):
    return lambda st: tuple(float(x) for x in volume(st).to_unit()[row])


def _vdb_atlas(st: CloudState) -> tuple:
    per_side = vdbplacement.gpu_layout(st.vdb_clouds).per_side if st.vdb_clouds else (1, 1, 1)
    return (*map(float, per_side), 0.0)


# Derived vec4 members: (name, what it holds, value).
_VEC4: tuple[tuple[str, str, Callable[[CloudState], tuple]], ...] = (
    ("sun_dir", "unit vector towards the sun, -", lambda st: (*_normalized(st.sun_direction), 0.0)),
    ("sun_radiance", "sun color x strength (irradiance), -", lambda st: (*st.sun_radiance, 0.0)),
    (
        "sun_air",
        "the sun through the air (1: sun_radiance is above the atmosphere), ground and top radii, horizon span",
        lambda st: (float(st.sun_air is not None), sky.EARTH_RADIUS, sky.ATMOSPHERE_TOP, sky.AIR_SPAN),
    ),
    (
        "ambient",
        "ambient sky color x strength x the ambient setting, -",
        lambda st: (*(c * st.params["lighting_ambient"] for c in st.ambient), 0.0),
    ),
    (
        "ambient_below",
        "sky light from below (the ground) x the ambient setting, -",
        lambda st: (*(c * st.params["lighting_ambient"] for c in (st.ambient_below or st.ambient)), 0.0),
    ),
    (
        "ambient_flank",
        "sky and ground light through an upright flank (core/sky.py flank_radiance) x the ambient setting, -",
        lambda st: (*(c * st.params["lighting_ambient"] for c in (st.ambient_flank or st.ambient)), 0.0),
    ),
    *(
        (f"{name}_volume_{axis}", f"unit coordinate {axis} in the {name}'s optical-depth volume: dot(xyz, p) + w", fn)
        for name, volume in (("sun", lightvolume.sun_volume), ("sky", lightvolume.sky_volume))
        for axis, fn in (("x", _volume_row(volume, 0)), ("y", _volume_row(volume, 1)), ("z", _volume_row(volume, 2)))
    ),
    ("vdb_atlas", "the VDB clouds' brick atlas: bricks per side x, y, z, -", _vdb_atlas),
    (
        "clip_box",
        "x0, y0, x1, y1: no clouds outside (a comparison clips to the baked box); x1 < x0: off",
        lambda st: st.clip_box or (1.0, 1.0, -1.0, -1.0),
    ),
)


def _shell(i: int):
    return lambda st: st.shell()[i]


def _wind(i: int):
    return lambda st: wind_vector(st.params["wind_direction"])[i]


def _cirrus_offset(i: int):
    return lambda st: wind_vector(st.params["cirrus_wind_direction"])[i] * st.params["cirrus_wind_speed"] * st.time


# Derived float members: (name, what it holds, value).
_FLOATS: tuple[tuple[str, str, Callable[[CloudState], float]], ...] = (
    ("shell_bottom", "lowest altitude any cloud reaches (the field's min heights)", _shell(0)),
    ("shell_top", "highest altitude any cloud reaches (the field's max heights)", _shell(1)),
    ("field_inv_size", "1 / field size", lambda st: 1.0 / st.params["field_size"]),
    ("sky_side_reach", "how far the sky volume's sideways depths reach (metres)", lightvolume.side_reach),
    ("draw_center_x", "the draw radius' center (the camera), x", lambda st: st.draw_center[0]),
    ("draw_center_y", "the draw radius' center, y", lambda st: st.draw_center[1]),
    ("draw_fade", "fade width at the draw radius", lambda st: 0.05 * st.params["layer_draw_radius"]),
    ("wind_dir_x", "wind direction, x", _wind(0)),
    ("wind_dir_y", "wind direction, y", _wind(1)),
    ("time", "simulated seconds", lambda st: st.time),
    ("cirrus_inv_period", "1 / cirrus texture period", lambda st: 1.0 / st.params["cirrus_period"]),
    ("cirrus_offset_x", "cirrus scroll, x (meters)", _cirrus_offset(0)),
    ("cirrus_offset_y", "cirrus scroll, y (meters)", _cirrus_offset(1)),
    ("cirrus_slab", "cirrus slab thickness of the bake", lambda st: st.cirrus_slab or st.params["cirrus_thickness"]),
    ("storm_count", "number of storms (<= NUBIS_MAX_STORMS)", lambda st: float(len(st.storms))),
    ("motion_dt", "timestep of the motion vectors, simulated seconds", lambda st: st.motion_dt),
    ("jitter", "jitter the march start (0/1)", lambda st: 1.0 if st.jitter else 0.0),
    ("jitter_pass", "accumulation pass", lambda st: float(st.jitter_pass)),
    ("pixel_angle", "pixel footprint: meters per meter of distance", lambda st: st.pixel_angle),
    ("pixel_size", "pixel footprint: meters (orthographic)", lambda st: st.pixel_size),
    (
        "light_cone_reach",
        "the light march's cone reach; the sun's volume gives the rest",
        lambda st: march.CONE_STEPS * st.params["march_light_step"],
    ),
    ("max_view_steps", "most view steps within the shader loop limit", lambda st: float(state_max_steps(st))),
    ("vdb_count", "VDB clouds drawn (<= NUBIS_MAX_VDB)", lambda st: float(len(st.vdb_clouds))),
    ("vdb_step", "the view march's step through the VDB clouds (metres)", lambda st: _vdb_step(st)),
    ("cloud_layer_count", "cloud layers drawn (<= NUBIS_MAX_CLOUD_LAYERS)", lambda st: float(len(st.drawn_layers()))),
)


# The view march's step through a VDB cloud, in its voxels (the finest cloud's).
VDB_STEP_VOXELS = 1.0


def _vdb_step(st: CloudState) -> float:
    return VDB_STEP_VOXELS * min((p.voxel_size for p in st.vdb_clouds), default=1.0)


def _vdb_rows(row: int):
    return lambda st: [tuple(p.world_to_leaf_index[row]) for p in st.vdb_clouds]


def _storm_rows(fn):
    return lambda st: [fn(st, s) for s in st.storms]


# Arrays of vec4: (name, length, what each row holds, rows).
_ARRAYS: tuple[tuple[str, int, str, Callable[[CloudState], list]], ...] = (
    (
        "storm_shape",
        MAX_STORMS,
        "center x, y, radius, blend factor",
        _storm_rows(lambda st, s: (s.x, s.y, s.radius, s.blend)),
    ),
    (
        "storm_light",
        MAX_STORMS,
        "spin (rad/s at the center), darkening, glow intensity, ambient boost",
        _storm_rows(lambda st, s: (s.spin, s.darkening, s.glow, s.ambient_boost)),
    ),
    ("storm_glow", MAX_STORMS, "glow color rgb, flash intensity", _storm_rows(lambda st, s: (*s.glow_color, s.flash))),
    (
        "storm_flash",
        MAX_STORMS,
        "flash offset x, y from the center, ground discharge (0/1), vortex time (wrapped)",
        _storm_rows(lambda st, s: (s.flash_x, s.flash_y, s.flash_ground, _storm_time(_vortex_time(st, s), s.spin))),
    ),
    *(
        (f"vdb_index_{axis}", vdbplacement.MAX_CLOUDS, f"world to the VDB cloud's leaf-relative index {axis}", fn)
        for axis, fn in (("x", _vdb_rows(0)), ("y", _vdb_rows(1)), ("z", _vdb_rows(2)))
    ),
    (
        "vdb_leaves",
        vdbplacement.MAX_CLOUDS,
        "the VDB cloud's index: leaves x, y, z, its first z in the index texture",
        lambda st: [
            (*p.cloud.bricks.index.shape[::-1], z)
            for p, z in zip(st.vdb_clouds, vdbplacement.gpu_layout(st.vdb_clouds).first_slice, strict=True)
        ],
    ),
    (
        "vdb_box_lo",
        vdbplacement.MAX_CLOUDS,
        "the VDB cloud's world box, low corner; density per value (extinction scale / density sigma)",
        lambda st: [(*p.world_box[0], p.extinction_scale / st.params["density_sigma"]) for p in st.vdb_clouds],
    ),
    (
        "vdb_box_hi",
        vdbplacement.MAX_CLOUDS,
        "the VDB cloud's world box, high corner; its first brick in the atlas",
        lambda st: [
            (*p.world_box[1], first)
            for p, first in zip(st.vdb_clouds, vdbplacement.gpu_layout(st.vdb_clouds).first_brick, strict=True)
        ],
    ),
    (
        "light_taps",
        march.MAX_LIGHT_TAPS,
        "the light march's taps (core/march.py): offset, length it stands for",
        lambda st: [
            tuple(t)
            for t in march.light_taps(st.sun_direction, st.params["march_light_step"], st.params["march_light_samples"])
        ],
    ),
)


@cache
def struct_members() -> tuple[tuple[str, str, int], ...]:
    """(name, GLSL type, array length or 0) of each NubisParams member, in order, padding included."""
    vec4 = [(name, "vec4", 0) for name, _doc, _fn in _VEC4]
    floats = [(s.key, "float", 0) for s in schema.gpu_settings()] + [(n, "float", 0) for n, _d, _f in _FLOATS]
    floats += [(f"_pad{i}", "float", 0) for i in range(-len(floats) % 4)]
    arrays = [(name, "vec4", n) for name, n, _doc, _fn in _ARRAYS]
    arrays += [(name, "vec4", cloudlayers.MAX_CLOUD_LAYERS) for name, _fields in _LAYER_ROWS]
    return tuple(vec4 + floats + arrays)


@cache
def struct_source() -> str:
    """The GLSL declaration of NubisParams, each member commented with its label or meaning."""
    docs = {s.key: f"{s.label} ({s.unit.lower()})" if s.unit != "NONE" else s.label for s in schema.gpu_settings()}
    docs.update({n: d for n, d, _f in _VEC4 + _FLOATS})
    docs.update({n: d for n, _c, d, _f in _ARRAYS})
    docs.update({name: _row_doc(fields) for name, fields in _LAYER_ROWS})
    lines = ["/* Generated from core/schema.py by render/uniforms.py: one member per setting, by its key. */"]
    lines.append(f"#define NUBIS_MAX_STORMS {MAX_STORMS}")
    lines.append(f"#define NUBIS_MAX_LIGHT_TAPS {march.MAX_LIGHT_TAPS}")
    lines.append(f"#define NUBIS_MAX_VDB {vdbplacement.MAX_CLOUDS}")
    lines.append(f"#define NUBIS_MAX_CLOUD_LAYERS {cloudlayers.MAX_CLOUD_LAYERS}")

    def size_name(name: str) -> str:
        if name.startswith("vdb_"):
            return "NUBIS_MAX_VDB"
        if name.startswith("cloud_layer_"):
            return "NUBIS_MAX_CLOUD_LAYERS"
        return {"light_taps": "NUBIS_MAX_LIGHT_TAPS"}.get(name, "NUBIS_MAX_STORMS")

    lines.append("struct NubisParams {")
    for name, typ, n in struct_members():
        decl = f"{typ} {name}[{size_name(name)}];" if n else f"{typ} {name};"
        lines.append(f"  {decl:<40} /* {docs.get(name, 'padding to whole vec4s')} */")
    lines.append("};")
    return "\n".join(lines) + "\n" + _layer_struct()


def member_values(state: CloudState) -> dict:
    p = state.params
    out: dict = {s.key: float(p[s.key]) for s in schema.gpu_settings()}
    out.update({name: fn(state) for name, _doc, fn in _VEC4})
    out.update({name: float(fn(state)) for name, _doc, fn in _FLOATS})
    out.update({name: fn(state) for name, _n, _doc, fn in _ARRAYS})
    out.update(layer_rows(state))
    return out


def pack(state: CloudState) -> np.ndarray:
    """The block as float32, laid out as struct_members() declares it (std140)."""
    values = member_values(state)
    flat: list[float] = []
    for name, typ, count in struct_members():
        if name.startswith("_pad"):
            flat.append(0.0)
            continue
        value = values[name]
        if count:
            if len(value) > count:
                raise ValueError(f"{name} holds at most {count} entries, got {len(value)}")
            for row in list(value) + [(0.0, 0.0, 0.0, 0.0)] * (count - len(value)):
                flat.extend(row)
        elif typ == "vec4":
            flat.extend(value)
        else:
            flat.append(value)
    data = np.array(flat, dtype=np.float32).reshape(-1, 4)
    if not np.all(np.isfinite(data)):
        raise NubisError("non-finite cloud settings: check the scene's Nubis values for NaN or infinity")
    return data


def state_max_steps(state: CloudState) -> int:
    """The view steps this state's march may take within the shader loop limit (core/march.py)."""
    p = state.params
    return march.max_steps(p["march_light_samples"], len(state.storms), state.light_mode, len(state.vdb_clouds))


@dataclass(frozen=True)
class LayerField:
    """One field of a cloud layer on the GPU: NubisLayer's member `name` (None: the row's unused rest), its
    GLSL type, what it holds, and its value from a _Layer."""

    name: str | None
    glsl: str  # "float", "vec2" or "vec4": how many of its row's components it takes
    doc: str
    value: Callable[[_Layer], float | tuple]

    @property
    def size(self) -> int:
        return {"float": 1, "vec2": 2, "vec3": 3, "vec4": 4}[self.glsl]


@dataclass(frozen=True)
class _Layer:
    """What a drawn layer's fields are read from: its settings, its altitudes (disjoint_extents), its field,
    the state (the wind's time, the sky's sigma)."""

    p: dict
    lo: float
    hi: float
    field: cloudlayers.LayerField
    state: CloudState


def _setting(key: str) -> Callable[[_Layer], float]:
    return lambda c: float(c.p[key])


def _noise(c: _Layer) -> tuple:
    return tuple(c.p[k] for k in ("noise_lf_period", "noise_hf_period", "noise_curl_period", "noise_curl_strength"))


def _sigma_scale(c: _Layer) -> float:
    return c.p["density_sigma"] / c.state.params["density_sigma"]


def _wind_distance(c: _Layer) -> float:
    return c.p["wind_speed"] * c.state.time


def _settings_rows() -> tuple[tuple[str, tuple[LayerField, ...]], ...]:
    """The rows of the cloud-layer settings flagged with a `layer_member` in the schema, four floats a row
    in the schema's order, the last row's rest unused: a new per-layer float is one line there."""
    fields = [
        LayerField(s.layer_member, "float", f"the setting {s.key} ({s.label})", _setting(s.key))
        for s in schema.CLOUD_LAYER_SETTINGS
        if s.layer_member
    ]
    fields += [LayerField(None, "float", "-", lambda c: 0.0)] * (-len(fields) % 4)
    return tuple((f"cloud_layer_settings{k}", tuple(fields[4 * k : 4 * k + 4])) for k in range(len(fields) // 4))


F = LayerField
# A cloud layer on the GPU: its rows of the uniform block (vec4 arrays, one row a drawn layer,
# NUBIS_MAX_CLOUD_LAYERS rows) and, in each, the fields they hold. The rows, their documentation, NubisLayer,
# its accessors and nubis_layer() (layer_source) are all made from this table. Its first rows are the values
# made from several settings or from the layer's field; the plain floats follow from the schema (their
# `layer_member`, _settings_rows).
_LAYER_ROWS: tuple[tuple[str, tuple[LayerField, ...]], ...] = (
    (
        "cloud_layer_heights",
        (
            F(
                "bottom",
                "float",
                "base altitude (the setting, before the min/max height channels)",
                _setting("layer_bottom"),
            ),
            F("top", "float", "top altitude", _setting("layer_top")),
            F("extent_bottom", "float", "the lowest its clouds reach", lambda c: c.lo),
            F("extent_top", "float", "the highest its clouds reach: a storm's anvil hangs under it", lambda c: c.hi),
        ),
    ),
    (
        "cloud_layer_noise",
        (F("noise", "vec4", "base shape period, detail period, curl period, curl strength", _noise),),
    ),
    (
        "cloud_layer_motion",
        (
            F(
                "sigma_scale",
                "float",
                "its sigma over P.density_sigma, which the light model multiplies by",
                _sigma_scale,
            ),
            F("wind_distance", "float", "wind speed x time", _wind_distance),
            F("wind_dir", "vec2", "the wind's direction", lambda c: tuple(wind_vector(c.p["wind_direction"]))),
        ),
    ),
    (
        "cloud_layer_reach",
        (
            F(
                "reach_channels",
                "vec4",
                "the greatest top type, min height and max height in its field (nubis_layer_reach), -",
                lambda c: c.field.reach_channels(),
            ),
        ),
    ),
    *_settings_rows(),
)
assert all(sum(f.size for f in fields) == 4 for _row, fields in _LAYER_ROWS), "each row fills one vec4"


def layer_fields(state: CloudState) -> list[dict[str, float | tuple]]:
    """Each drawn cloud layer's fields by name (its NubisLayer), in the layers' order."""
    layers = state.drawn_layers()
    out = []
    for layer, (lo, hi) in zip(layers, cloudlayers.disjoint_extents(layers), strict=True):
        c = _Layer(layer.params, lo, hi, layer, state)
        out.append({f.name: f.value(c) for _row, fields in _LAYER_ROWS for f in fields if f.name})
    return out


def layer_rows(state: CloudState) -> dict[str, list[tuple]]:
    """The drawn cloud layers' rows of the block, made once per pack from _LAYER_ROWS."""
    layers = state.drawn_layers()
    rows: dict[str, list[tuple]] = {row: [] for row, _fields in _LAYER_ROWS}
    for layer, (lo, hi) in zip(layers, cloudlayers.disjoint_extents(layers), strict=True):
        c = _Layer(layer.params, lo, hi, layer, state)
        for row, fields in _LAYER_ROWS:
            flat: list[float] = []
            for f in fields:
                v = f.value(c)
                flat.extend(v if isinstance(v, tuple | list) else (v,))
            rows[row].append(tuple(float(x) for x in flat))
    return rows


def _row_doc(fields: tuple[LayerField, ...]) -> str:
    return "a cloud layer's " + ", ".join(f.name or "-" for f in fields for _ in range(1 if f.name else f.size))


@cache
def layer_source() -> str:
    """NubisLayer's accessors and nubis_layer(i), generated from _LAYER_ROWS (in the libraries' place of
    `NUBIS_GENERATED(nubis_layer)`, after the block P they read)."""
    lines = ["/* Generated from _LAYER_ROWS by render/uniforms.py: where each field of layer i lives in P. */"]
    body = ["NubisLayer nubis_layer(int i)", "{", "  NubisLayer L;", "  L.slice = i;"]
    for row, fields in _LAYER_ROWS:
        at = 0
        for f in fields:
            if f.name:
                swizzle = "xyzw"[at : at + f.size]
                lines.append(f"{f.glsl} nubis_layer_{f.name}(int i) {{ return P.{row}[i].{swizzle}; }}")
                body.append(f"  L.{f.name} = nubis_layer_{f.name}(i);")
            at += f.size
    return "\n".join([*lines, "", *body, "  return L;", "}"]) + "\n"


def _layer_struct() -> str:
    lines = [
        "/* One cloud layer of a layered sky (docs/layers.md): its slice of the field textures and its own",
        " * settings, unpacked by nubis_layer(i) (render/uniforms.py: _LAYER_ROWS). */",
        "struct NubisLayer {",
        "  int slice;",
    ]
    for _row, fields in _LAYER_ROWS:
        for f in fields:
            if f.name:
                decl = f"{f.glsl} {f.name};"
                lines.append(f"  {decl:<28} /* {f.doc} */")
    return "\n".join([*lines, "};"]) + "\n"


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
