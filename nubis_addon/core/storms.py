"""Superstorm stencils of the Nubis Data Field generator (GDC22): rasterise each storm's
mesocyclone into the tropospheric field images ("a", "b") and its anvil into the cirrus image.

A storm is defined by "Position, Radius and blend factor" (GDC22); the blend factor is animated over
the storm's lifecycle (:func:`lifecycle_keys`). Pure numpy: no bpy, no gpu.
The renderer's share of the storm (vortex rotation, flipped profile, darkening, glow) lives in the
shaders and reads the storm coverage channel written here. Where GDC22 gives no shape or number, the
choices are in docs/sources.md#superstorms.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import astuple, dataclass
from typing import Any

import numpy as np

from . import schema
from .fields import pixel_centres
from .noise import world_fbm_2d

# Width of the stencil's outer fade, as a fraction of the radius: the modelling is fully on inside
# (1 - EDGE_WIDTH) x radius and fades out with zero slope at the radius (docs/sources.md#storm-stencil).
EDGE_WIDTH = 0.4
ANVIL_EDGE_WIDTH = 0.3
# Shape constants of the mesocyclone, in fractions of the radius, not given by GDC22
# (docs/sources.md#mesocyclone-shape).
COLUMN_RADIUS = (0.18, 0.42)  # coverage column: fully covered inside .18, gone by .42 (noisy radius)
TOWER_RADIUS = (0.12, 0.5)  # the raised max height spreads a little wider than the coverage column
FOOT_RADIUS = (0.55, 0.95)  # the flat, spread-out foot (the sombrero's brim)
ANVIL_COVERAGE = 0.95
ANVIL_TYPE = (0.75, 0.35)  # billowy above the storm, wispy at the downwind tail (0 cirrostratus, 1 cirrocumulus)


_D = {s.name: s.default for s in schema.STORM}


@dataclass
class Storm:
    """One superstorm stencil (GDC22). Heights are fractions of the layer thickness above the layer
    bottom, like the field's min/max height channels (docs/sources.md#storm-heights)."""

    x: float  # world centre, metres
    y: float
    radius: float  # metres
    # Defaults are the settings schema's (core/schema.py): one value for presets, the sidebar and here.
    coverage: float = _D["coverage"]  # peak cloud coverage at the centre
    blend: float = _D["blend"]  # lifecycle blend factor (GDC22 animates it: 0 = no storm)
    height: float = _D["height"]  # max height at the centre: 3.0 raises a 1.5-4 km layer's top to ~9 km
    base: float = _D["base"]  # min height at the foot: < 0 lowers the flat foot below the layer bottom
    bottom_type: float = _D["bottom_type"]  # ragged, wispy underside (GDC22's bottom type)
    seed: int = 0
    anvil_offset: float | None = None  # metres downwind of the centre; None = 1.0 x radius
    wind_x: float = 1.0  # wind direction (normalised here) that carries the anvil
    wind_y: float = 0.0
    anvil_size: float = 1.6  # anvil radius / storm radius
    twist: float = 2.2  # radians the noises are twisted about the centre (GDC22's vortex tendrils)

    def wind(self) -> tuple[float, float]:
        n = math.hypot(self.wind_x, self.wind_y)
        return (self.wind_x / n, self.wind_y / n) if n > 0 else (0.0, 0.0)

    def anvil_centre(self) -> tuple[float, float]:
        offset = self.radius if self.anvil_offset is None else self.anvil_offset
        wx, wy = self.wind()
        return self.x + wx * offset, self.y + wy * offset

    def anvil_radius(self) -> float:
        return self.anvil_size * self.radius

    def reach(self) -> float:
        """Farthest distance from the centre that any image is touched (the anvil's, in the cirrus)."""
        ax, ay = self.anvil_centre()
        return max(self.radius, math.hypot(ax - self.x, ay - self.y) + self.anvil_radius())


# ---- tiny pure helpers ---------------------------------------------------------------------------


def _smoothstep(e0: float, e1: float, x: np.ndarray) -> np.ndarray:
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _smootherstep(t: np.ndarray) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)


def storm_weight(dist: np.ndarray, radius: float, edge: float = EDGE_WIDTH) -> np.ndarray:
    """The stencil's radial weight: 1 inside (1 - edge) x radius, a C2 fade to exactly 0 at the radius
    and beyond, so the storm meets the surrounding sky without a seam (GDC22: "seamless")."""
    return _smootherstep((1.0 - np.asarray(dist, np.float64) / radius) / edge)


def _window(params: Mapping[str, Any], cx: float, cy: float, half: float) -> tuple[slice, slice] | None:
    """Rows and columns of the field pixels whose centres may lie within `half` of (cx, cy)."""
    res, size = params["field_resolution"], params["field_size"]

    def span(c: float, origin: float) -> slice | None:
        lo = math.floor(((c - half - origin) / size + 0.5) * res - 0.5)
        hi = math.ceil(((c + half - origin) / size + 0.5) * res - 0.5) + 1
        lo, hi = max(lo, 0), min(hi, res)
        return slice(lo, hi) if hi > lo else None

    cols, rows = span(cx, params["field_origin_x"]), span(cy, params["field_origin_y"])
    return None if rows is None or cols is None else (rows, cols)


def _inside(
    params: Mapping[str, Any], xs: np.ndarray, ys: np.ndarray, cx: float, cy: float, radius: float
) -> tuple[tuple[slice, slice], np.ndarray] | None:
    """The window around a circle and the mask of its pixels strictly inside the circle: only those are
    evaluated (the noises are the expensive part) and only those can change."""
    win = _window(params, cx, cy, radius)
    if win is None:
        return None
    inside = np.hypot(xs[win] - cx, ys[win] - cy) < radius
    return (win, inside) if inside.any() else None


# ---- the mesocyclone (GDC22) --------------------------------------------------------------------


def _mesocyclone(storm: Storm, xs: np.ndarray, ys: np.ndarray) -> dict[str, np.ndarray]:
    """Weight and target values of one storm over a window of pixel centres (storm-local noise, so
    moving a storm moves its shape with it; deterministic for its seed)."""
    lx, ly = (xs - storm.x) / storm.radius, (ys - storm.y) / storm.radius
    r = np.hypot(lx, ly)
    s = int(storm.seed) * 64  # each noise below gets its own 8 seeds (fbm uses seed + octave)
    # GDC22: "We twisted these noises around the center of the mesocyclone to produce the
    # characteristic vortex tendrils": the twist grows towards the centre, where the vortex is fastest.
    phi = storm.twist * (1.0 - np.minimum(r, 1.0)) ** 2
    c, sn = np.cos(phi), np.sin(phi)
    tx, ty = c * lx - sn * ly, sn * lx + c * ly
    # Distorted noises (GDC22): a low-frequency warp bends the tendril and relief noises.
    wx = world_fbm_2d("perlin", tx * 2.5 + 11.3, ty * 2.5 - 4.7, 2, s) - 0.5
    wy = world_fbm_2d("perlin", tx * 2.5 - 7.9, ty * 2.5 + 3.1, 2, s + 8) - 0.5
    edge = world_fbm_2d("perlin", tx * 2.2 + 5.5, ty * 2.2 + 1.7, 3, s + 16) - 0.5
    tendril = world_fbm_2d("perlin", (tx + 0.5 * wx) * 4.0, (ty + 0.5 * wy) * 4.0, 3, s + 24)
    billow = world_fbm_2d("worley", tx * 3.5 + 0.37, ty * 3.5 + 0.61, 2, s + 32)
    relief = world_fbm_2d("perlin", (tx + 0.6 * wy) * 3.5 - 2.3, (ty + 0.6 * wx) * 3.5 + 8.1, 3, s + 40)
    # GDC22: "Several noises were composited and blended to their maximum values at the
    # center to produce the characteristic cylindrical foot of the mesocyclone" (the "sombrero").
    comp = np.clip((0.55 * tendril + 0.45 * billow - 0.4) / 0.3, 0.0, 1.0)
    rc = r + 0.22 * edge  # noisy, twisted radius: a round column with ragged edges, not a disc
    column = 1.0 - _smoothstep(*COLUMN_RADIUS, rc)
    tower = 1.0 - _smoothstep(*TOWER_RADIUS, rc)
    foot = 1.0 - _smoothstep(*FOOT_RADIUS, r + 0.3 * edge)
    brim = foot * (0.45 + 0.55 * comp)  # the spread-out foot: mostly covered, torn into tendrils
    coverage = storm.coverage * (brim + (1.0 - brim) * column)
    # "increase cloud coverage and type radially toward a point": cumulonimbus (1) at the centre.
    top_type = (0.55 + 0.35 * comp) * (1.0 - column) + column
    # GDC22: a raised bottom type relaxes the bottom profile into ragged, wispy shapes.
    bottom_type = storm.bottom_type * (0.8 + 0.2 * np.maximum(comp, column))
    # GDC22: variable heights. The tower reaches `height` with a slightly domed top; the brim
    # rises a little above the layer where its noise is dense.
    dome = storm.height * (1.0 - 0.1 * np.clip(rc / TOWER_RADIUS[1], 0.0, 1.0) ** 2)
    brim_top = 1.0 + 0.3 * comp * foot
    max_height = brim_top + (dome - brim_top) * tower
    # GDC22: "a set of distorted noises and radial gradients to use as signals for a height
    # adjustment to give the underside more definition"; "the bottom of a mesocyclone flattens out, [but]
    # the underside is anything but flat": small relief at the foot growing outwards, and a slight
    # lowering (wall cloud) under the column.
    gradient = _smoothstep(0.3, 1.0, r)
    min_height = storm.base + (0.06 + 0.4 * gradient) * (relief - 0.5) * 2.0 - 0.05 * column
    return {
        "weight": storm_weight(r * storm.radius, storm.radius) * float(np.clip(storm.blend, 0.0, 1.0)),
        "coverage": coverage,
        "type": top_type,
        "bottom_type": bottom_type,
        "max_height": max_height,
        "min_height": min_height,
    }


def _anvil(storm: Storm, xs: np.ndarray, ys: np.ndarray) -> dict[str, np.ndarray]:
    """GDC22: "We used the superstorm position, radius and wind vector to create a cirrus cloud
    formation above the superstorm mesocyclone and offset in the wind direction." An ellipse that
    fans out downwind, inside the circle of `anvil_radius` around `anvil_centre`, streaked along the wind
    (docs/sources.md#cirrus-anvil)."""
    ax, ay = storm.anvil_centre()
    ra = storm.anvil_radius()
    wx, wy = storm.wind()
    if wx == 0.0 and wy == 0.0:
        wx = 1.0
    dx, dy = (xs - ax) / ra, (ys - ay) / ra
    along, across = dx * wx + dy * wy, -dx * wy + dy * wx
    spread = 0.55 + 0.35 * np.clip(0.5 + 0.5 * along, 0.0, 1.0)  # <= 1: stays inside the anvil circle
    re = np.hypot(along, across / spread)
    s = int(storm.seed) * 64
    edge = world_fbm_2d("perlin", along * 1.5 + 3.3, across * 4.0 - 1.9, 3, s + 48) - 0.5
    streak = world_fbm_2d("perlin", along * 2.0 - 6.1, across * 6.0 + 2.7, 3, s + 56)
    shape = 1.0 - _smoothstep(0.6, 1.0, re + 0.35 * edge)
    blend = float(np.clip(storm.blend, 0.0, 1.0))
    return {
        "weight": _smootherstep((1.0 - re) / ANVIL_EDGE_WIDTH) * blend,
        "coverage": ANVIL_COVERAGE * shape * (0.75 + 0.25 * streak),
        "type": ANVIL_TYPE[0] + (ANVIL_TYPE[1] - ANVIL_TYPE[0]) * np.clip(0.5 + 0.5 * along, 0.0, 1.0),
        "shape": shape,
    }


# ---- rasterising the stencils -----------------------------------------------------------------


def _order_key(storm: Storm) -> tuple:
    return tuple(storm.radius if v is None else v for v in astuple(storm))


def apply_storms(fields: dict[str, np.ndarray], params: Mapping[str, Any], storms: Sequence[Storm]) -> None:
    """Rasterise the storms into the field images in place (GDC22; docs/sources.md#storm-stencil).

    "Using a position, radius and coverage, stencils would only affect the region that they occupied"
    (GDC22): in "a" and "b" a storm changes only pixels whose centres lie strictly inside its radius, and it
    fades to nothing at the radius. The anvil (GDC22) is offset downwind and larger than the storm,
    so it necessarily reaches outside the radius -- but only in the "cirrus" image, up to
    ``storm.reach()`` from the centre. A storm with blend 0 changes nothing; pixels no storm touches keep
    their exact bits.

    Channels: coverage, top type, bottom type, max height and storm coverage are only ever raised (each
    storm's result is computed from the original fields and the storms are max-combined); min height and
    cirrus type move towards each storm's target by its weight, averaged by weight where storms overlap.
    Both are independent of the order of ``storms``. Precipitation and the density multiplier are left
    alone (GDC22 gives Horizon Forbidden West no precipitation channel). Min height may go below 0 (under
    the layer bottom) down to the ground, so call this after :func:`fields.clamp_fields`, which would clip it.
    """
    a, b, ci = fields["a"], fields["b"], fields["cirrus"]
    # Canonical order, so that the weighted sums below round identically for any input order.
    active = sorted((s for s in storms if s.blend > 0.0 and s.radius > 0.0), key=_order_key)
    if not active:
        return
    xs_all, ys_all = pixel_centres(params)
    thickness = params.get("layer_top", 4000.0) - params.get("layer_bottom", 1500.0)
    ground = -params.get("layer_bottom", 1500.0) / thickness if thickness > 0 else -np.inf

    raised = {"coverage": (a, 0), "type": (a, 2), "bottom_type": (a, 3), "max_height": (b, 2), "storm": (b, 0)}
    orig = {k: img[..., i].astype(np.float64) for k, (img, i) in raised.items()}
    out = {k: v.copy() for k, v in orig.items()}
    min_orig = b[..., 1].astype(np.float64)
    num, den = np.zeros_like(min_orig), np.zeros_like(min_orig)
    cov_orig, ctype_orig = ci[..., 0].astype(np.float64), ci[..., 1].astype(np.float64)
    cov_out = cov_orig.copy()
    c_num, c_den, c_touch = np.zeros_like(cov_orig), np.zeros_like(cov_orig), np.zeros(cov_orig.shape, bool)

    for storm in active:
        sel = _inside(params, xs_all, ys_all, storm.x, storm.y, storm.radius)
        if sel is not None:
            win, inside = sel
            m = _mesocyclone(storm, xs_all[win][inside], ys_all[win][inside])
            wgt = m["weight"]
            targets = dict(m, storm=wgt)  # GDC22's storm coverage = the stencil's weight x blend
            for key in raised:
                o = orig[key][win][inside]
                cand = o + (np.maximum(o, targets[key]) - o) * (1.0 if key == "storm" else wgt)
                out[key][win][inside] = np.maximum(out[key][win][inside], cand)
            num[win][inside] += wgt * (m["min_height"] - min_orig[win][inside])
            den[win][inside] += wgt
        sel = _inside(params, xs_all, ys_all, *storm.anvil_centre(), storm.anvil_radius())
        if sel is not None:
            win, inside = sel
            m = _anvil(storm, xs_all[win][inside], ys_all[win][inside])
            wgt = m["weight"]
            o = cov_orig[win][inside]
            cov_out[win][inside] = np.maximum(cov_out[win][inside], o + (np.maximum(o, m["coverage"]) - o) * wgt)
            tw = wgt * m["shape"]
            c_num[win][inside] += tw * (m["type"] - ctype_orig[win][inside])
            c_den[win][inside] += tw
            c_touch[win][inside] |= wgt > 0.0

    touched = den > 0.0
    for key, (img, i) in raised.items():
        hi = 1.0 if key != "max_height" else np.inf
        img[..., i][touched] = np.clip(out[key][touched], 0.0, hi)
    min_new = np.maximum(min_orig + num / np.maximum(den, 1.0), ground)
    b[..., 1][touched] = min_new[touched]
    # Keep the layer at least 1 % thick where we touched it (as fields.clamp_fields does).
    thin = touched & (b[..., 2] < b[..., 1] + 0.01)
    b[..., 2][thin] = b[..., 1][thin] + 0.01
    ci[..., 0][c_touch] = np.clip(cov_out[c_touch], 0.0, 1.0)
    ctype_new = ctype_orig + c_num / np.maximum(c_den, 1.0)
    ci[..., 1][c_touch] = np.clip(ctype_new[c_touch], 0.0, 1.0)


# ---- lifecycle (GDC22) ------------------------------------------------------------------------


def lifecycle_keys(
    start_frame: int, fps: float, ramp_in_s: float = 120.0, hold_s: float = 180.0, ramp_out_s: float = 120.0
) -> list[tuple[int, float]]:
    """(frame, blend) keyframes of a storm's life, GDC22: the system "begins to load a
    superstorm there over a period of 2 minutes. The Storm persists for a few minutes [...] And then it
    dissipates over 2 minutes". The hold ("a few minutes") defaults to 3 (docs/sources.md#storm-lifecycle)."""
    t1 = start_frame + round(ramp_in_s * fps)
    t2 = t1 + round(hold_s * fps)
    t3 = t2 + round(ramp_out_s * fps)
    return [(int(start_frame), 0.0), (int(t1), 1.0), (int(t2), 1.0), (int(t3), 0.0)]


def lightning_keys(
    start_frame: int, fps: float, flashes: int = 4, discharges: int = 2, peak: float = 20.0, seed: int = 0
) -> list[dict[str, float]]:
    """Keyframes of a lightning sequence (GDC22 after Uman, *Lightning*): "several intra-cloud
    effects while increasing the intensity of the flashes each time. Then it would fire off 1 to 2 Ground
    discharge effects". Each key: frame, flash intensity, the flash position as a fraction of the storm
    radius (x, y; GDC22 feeds "a variable position for each flash") and ground (1 for a discharge).
    Each flash lasts a handful of frames (GDC22: 4-8) and flickers with a re-stroke; the pauses between
    flashes (0.4-1.5 s) and positions are our choice, seeded (docs/sources.md#lightning-sequence)."""
    rng = np.random.default_rng(seed)
    keys: list[dict[str, float]] = []
    frame = int(start_frame)
    for i in range(flashes + discharges):
        ground = i >= flashes
        strength = peak if ground else peak * (0.25 + 0.6 * i / max(flashes - 1, 1))
        angle = rng.uniform(0.0, 2.0 * np.pi)
        reach = rng.uniform(0.2, 0.5) if ground else rng.uniform(0.0, 0.35)
        x, y, g = reach * np.cos(angle), reach * np.sin(angle), 1.0 if ground else 0.0
        pulse = [(-1, 0.0), (0, 1.0), (1, 0.35)]
        # A ground discharge restrikes more and lasts longer (several return strokes).
        pulse += [(2, 0.8), (3, 0.2), (6, 0.0)] if ground else [(3, 0.0)]
        keys += [{"frame": frame + df, "flash": strength * v, "x": x, "y": y, "ground": g} for df, v in pulse]
        frame += pulse[-1][0] + 1 + int(round(fps * rng.uniform(0.4, 1.5)))
    return keys


# How many frames before a flash its position is set: the temporal viewport needs 16 redraws to build
# the flash mask at that position (GDC22: "generate a mask using position and radius data before each
# flash"), so the mask is whole when the flash fires.
FLASH_MASK_LEAD = 16


def lightning_position_keys(keys: list[dict[str, float]]) -> list[dict[str, float]]:
    """One key per flash for its position (x, y, ground), set as early as possible before it fires:
    FLASH_MASK_LEAD frames ahead of the first flash, and right after the previous flash for the others.
    Positions are held (constant interpolation) until the next flash's key."""
    starts: list[dict[str, float]] = []
    ends: list[float] = []
    for k in keys:
        if not starts or (k["x"], k["y"], k["ground"]) != (starts[-1]["x"], starts[-1]["y"], starts[-1]["ground"]):
            starts.append(k)
            ends.append(k["frame"])
        ends[-1] = k["frame"]
    out = []
    for i, k in enumerate(starts):
        frame = k["frame"] - FLASH_MASK_LEAD if i == 0 else min(ends[i - 1] + 1, k["frame"])
        out.append({"frame": frame, "x": k["x"], "y": k["y"], "ground": k["ground"]})
    return out


def vortex_fade(blend):
    """How fast a storm's vortex turns at a lifecycle blend, relative to its spin: GLSL's
    smoothstep(0, 0.25, blend), as the density fades the storm in (GDC22)."""
    t = np.clip(np.asarray(blend, np.float64) / 0.25, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def vortex_time(times: np.ndarray, blends: np.ndarray, t: float) -> float:
    """The storm's vortex time at time `t`: vortex_fade(blend) integrated over time, from the first
    sample (where it is that sample's time times its fade) to `t`, the fade linear between samples.
    The vortex angle is vortex time x ring speed, so a ramp turns the storm at most at its spin."""
    times = np.asarray(times, np.float64)
    fades = vortex_fade(blends)
    if len(times) == 0:
        return 0.0
    start = float(times[0] * fades[0])
    if t <= times[0] or len(times) == 1:
        return start + (t - float(times[0])) * float(fades[0])
    cumulative = np.concatenate([[0.0], np.cumsum(0.5 * (fades[1:] + fades[:-1]) * np.diff(times))])
    i = int(np.searchsorted(times, t, side="right")) - 1
    if i >= len(times) - 1:
        return start + float(cumulative[-1]) + (t - float(times[-1])) * float(fades[-1])
    w = (t - times[i]) / (times[i + 1] - times[i])
    fade_t = fades[i] + w * (fades[i + 1] - fades[i])
    return start + float(cumulative[i]) + 0.5 * float(fades[i] + fade_t) * float(t - times[i])
