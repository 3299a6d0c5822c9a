"""Painting the data field from above: brush dabs, their raster, and how a paint layer meets the field.

A paint layer holds brush dabs in world metres (one row of DABS each: position, radius, signed strength,
falloff, mode, stroke start), not pixels: it is re-rasterized at any field resolution and its strokes are
plain data, which Blender saves and undoes like any setting. Its raster is a signed change per field pixel in [-1, 1].

Paint layers act last, after the stack, the weather rules and the superstorm stencils, in their order
(docs/painting.md). A coverage paint layer adds to the coverage the shader sees *after* the Coverage
slider's multiplier, so a stroke raises the clouds where it falls and nowhere else: the multiplier is
found from the field without the paint, and the painted cover is stored divided by it. No bpy here.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np

from . import fields
from .errors import NubisError


@dataclass(frozen=True)
class Choice:
    """One entry of a brush menu: the name core/ uses, and the label and tooltip Blender shows."""

    name: str
    label: str
    description: str


# The channels a brush paints, in the Paint Sky tool's menu order. Blender keeps the tool's choice by its
# position in this list, so a new channel goes at the end. The one list: the tool's menu (blender/sidebar/paint.py),
# a paint layer's channel menu (blender/sidebar/properties.py) and every check derive from it.
BRUSH_CHANNELS = (
    Choice("coverage", "Coverage", "Where the clouds are: adds to the cover the Coverage slider gives"),
    Choice("type", "Cloud Type", "Stratus (0) to cumulonimbus (1)"),
    Choice("precipitation", "Precipitation", "Rain: darker, denser clouds"),
    Choice("storm", "Storm Coverage", "Where a superstorm's clouds stand (inside a superstorm)"),
)
# Where each lives in the field images, in core/fields.py's layout order (the order sentences list them in).
PAINT_CHANNELS: dict[str, tuple[str, int]] = {
    name: place for name, place in fields.CHANNELS.items() if name in {c.name for c in BRUSH_CHANNELS}
}
FALLOFFS = ("smooth", "linear", "constant")
MODES = ("paint", "smooth")  # what a dab does: its `mode` column holds the index


@dataclass(frozen=True)
class BrushMode:
    """A way the brush paints: the modifier key that picks it during a drag, and the dabs it lays."""

    name: str
    label: str
    description: str
    key: str  # the modifier held while dragging ("ctrl", "shift"); "" for the plain drag
    sign: float  # of the dabs' strength: negative subtracts
    dab_mode: str  # a MODES entry


# The one list of brush modes: the tool's Mode menu, the keys a drag reads and the tooltips derive from it
# (blender/sidebar/paint.py). A drag holding several keys takes the first mode here whose key is held.
BRUSH_MODES = (
    BrushMode("add", "Add", "Raise the channel under the brush", "", 1.0, "paint"),
    BrushMode("subtract", "Subtract", "Lower the channel under the brush", "ctrl", -1.0, "paint"),
    BrushMode("smooth", "Smooth", "Soften the paint layer's strokes under the brush", "shift", 1.0, "smooth"),
)
BRUSH_MODE: dict[str, BrushMode] = {m.name: m for m in BRUSH_MODES}


@dataclass(frozen=True)
class DabColumn:
    """One number of a stored dab, and how Blender stores it (blender/sidebar/properties.py builds its dab
    from these)."""

    name: str
    kind: str  # "float", "int" or "bool"
    label: str
    description: str = ""
    metres: bool = False  # a length in world metres
    min: float | None = None
    max: float | None = None


# One dab: x, y (metres), radius (metres), signed strength (with the pen's pressure), falloff index,
# mode index, 1 where a stroke starts. The one list of its columns: arrays hold them in this order.
DABS = (
    DabColumn("x", "float", "X", metres=True),
    DabColumn("y", "float", "Y", metres=True),
    DabColumn("radius", "float", "Radius", metres=True, min=0.0),
    DabColumn("strength", "float", "Strength", "Signed: negative subtracts", min=-1.0, max=1.0),
    DabColumn("falloff", "int", "Falloff", "Index into core/paint.FALLOFFS", min=0),
    DabColumn("mode", "int", "Mode", "Index into core/paint.MODES", min=0),
    DabColumn("start", "bool", "Stroke Start", "The first dab of a stroke"),
)
DAB_COLUMNS = tuple(c.name for c in DABS)
COLUMN: dict[str, int] = {name: i for i, name in enumerate(DAB_COLUMNS)}  # a column's index in a dab array

# The slider's multiplier stored in the file while coverage paint exists: at 0 (a clear sky) the painted
# cover could not be stored as cover / multiplier. Unpainted texels read exactly as before at any floor.
MULTIPLIER_FLOOR = 1e-3
SPACING = 0.2  # dabs along a stroke, in radii: dense enough that a stroke has no beads at full strength
# A layer's dabs; beyond this a stroke is refused. 56 MB as arrays, 1.7 GB as Blender holds them and about
# 35 s to rasterize (docs/painting.md#long-composites).
MAX_DABS = 1_000_000


@dataclass(frozen=True)
class Grid:
    """The field's pixel grid in the world: pixel (i, j) (row i, bottom row first) is centred at
    x = ox + ((j + 0.5) / res - 0.5) * size, likewise y with i (core/fields.pixel_centres)."""

    resolution: int
    size: float
    ox: float
    oy: float

    @classmethod
    def of(cls, params: Mapping[str, Any]) -> Grid:
        return cls(
            int(params["field_resolution"]),
            float(params["field_size"]),
            float(params["field_origin_x"]),
            float(params["field_origin_y"]),
        )

    @property
    def pixel(self) -> float:
        return self.size / self.resolution

    def to_pixel(self, x: float, y: float) -> tuple[float, float]:
        """Continuous (column, row) of a world point, pixel centres at integers."""
        return ((x - self.ox) / self.size + 0.5) * self.resolution - 0.5, (
            (y - self.oy) / self.size + 0.5
        ) * self.resolution - 0.5

    def reach(self, radius: float) -> tuple[float, float, float, float]:
        """(x min, x max, y min, y max): where a dab's centre must lie for its disc to touch the field."""
        half = self.size / 2 + radius
        return self.ox - half, self.ox + half, self.oy - half, self.oy + half

    def rect(self, x: float, y: float, radius: float, margin: int = 0) -> tuple[int, int, int, int] | None:
        """(row0, row1, col0, col1), ends exclusive, of the pixels a disc can touch; None when it misses."""
        cx, cy = self.to_pixel(x, y)
        r = radius / self.pixel + margin
        c0, c1 = max(math.floor(cx - r), 0), min(math.ceil(cx + r) + 1, self.resolution)
        r0, r1 = max(math.floor(cy - r), 0), min(math.ceil(cy + r) + 1, self.resolution)
        if c0 >= c1 or r0 >= r1:
            return None
        return r0, r1, c0, c1


def union(a: tuple[int, int, int, int] | None, b: tuple[int, int, int, int] | None):
    if a is None:
        return b
    if b is None:
        return a
    return min(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), max(a[3], b[3])


# ---- checking a brush, a stroke and a dab ------------------------------------------------------------
#
# Each rule stated once, here; the brush and a script's stroke (blender/sidebar/paint.py) and a preset's dabs
# (parse_dabs, which core/presets.py calls) go through the same functions (docs/painting.md#what-is-refused).

# Values at or beyond this size are refused as infinite: Blender stores an infinite float property as float32's
# largest, 3.4e38, which math.isfinite passes, and a float64 beyond float32's range is stored the same way.
NUMBER_MAX = 3.0e38
FLOAT32_MAX = 3.4028234663852886e38
# metres: a millimetre. A smaller radius rounds to 0 once Blender stores it as float32, and the raster
# divides by it; the brush asks for more anyway (half a field pixel, 12 mm on the finest field).
RADIUS_MIN = 0.001
RADIUS_MAX = 1e7  # metres: the widest data field (Field > Size's maximum, core/schema.py)
# metres from the origin, a stored dab's x and y: the farthest field edge is 1.5e7 m away (Center within
# 1e7 m, Size up to 1e7 m), so this leaves room for strokes kept while the field moves, and no more.
DAB_POSITION_MAX = 1e8


def _shown(value: float) -> str:
    """A refused number as a person reads it: NaN, infinite (float32's largest too: Blender's infinity), or
    itself with the bound it passes."""
    if math.isnan(value):
        return "NaN"
    if math.isinf(value) or abs(value) == FLOAT32_MAX:
        return "infinite"
    return f"{value:g} ({NUMBER_MAX:g} or more)"


def _metres(value: float) -> str:
    """A bound in metres as a person writes it: 64000, 125, 0.0122."""
    return f"{value:.0f}" if abs(value) >= 100 else f"{value:.3g}"


def _at_least(value: float) -> str:
    """A lower bound in metres rounded up as a person writes it: 125, 68.4 (for 68.36), 0.0123 (0.01221)."""
    if value >= 100:
        return str(math.ceil(value))
    scale = 10.0 ** (2 - math.floor(math.log10(value)))
    return f"{math.ceil(value * scale) / scale:.3g}"


def check_number(value: float, what: str, unit: str, fix: str) -> None:
    """Rule: a finite number below NUMBER_MAX in size (what Blender can store as float32 and is not its
    infinity). `unit` is "" or " of metres"."""
    if not (math.isfinite(value) and abs(value) < NUMBER_MAX):
        raise NubisError(f"{what} must be a finite number{unit}, not {_shown(value)}: {fix}")


def check_radius(radius: float, what: str, grid: Grid | None = None) -> None:
    """Rules: a radius of at least a millimetre and, on a field, half its pixel (a smaller dab would not show);
    at most the field's width, or without a field the widest field's."""
    lo = RADIUS_MIN if grid is None else max(RADIUS_MIN, grid.pixel / 2)
    hi = RADIUS_MAX if grid is None else grid.size
    check_number(radius, what, " of metres", f"use {_at_least(lo)} to {_metres(hi)} m")
    if radius < lo:
        if lo > RADIUS_MIN:
            raise NubisError(
                f"{what} {radius:g} m is smaller than half a field pixel ({_metres(lo)} m): "
                f"use at least {_at_least(lo)} m, or raise the field resolution"
            )
        raise NubisError(f"{what} {radius:g} m is under a millimetre: use at least {RADIUS_MIN:g} m")
    if radius > hi:
        field = "the whole field" if grid is not None else "the widest data field"
        raise NubisError(
            f"{what} {radius:g} m is larger than {field} ({_metres(hi)} m across): use at most {_metres(hi)} m "
            "(a constant or gradient layer changes the whole field)"
        )


def check_brush(grid: Grid, radius: float, strength: float) -> None:
    """The brush: its radius (check_radius on the field) and its strength, in (0, 1]. Blender's Strength
    slider clamps to 0-1 before this sees it, as its own sliders do; 0 would paint nothing."""
    check_radius(radius, "the brush radius", grid)
    check_number(strength, "the brush strength", "", "use a strength between 0.01 and 1")
    if not 0.0 < strength <= 1.0:
        raise NubisError(f"the brush strength {strength:g} is not in (0, 1]: use a strength between 0.01 and 1")


def check_points(grid: Grid, points: Sequence[tuple[float, float, float, bool]]) -> None:
    """A stroke must have points, each location and pressure a finite number (check_number). Points far
    outside the `grid` are fine: stroke_dabs lays only the part of the stroke over it, and refuses a stroke
    with no such part."""
    if not points:
        raise NubisError("the stroke has no points: give it at least one location")
    for n, (x, y, pressure, _start) in enumerate(points, 1):
        for name, v in (("x", x), ("y", y)):
            check_number(v, f"the {name} of stroke point {n}", " of metres", "give finite world locations")
        check_number(pressure, f"the pressure of stroke point {n}", "", "give a pressure between 0 and 1")


def check_paint_channel(layer: str, channel: str) -> None:
    """Rule: a paint layer writes a channel a brush paints (PAINT_CHANNELS); `channel` as presets write it."""
    if channel not in PAINT_CHANNELS:
        raise NubisError(
            f"the paint layer '{layer}' writes '{channel}', which a brush cannot paint: "
            f"set its channel to one of {', '.join(PAINT_CHANNELS)}"
        )


# Points one scripted stroke may hold. Blender keeps about 5 KB a point in the operator's properties and copies
# them once the operator has run: two million points crashed Blender's copy under an 8 GB memory cap
# (docs/painting.md#what-is-refused); a hand's drag records hundreds.
MAX_STROKE_POINTS = 1_000_000


def check_stroke_length(points: int) -> None:
    """Rule: a stroke of at most MAX_STROKE_POINTS points (refused before Blender copies them)."""
    if points > MAX_STROKE_POINTS:
        raise NubisError(
            f"the stroke has {points:,} points, over the {MAX_STROKE_POINTS:,} one stroke may hold: paint it as "
            "several strokes (one call each)"
        )


def check_room(held: int, adding: int, layer: str = "") -> None:
    """Rule: a paint layer holds at most MAX_DABS dabs; `adding` is counted before any is laid."""
    if held + adding <= MAX_DABS:
        return
    whose = f"the paint layer '{layer}' holds {held:,} dabs, and " if layer else ""
    raise NubisError(
        f"{whose}this stroke would lay {adding:,} dabs, over the {MAX_DABS:,} a paint layer holds: paint shorter "
        "strokes or with a larger radius, or start a new paint layer (Data Field > +, kind Paint)"
    )


def outside(grid: Grid) -> NubisError:
    half = grid.size / 2
    return NubisError(
        f"the stroke lies outside the data field (x {grid.ox - half:.0f} to {grid.ox + half:.0f} m, "
        f"y {grid.oy - half:.0f} to {grid.oy + half:.0f} m): paint over the field, or move or enlarge it "
        "(Field > Origin, Size)"
    )


def check_dab(row: Sequence[float], where: str) -> None:
    """A stored dab (a preset's row): finite numbers (check_number), its radius by check_radius without a
    field (the field may change after painting: the dabs are re-rasterized), its strength signed within
    -1 to 1 (a subtracting stroke's dabs are negative, a pen's light touch near 0), its position within
    DAB_POSITION_MAX of the origin."""
    x, y, radius, strength, falloff, mode, start = row
    for column, v in zip(DABS, row, strict=True):
        if column.name != "radius":  # check_radius says which radius to use
            unit = " of metres" if column.metres else ""
            check_number(v, f"{where}: {column.name}", unit, "fix or remove the dab")
    for name, v in (("x", x), ("y", y)):
        if abs(v) > DAB_POSITION_MAX:
            raise NubisError(
                f"{where}: {name} = {v:g} m is too far out: keep a dab within {DAB_POSITION_MAX:g} m of the "
                "origin (the farthest data field ends 1.5e+07 m from it), or remove it"
            )
    check_radius(radius, f"{where}: the radius", None)
    if not -1.0 <= strength <= 1.0:
        raise NubisError(f"{where}: the strength {strength:g} is outside -1 to 1: use -1 (subtract) to 1 (add)")
    if falloff not in range(len(FALLOFFS)) or mode not in range(len(MODES)):
        raise NubisError(
            f"{where}: falloff must be 0-{len(FALLOFFS) - 1} ({', '.join(FALLOFFS)}) and mode "
            f"0-{len(MODES) - 1} ({', '.join(MODES)})"
        )
    if start not in (0, 1):
        raise NubisError(f"{where}: start must be 1 (the first dab of a stroke) or 0")


# ---- a stroke into dabs --------------------------------------------------------------------------------


def clip(box: tuple[float, float, float, float], x0: float, y0: float, x1: float, y1: float):
    """The part (t0, t1) of the segment from (x0, y0) to (x1, y1) inside `box` (x min, x max, y min, y max),
    as fractions of the segment, or None when it misses the box (Liang-Barsky). Exact on Fractions."""
    t0, t1 = 0, 1
    dx, dy = x1 - x0, y1 - y0
    for p, q in ((-dx, x0 - box[0]), (dx, box[1] - x0), (-dy, y0 - box[2]), (dy, box[3] - y0)):
        if p == 0:
            if q < 0:
                return None
            continue
        t = q / p
        if p < 0:
            t0 = max(t0, t)
        else:
            t1 = min(t1, t)
        if t0 > t1:
            return None
    return t0, t1


# metres: a stretch with an end this far out is clipped in exact arithmetic. In float64 the part over the
# field of a line from 1e20 m away would be placed up to 1e20 * 2e-16 = 20 km off it.
FAR = 1e9


def clip_points(box, x0: float, y0: float, x1: float, y1: float):
    """The part of the segment inside `box`: (entry x, y, exit x, y, t at the entry, t at the exit), or None."""
    far = max(abs(x0), abs(y0), abs(x1), abs(y1)) >= FAR
    ends = tuple(Fraction(v) for v in (x0, y0, x1, y1)) if far else (x0, y0, x1, y1)
    window = clip(tuple(Fraction(v) for v in box) if far else box, *ends)
    if window is None:
        return None
    t0, t1 = window
    ax, ay, bx, by = ends
    entry = (x0, y0) if t0 == 0 else (float(ax + (bx - ax) * t0), float(ay + (by - ay) * t0))
    leave = (x1, y1) if t1 == 1 else (float(ax + (bx - ax) * t1), float(ay + (by - ay) * t1))
    return (*entry, *leave, float(t0), float(t1))


class Spacer:
    """Turns stroke points, as they come, into dabs spaced `spacing` radii apart along the stroke (the
    pressure interpolated between points); the first point of a stroke is a dab of its own.

    On a `grid`, each stretch between two points is clipped to the field widened by the radius before any
    dab is laid: a point kilometres (or 1e12 m) away costs the dabs over the field and no more, and the
    first dab laid of a stroke that starts off the field is its start. `advance` counts a stretch's dabs
    without laying them (check_room can refuse them first), `lay` lays them."""

    def __init__(self, radius: float, strength: float, falloff="smooth", mode="paint", spacing=SPACING, grid=None):
        self.radius, self.strength = radius, strength
        self.falloff_index, self.mode_index = FALLOFFS.index(falloff), MODES.index(mode)
        self.step = max(radius * spacing, 1e-6)
        self.box = None if grid is None else grid.reach(radius)
        self.prev: tuple[float, float, float] | None = None
        self.carry = 0.0  # the distance along the stroke since its last dab, laid or clipped away
        self.pending = False  # the stroke's start is not laid yet (its point was off the field)

    def advance(self, x: float, y: float, pressure: float, start: bool = False) -> tuple | None:
        """Move along the stroke to (x, y) and say which of the stretch's dabs fall on the field, laying none:
        (x0, y0, p0, x1, y1, p1, length, first, count) for `count` dabs at first + k * step along the line
        from (x0, y0) (pressure p0) to (x1, y1) (p1), `length` long; None for no dab."""
        pressure = min(max(float(pressure), 0.0), 1.0)
        if self.prev is None or start:
            self.prev, self.carry, self.pending = (x, y, pressure), 0.0, True
            if self.box is not None and clip(self.box, x, y, x, y) is None:
                return None
            return (x, y, pressure, x, y, pressure, 1.0, 0.0, 1)
        px, py, pp = self.prev
        self.prev = (x, y, pressure)
        length = math.hypot(x - px, y - py)
        first = self.step - self.carry
        if first > length:
            self.carry += length
            return None
        self.carry = math.fmod(length - first, self.step)  # exact at any length
        part = (px, py, x, y, 0.0, 1.0) if self.box is None else clip_points(self.box, px, py, x, y)
        if part is None:
            return None
        ex, ey, xx, xy, t0, t1 = part
        span = math.hypot(xx - ex, xy - ey)
        # The first dab at or after the entry: along the whole stretch the dabs lie at first + k * step.
        entry = t0 * length
        offset = first - entry if entry <= first else (self.step - math.fmod(entry - first, self.step)) % self.step
        if span <= 0.0 or offset > span:
            return None
        count = round((span - offset - math.fmod(span - offset, self.step)) / self.step) + 1
        p0, p1 = pp + (pressure - pp) * t0, pp + (pressure - pp) * t1
        return (ex, ey, p0, xx, xy, p1, span, offset, count)

    def lay(self, run: tuple | None) -> np.ndarray:
        """The dabs of an `advance`: (N, 7) float64 in DAB_COLUMNS order."""
        if run is None:
            return as_dabs([])
        x0, y0, p0, x1, y1, p1, length, first, count = run
        t = (first + np.arange(count) * self.step) / length
        out = np.empty((count, len(DAB_COLUMNS)), np.float64)
        out[:, COLUMN["x"]] = x0 + (x1 - x0) * t
        out[:, COLUMN["y"]] = y0 + (y1 - y0) * t
        out[:, COLUMN["radius"]] = self.radius
        out[:, COLUMN["strength"]] = self.strength * (p0 + (p1 - p0) * t)
        out[:, COLUMN["falloff"]] = self.falloff_index
        out[:, COLUMN["mode"]] = self.mode_index
        out[:, COLUMN["start"]] = 0.0
        if self.pending:
            out[0, COLUMN["start"]], self.pending = 1.0, False
        return out

    def add(self, x: float, y: float, pressure: float, start: bool = False) -> np.ndarray:
        """Dab along the stroke to (x, y): the new dabs, (N, 7)."""
        return self.lay(self.advance(x, y, pressure, start))


def stroke_dabs(
    points: Iterable[tuple[float, float, float, bool]],
    radius: float,
    strength: float,
    falloff: str = "smooth",
    mode: str = "paint",
    spacing: float = SPACING,
    grid: Grid | None = None,
) -> np.ndarray:
    """The dabs of one or more strokes: `points` are (x, y, pressure, is_start); `strength` is signed
    (negative subtracts). On a `grid` only the strokes' parts over the field are laid, and a stroke with no
    part over it is refused. The dabs are counted first and refused past MAX_DABS before any is laid.
    Returns (N, 7) float64 in DAB_COLUMNS order."""
    points = list(points)
    counter = Spacer(radius, strength, falloff, mode, spacing, grid)
    total = 0
    for x, y, pressure, start in points:
        run = counter.advance(x, y, pressure, start)
        total += run[-1] if run is not None else 0
    check_room(0, total)
    if grid is not None and total == 0:
        raise outside(grid)
    spacer = Spacer(radius, strength, falloff, mode, spacing, grid)
    parts = [spacer.add(x, y, pressure, start) for x, y, pressure, start in points]
    return np.concatenate(parts) if parts else as_dabs([])


def as_dabs(rows) -> np.ndarray:
    return np.array(rows, np.float64).reshape(-1, len(DAB_COLUMNS))


def _as_float(v: int | float) -> float:
    """A TOML number as a float: an integer too large for one is infinite (check_number refuses it)."""
    try:
        return float(v)
    except OverflowError:
        return math.inf if v > 0 else -math.inf


def parse_dabs(value, where: str) -> list[list[float]]:
    """A preset's `dabs` (a paint layer's strokes, one row of DAB_COLUMNS per dab) checked row by row by
    check_dab, with the row and the rule in the message."""
    columns = ", ".join(DAB_COLUMNS)
    if not isinstance(value, list):
        raise NubisError(f"{where} must be an array of dabs, each [{columns}]")
    if len(value) > MAX_DABS:
        raise NubisError(
            f"{where} holds {len(value):,} dabs, over the {MAX_DABS:,} a paint layer holds: split the strokes "
            "into more layers"
        )
    rows = []
    for i, row in enumerate(value):
        here = f"{where}[{i}]"
        if (
            not isinstance(row, list)
            or len(row) != len(DAB_COLUMNS)
            or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in row)
        ):
            raise NubisError(f"{here} must be {len(DAB_COLUMNS)} numbers: {columns}")
        row = [_as_float(v) for v in row]
        check_dab(row, here)
        rows.append([v if column.kind == "float" else int(v) for column, v in zip(DABS, row, strict=True)])
    return rows
