"""Paint onto the field: a paint layer's dabs rasterized into a coverage of the field's grid (the rasters
kept for the next composite), what a raster costs before it is made, and the paint laid on a cloud
layer's field planes (docs/painting.md)."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from . import console, paint
from .errors import NubisError


def dab_weights(grid: paint.Grid, rect, x: float, y: float, radius: float, falloff: int) -> np.ndarray:
    """The brush's weight (0-1) over `rect`: 1 at the centre, 0 from the radius on."""
    r0, r1, c0, c1 = rect
    cx, cy = grid.to_pixel(x, y)
    dx = (np.arange(c0, c1) - cx)[None, :]
    dy = (np.arange(r0, r1) - cy)[:, None]
    d = np.sqrt(dx * dx + dy * dy) * (grid.pixel / radius)
    t = np.clip(1.0 - d, 0.0, 1.0)
    if paint.FALLOFFS[falloff] == "smooth":
        return t * t * (3.0 - 2.0 * t)
    if paint.FALLOFFS[falloff] == "linear":
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

    def __init__(self, grid: paint.Grid):
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
        # Dabs the checks (check_dab) keep out, should a script write them into a layer's strokes: a radius
        # under RADIUS_MIN divides by (float32's) zero, one past RADIUS_MAX or a point beyond the float range
        # paints nothing sensible. They are skipped.
        if not (
            paint.RADIUS_MIN <= radius <= paint.RADIUS_MAX and abs(x) < paint.NUMBER_MAX and abs(y) < paint.NUMBER_MAX
        ):
            return None
        if math.isnan(strength):
            return None
        rect = self.grid.rect(x, y, radius)
        if rect is None:
            return None
        r0, r1, c0, c1 = rect
        w = dab_weights(self.grid, rect, x, y, radius, int(falloff)) * abs(strength)
        if paint.MODES[int(mode)] == "smooth":
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
            rect = paint.union(rect, self.add(dab))
        return rect


# layer key -> (grid, dabs, raster). A layer key is a number the caller gives each layer (blender/scene/cloudstate.py
# mints them), never a Blender pointer: core holds no Blender identity. A cached raster is used only for the
# dabs it was made from, so a key that comes to name another layer costs a raster from scratch, no more.
_RASTERS: dict[int, tuple[paint.Grid, np.ndarray, Raster]] = {}


_MAX_RASTERS = 8  # at most 16 MB each for a 2048x2048 field


def raster(layer_key: int, dabs: np.ndarray, grid: paint.Grid) -> Raster:
    """The raster of a layer's dabs, cached per layer key: a layer whose dabs only grew (a new stroke) is
    rasterized from where it was, anything else (an undo, a cleared layer, a new field grid) from scratch.
    A long one is announced on the console first (notice), one holding too much memory refused (check_cost)."""
    dabs = np.asarray(dabs, np.float64).reshape(-1, len(paint.DAB_COLUMNS))
    todo, r = _todo(layer_key, dabs, grid)
    cost = raster_cost(todo, grid)
    check_cost(cost)
    line = notice(cost)
    if line:
        console.current().line(f"Nubis: {line}")
    if r is None:
        if len(_RASTERS) >= _MAX_RASTERS and layer_key not in _RASTERS:
            _RASTERS.pop(next(iter(_RASTERS)))
        r = Raster(grid)
    r.add_all(todo)
    r.end_stroke()
    _RASTERS[layer_key] = (grid, dabs.copy(), r)
    return r


def remember(layer_key: int, dabs: np.ndarray, r: Raster) -> None:
    """Keep a raster built live (during a drag) as the one for these dabs, so the stroke's end does not
    rasterize it again."""
    r.end_stroke()
    _RASTERS[layer_key] = (r.grid, np.asarray(dabs, np.float64).reshape(-1, len(paint.DAB_COLUMNS)).copy(), r)


def forget() -> None:
    _RASTERS.clear()


#
# Measured on the development machine (2 cores, shared; Blender 5.3's Python and numpy) by rasterizing random
# dabs on 512- to 4096-pixel fields (docs/painting.md#long-composites): 1,000,000 dabs of 2500 m on the
# default field (70 km, 512 pixels) took 33 s, 34 us a dab. A dab costs a fixed part (Python's work around
# numpy), a part per pixel of its rectangle (more once the rectangle outgrows the caches, above 256x256
# pixels: 15 ns measured against 3-6), twenty times more for a smoothing dab (its blur), and a stroke's
# first dab two field planes (the stroke's working arrays: 1.2 ns a pixel, 17 s for 3000 strokes at 2048).
DAB_S = 32e-6


PIXEL_S = 5e-9


BIG_PIXEL_S = 15e-9


BIG_RECT = 256 * 256


SMOOTH_FACTOR = 20.0


STROKE_PIXEL_S = 1.2e-9


NOTICE_S = 2.0  # a composite of paint longer than this is announced first


# bytes: the arrays a composite of paint holds at once (dabs, planes, one dab's rectangle), beyond which it is
# refused. A full layer (MAX_DABS) on the finest field needs about 1.2 GB; this takes several full layers.
MEMORY_MAX = 8 * 2**30


@dataclass(frozen=True)
class Cost:
    """What rasterizing some dabs takes: how many, about how long, and the arrays' bytes at the peak."""

    dabs: int
    seconds: float
    bytes: int

    def __add__(self, other: Cost) -> Cost:
        return Cost(self.dabs + other.dabs, self.seconds + other.seconds, self.bytes + other.bytes)


def raster_cost(dabs: np.ndarray, grid: paint.Grid) -> Cost:
    """The cost of rasterizing `dabs` on `grid`, from their count, their rectangles' areas in pixels and
    their strokes (bpy-free arithmetic: nothing is rasterized)."""
    dabs = np.asarray(dabs, np.float64).reshape(-1, len(paint.DAB_COLUMNS))
    res = grid.resolution
    radius_px = np.abs(np.nan_to_num(dabs[:, paint.COLUMN["radius"]], posinf=0.0)) / grid.pixel
    side = np.minimum(2.0 * np.ceil(radius_px) + 2.0, res)
    smooth = dabs[:, paint.COLUMN["mode"]] == paint.MODES.index("smooth")
    area = side * side
    per_pixel = np.where(area > BIG_RECT, BIG_PIXEL_S, PIXEL_S) * np.where(smooth, SMOOTH_FACTOR, 1.0)
    strokes = int(np.count_nonzero((dabs[:, paint.COLUMN["start"]] == 1) & ~smooth)) + (len(dabs) > 0)
    seconds = len(dabs) * DAB_S + float((area * per_pixel).sum()) + strokes * res * res * STROKE_PIXEL_S
    # The dabs read from Blender and the cached copy, three planes (the values, the stroke's base and reach),
    # and the largest rectangle's float64 temporaries (about six at once).
    peak = float(side.max()) ** 2 * 8 * 6 if len(dabs) else 0.0
    return Cost(len(dabs), seconds, int(dabs.nbytes * 2 + 3 * res * res * 4 + peak))


def _todo(layer_key: int, dabs: np.ndarray, grid: paint.Grid) -> tuple[np.ndarray, Raster | None]:
    """The dabs `raster` has still to rasterize for this layer, and the cached raster they add to (None:
    from scratch)."""
    cached = _RASTERS.get(layer_key)
    if cached is not None and cached[0] == grid and len(dabs) >= len(cached[1]):
        old = cached[1]
        if np.array_equal(dabs[: len(old)], old):
            return dabs[len(old) :], cached[2]
    return dabs, None


def composite_cost(layers: Iterable[tuple[int, np.ndarray]], grid: paint.Grid) -> Cost:
    """What rasterizing these (layer key, dabs) takes now, the cached rasters counted as done."""
    total = Cost(0, 0.0, 0)
    for key, dabs in layers:
        todo, _cached = _todo(key, np.asarray(dabs, np.float64).reshape(-1, len(paint.DAB_COLUMNS)), grid)
        total += raster_cost(todo, grid)
    return total


def notice(cost: Cost) -> str | None:
    """The line announcing a long composite, or None for a short one."""
    if cost.seconds < NOTICE_S:
        return None
    return f"compositing {cost.dabs:,} dabs takes about {cost.seconds:.0f} s"


def check_cost(cost: Cost) -> None:
    """Rule: a composite of paint holds at most MEMORY_MAX bytes of arrays."""
    if cost.bytes > MEMORY_MAX:
        raise NubisError(
            f"compositing {cost.dabs:,} dabs would hold about {cost.bytes / 2**30:.1f} GB, over the "
            f"{MEMORY_MAX / 2**30:.0f} GB Nubis allows: clear or disable paint layers, or lower the field resolution"
        )


@dataclass(frozen=True)
class PaintLayer:
    """An enabled paint layer as the compositor needs it."""

    channel: str
    opacity: float
    values: np.ndarray  # (H, W) float32 in [-1, 1]


def effective_multiplier(multiplier: float, layers: Sequence[PaintLayer]) -> float:
    """The multiplier stored for the shader: the slider's own, floored while coverage is painted."""
    if any(p.channel == "coverage" for p in layers):
        return max(multiplier, paint.MULTIPLIER_FLOOR)
    return multiplier


def pre_planes(fields: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Copies of the paintable planes before the paint (what a live stroke re-applies its paint to)."""
    return {ch: np.array(fields[img][..., i], np.float32) for ch, (img, i) in paint.PAINT_CHANNELS.items()}


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
        img, i = paint.PAINT_CHANNELS[ch]
        fields[img][..., i] = paint_plane(ch, pre[ch], layers, multiplier)
