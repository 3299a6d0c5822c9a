"""Painting the data field from above: brush dabs, their raster, and how a paint layer meets the field.

A paint layer holds brush dabs in world metres (x, y, radius, signed strength, falloff, mode, stroke
start), not pixels: it is re-rasterized at any field resolution and its strokes are plain data, which
Blender saves and undoes like any setting. Its raster is a signed change per field pixel in [-1, 1].

Paint layers act last, after the stack, the weather rules and the superstorm stencils, in their order
(docs/painting.md). A coverage paint layer adds to the coverage the shader sees *after* the Coverage
slider's multiplier, so a stroke raises the clouds where it falls and nowhere else: the multiplier is
found from the field without the paint, and the painted cover is stored divided by it. No bpy here.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import NubisError

# The channels a brush paints, and where they live in the field images (core/fields.py's layout).
PAINT_CHANNELS: dict[str, tuple[str, int]] = {
    "coverage": ("a", 0),
    "precipitation": ("a", 1),
    "type": ("a", 2),
    "storm": ("b", 0),
}
FALLOFFS = ("smooth", "linear", "constant")
MODES = ("paint", "smooth")
# One dab: x, y (metres), radius (metres), signed strength (with the pen's pressure), falloff index,
# mode index, 1 where a stroke starts.
DAB_COLUMNS = ("x", "y", "radius", "strength", "falloff", "mode", "start")
# The slider's multiplier stored in the file while coverage paint exists: at 0 (a clear sky) the painted
# cover could not be stored as cover / multiplier. Unpainted texels read exactly as before at any floor.
MULTIPLIER_FLOOR = 1e-3
SPACING = 0.2  # dabs along a stroke, in radii: dense enough that a stroke has no beads at full strength
MAX_DABS = 1_000_000  # a layer's dabs; beyond this a stroke is refused (about 56 MB of strokes)


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

    def contains(self, x: float, y: float) -> bool:
        half = self.size / 2
        return abs(x - self.ox) <= half and abs(y - self.oy) <= half

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


# ---- checking a stroke -------------------------------------------------------------------------------


def check_brush(grid: Grid, radius: float, strength: float) -> None:
    """Refuse a radius the field cannot show or that would repaint all of it, and a strength that is not a
    number, each with what to use instead."""
    if not math.isfinite(radius) or radius < grid.pixel / 2:
        raise NubisError(
            f"the brush radius {radius:g} m is smaller than half a field pixel ({grid.pixel / 2:.0f} m): "
            f"use at least {math.ceil(grid.pixel / 2)} m, or raise the field resolution"
        )
    if radius > grid.size:
        raise NubisError(
            f"the brush radius {radius:.0f} m is larger than the whole field ({grid.size:.0f} m across): "
            f"use at most {grid.size:.0f} m (a constant or gradient layer changes the whole field)"
        )
    if not math.isfinite(strength) or not 0.0 < abs(strength) <= 1.0:
        raise NubisError(f"the brush strength {strength:g} is not in (0, 1]: use a strength between 0.01 and 1")


def check_points(grid: Grid, points: Sequence[tuple[float, float, float, bool]]) -> None:
    """A stroke must have points, finite ones, and at least one inside the field."""
    if not points:
        raise NubisError("the stroke has no points: give it at least one location")
    for x, y, pressure, _start in points:
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(pressure)):
            raise NubisError("a stroke point is not a number (NaN or infinite): give finite world locations")
    if not any(grid.contains(x, y) for x, y, _p, _s in points):
        half = grid.size / 2
        raise NubisError(
            f"the stroke lies outside the data field (x {grid.ox - half:.0f} to {grid.ox + half:.0f} m, "
            f"y {grid.oy - half:.0f} to {grid.oy + half:.0f} m): paint over the field, or move or enlarge it "
            "(Field > Origin, Size)"
        )


# ---- a stroke into dabs --------------------------------------------------------------------------------


class Spacer:
    """Turns stroke points, as they come, into dabs spaced `spacing` radii apart along the stroke (the
    pressure interpolated between points); the first point of a stroke is a dab of its own."""

    def __init__(self, radius: float, strength: float, falloff: str = "smooth", mode: str = "paint", spacing=SPACING):
        self.radius, self.strength = radius, strength
        self.fi, self.mi = FALLOFFS.index(falloff), MODES.index(mode)
        self.step = max(radius * spacing, 1e-6)
        self.prev: tuple[float, float, float] | None = None
        self.carry = 0.0

    def add(self, x: float, y: float, pressure: float, start: bool = False) -> list[tuple]:
        pressure = min(max(float(pressure), 0.0), 1.0)
        if self.prev is None or start:
            self.prev, self.carry = (x, y, pressure), 0.0
            return [(x, y, self.radius, self.strength * pressure, self.fi, self.mi, 1.0)]
        px, py, pp = self.prev
        length = math.hypot(x - px, y - py)
        rows = []
        d = self.step - self.carry
        while d <= length:
            t = d / length
            p = pp + (pressure - pp) * t
            rows.append((px + (x - px) * t, py + (y - py) * t, self.radius, self.strength * p, self.fi, self.mi, 0.0))
            d += self.step
        self.carry = length - (d - self.step)
        self.prev = (x, y, pressure)
        return rows


def stroke_dabs(
    points: Iterable[tuple[float, float, float, bool]],
    radius: float,
    strength: float,
    falloff: str = "smooth",
    mode: str = "paint",
    spacing: float = SPACING,
) -> np.ndarray:
    """The dabs of one or more strokes: `points` are (x, y, pressure, is_start); `strength` is signed
    (negative subtracts). Returns (N, 7) float64 in DAB_COLUMNS order."""
    spacer = Spacer(radius, strength, falloff, mode, spacing)
    rows = [row for x, y, pressure, start in points for row in spacer.add(x, y, pressure, start)]
    return as_dabs(rows)


def as_dabs(rows) -> np.ndarray:
    return np.array(rows, np.float64).reshape(-1, len(DAB_COLUMNS))


def parse_dabs(value, where: str) -> list[list[float]]:
    """A preset's `dabs` (a paint layer's strokes, one [x, y, radius, strength, falloff, mode, start] row per
    dab) checked row by row, with the row and the rule in the message."""
    if not isinstance(value, list):
        raise NubisError(f"{where} must be an array of dabs, each [x, y, radius, strength, falloff, mode, start]")
    if len(value) > MAX_DABS:
        raise NubisError(f"{where} holds {len(value)} dabs, over {MAX_DABS}: split the strokes into more layers")
    rows = []
    for i, row in enumerate(value):
        here = f"{where}[{i}]"
        if (
            not isinstance(row, list)
            or len(row) != len(DAB_COLUMNS)
            or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in row)
        ):
            raise NubisError(f"{here} must be 7 numbers: x, y, radius, strength, falloff, mode, start")
        if not all(math.isfinite(v) for v in row):
            raise NubisError(f"{here} holds a value that is not a finite number: fix or remove the dab")
        x, y, radius, strength, falloff, mode, start = row
        if radius <= 0 or abs(strength) > 1 or falloff not in range(len(FALLOFFS)) or mode not in range(len(MODES)):
            raise NubisError(
                f"{here}: radius must be positive, strength within -1 to 1, falloff 0-{len(FALLOFFS) - 1} "
                f"({', '.join(FALLOFFS)}) and mode 0-{len(MODES) - 1} ({', '.join(MODES)})"
            )
        if start not in (0, 1):
            raise NubisError(f"{here}: start must be 1 (the first dab of a stroke) or 0")
        rows.append([float(x), float(y), float(radius), float(strength), int(falloff), int(mode), int(start)])
    return rows


# ---- rasterizing dabs -------------------------------------------------------------------------------------


def dab_weights(grid: Grid, rect, x: float, y: float, radius: float, falloff: int) -> np.ndarray:
    """The brush's weight (0-1) over `rect`: 1 at the centre, 0 from the radius on."""
    r0, r1, c0, c1 = rect
    cx, cy = grid.to_pixel(x, y)
    dx = (np.arange(c0, c1) - cx)[None, :]
    dy = (np.arange(r0, r1) - cy)[:, None]
    d = np.sqrt(dx * dx + dy * dy) * (grid.pixel / radius)
    t = np.clip(1.0 - d, 0.0, 1.0)
    if FALLOFFS[falloff] == "smooth":
        return t * t * (3.0 - 2.0 * t)
    if FALLOFFS[falloff] == "linear":
        return t
    return (d < 1.0).astype(np.float64)


def _box_blur(a: np.ndarray, k: int) -> np.ndarray:
    """A (2k+1)-wide box blur, edges clamped, separable by cumulative sums."""
    if k <= 0:
        return a.copy()
    out = a
    for axis in (0, 1):
        pad = [(0, 0), (0, 0)]
        pad[axis] = (k + 1, k)
        c = np.cumsum(np.pad(out, pad, mode="edge"), axis=axis)
        n = out.shape[axis]
        hi = np.take(c, np.arange(2 * k + 1, 2 * k + 1 + n), axis=axis)
        lo = np.take(c, np.arange(0, n), axis=axis)
        out = (hi - lo) / (2 * k + 1)
    return out


class Raster:
    """A paint layer's signed change per field pixel, built dab by dab.

    Within one stroke a dab raises (or lowers) the layer to at most the stroke's strength: overlapping
    dabs of one stroke take the larger weight, not the sum, so a slow drag paints what a fast one does
    (as an image brush with accumulation off). A smoothing stroke blends each dab's pixels towards their
    neighbours' mean by its weight."""

    def __init__(self, grid: Grid):
        self.grid = grid
        self.values = np.zeros((grid.resolution, grid.resolution), np.float32)
        self.count = 0  # dabs rasterized
        self._base: np.ndarray | None = None  # the values at the current stroke's start
        self._reach: np.ndarray | None = None  # the stroke's largest weight so far, per pixel
        self._sign = 1.0

    def add(self, dab: Sequence[float]) -> tuple[int, int, int, int] | None:
        """Rasterize one dab (a DAB_COLUMNS row); returns the pixels it changed, or None."""
        x, y, radius, strength, falloff, mode, start = (float(v) for v in dab)
        self.count += 1
        if start or self._base is None:
            self._base, self._reach = None, None
            self._sign = 1.0 if strength >= 0 else -1.0
        rect = self.grid.rect(x, y, radius)
        if rect is None:
            return None
        r0, r1, c0, c1 = rect
        w = dab_weights(self.grid, rect, x, y, radius, int(falloff)) * abs(strength)
        if MODES[int(mode)] == "smooth":
            k = max(1, round(radius / self.grid.pixel / 4))
            big = self.grid.rect(x, y, radius, margin=k)
            b0, b1, d0, d1 = big
            blurred = _box_blur(self.values[b0:b1, d0:d1].astype(np.float64), k)
            blurred = blurred[r0 - b0 : r1 - b0, c0 - d0 : c1 - d0]
            cur = self.values[r0:r1, c0:c1]
            self.values[r0:r1, c0:c1] = cur + (blurred - cur) * np.minimum(w, 1.0)
            return rect
        if self._base is None:
            self._base = self.values.copy()
            self._reach = np.zeros_like(self.values)
        reach = np.maximum(self._reach[r0:r1, c0:c1], w)
        self._reach[r0:r1, c0:c1] = reach
        self.values[r0:r1, c0:c1] = np.clip(self._base[r0:r1, c0:c1] + self._sign * reach, -1.0, 1.0)
        return rect

    def end_stroke(self) -> None:
        """Drop the stroke's working arrays (two field-sized planes); the next dab starts a stroke."""
        self._base = self._reach = None

    def add_all(self, dabs: np.ndarray) -> tuple[int, int, int, int] | None:
        rect = None
        for dab in dabs:
            rect = union(rect, self.add(dab))
        return rect


_RASTERS: dict[int, tuple[tuple, np.ndarray, Raster]] = {}  # layer key -> (grid key, dabs, raster)
_MAX_RASTERS = 8  # at most 16 MB each for a 2048x2048 field


def raster(layer_key: int, dabs: np.ndarray, grid: Grid) -> Raster:
    """The raster of a layer's dabs, cached per layer: a layer whose dabs only grew (a new stroke) is
    rasterized from where it was, anything else (an undo, a cleared layer, a new field grid) from scratch."""
    dabs = np.asarray(dabs, np.float64).reshape(-1, len(DAB_COLUMNS))
    cached = _RASTERS.get(layer_key)
    if cached is not None and cached[0] == grid and len(dabs) >= len(cached[1]):
        old = cached[1]
        if np.array_equal(dabs[: len(old)], old):
            r = cached[2]
            r.add_all(dabs[len(old) :])
            r.end_stroke()
            _RASTERS[layer_key] = (grid, dabs.copy(), r)
            return r
    if len(_RASTERS) >= _MAX_RASTERS and layer_key not in _RASTERS:
        _RASTERS.pop(next(iter(_RASTERS)))
    r = Raster(grid)
    r.add_all(dabs)
    r.end_stroke()
    _RASTERS[layer_key] = (grid, dabs.copy(), r)
    return r


def remember(layer_key: int, dabs: np.ndarray, r: Raster) -> None:
    """Keep a raster built live (during a drag) as the one for these dabs, so the stroke's end does not
    rasterize it again."""
    r.end_stroke()
    _RASTERS[layer_key] = (r.grid, np.asarray(dabs, np.float64).reshape(-1, len(DAB_COLUMNS)).copy(), r)


def forget() -> None:
    _RASTERS.clear()


# ---- the paint on the field ----------------------------------------------------------------------------


@dataclass(frozen=True)
class PaintLayer:
    """An enabled paint layer as the compositor needs it."""

    channel: str
    opacity: float
    values: np.ndarray  # (H, W) float32 in [-1, 1]


def effective_multiplier(multiplier: float, layers: Sequence[PaintLayer]) -> float:
    """The multiplier stored for the shader: the slider's own, floored while coverage is painted."""
    if any(p.channel == "coverage" for p in layers):
        return max(multiplier, MULTIPLIER_FLOOR)
    return multiplier


def pre_planes(fields: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Copies of the paintable planes before the paint (what a live stroke re-applies its paint to)."""
    return {ch: np.array(fields[img][..., i], np.float32) for ch, (img, i) in PAINT_CHANNELS.items()}


def paint_plane(
    channel: str,
    pre: np.ndarray,
    layers: Sequence[PaintLayer],
    multiplier: float,
    rect: tuple[int, int, int, int] | None = None,
) -> np.ndarray:
    """The channel's plane with its paint layers on top, over `rect` (all of it when None).

    Coverage is painted as the shader sees it: the field times the slider's multiplier, clamped, plus the
    paint, clamped, then stored divided by the effective multiplier (which the shader multiplies back).
    Precipitation, type and storm coverage add the paint to the field's value, clamped to 0-1."""
    r0, r1, c0, c1 = rect if rect is not None else (0, pre.shape[0], 0, pre.shape[1])
    value = pre[r0:r1, c0:c1].astype(np.float64)
    mine = [p for p in layers if p.channel == channel]
    if channel == "coverage":
        if not mine:
            return value.astype(np.float32)
        m_eff = effective_multiplier(multiplier, layers)
        cover = np.clip(value * multiplier, 0.0, 1.0)
        for p in mine:
            cover = np.clip(cover + p.opacity * p.values[r0:r1, c0:c1], 0.0, 1.0)
        return (cover / m_eff).astype(np.float32)
    for p in mine:
        value = np.clip(value + p.opacity * p.values[r0:r1, c0:c1], 0.0, 1.0)
    return value.astype(np.float32)


def apply(
    fields: dict[str, np.ndarray], pre: Mapping[str, np.ndarray], layers: Sequence[PaintLayer], multiplier: float
) -> None:
    """Write the paint layers into `fields` (in place) over the whole field."""
    for ch in {p.channel for p in layers}:
        img, i = PAINT_CHANNELS[ch]
        fields[img][..., i] = paint_plane(ch, pre[ch], layers, multiplier)
