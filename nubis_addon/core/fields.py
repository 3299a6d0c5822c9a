"""The Nubis Data Field generator (GDC22): a stack of layers composited into the field images.

Images (docs/sources.md#field-layout): A = coverage, precipitation, top type, bottom type;
B = storm coverage, min height, max height (fractions of the layer, may exceed 1), density multiplier;
cirrus = cirrus coverage, cirrus type. Arrays are (H, W, 4) float32, bottom row first like Blender images.
The field is not animated by wind (GDC22): only the 3D noise moves.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from .errors import NubisError
from .noise import world_fbm_2d

CHANNELS: dict[str, tuple[str, int]] = {
    "coverage": ("a", 0),
    "precipitation": ("a", 1),
    "type": ("a", 2),
    "bottom_type": ("a", 3),
    "storm": ("b", 0),
    "min_height": ("b", 1),
    "max_height": ("b", 2),
    "density": ("b", 3),
    "cirrus_coverage": ("cirrus", 0),
    "cirrus_type": ("cirrus", 1),
}
# Stratocumulus, flat bases, the full layer height, unit density, no cirrus.
BASE_VALUES = {"a": (0.0, 0.0, 0.5, 0.0), "b": (0.0, 0.0, 1.0, 1.0), "cirrus": (0.0, 0.0, 0.0, 0.0)}


def base_fields(resolution: int) -> dict[str, np.ndarray]:
    return {
        k: np.broadcast_to(np.asarray(v, np.float32), (resolution, resolution, 4)).copy()
        for k, v in BASE_VALUES.items()
    }


def pixel_centres(params: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """World X and Y of every field pixel's centre, each (H, W), bottom row first."""
    res, size = params["field_resolution"], params["field_size"]
    t = (np.arange(res, dtype=np.float64) + 0.5) / res - 0.5
    xs = params["field_origin_x"] + t * size
    ys = params["field_origin_y"] + t * size
    return np.meshgrid(xs, ys)


_CACHE: dict[tuple, np.ndarray] = {}
_CACHE_SIZE = 16


def _cache_key(layer: Mapping[str, Any], xs: np.ndarray, ys: np.ndarray) -> tuple:
    shape_keys = ("kind", "scale", "seed", "octaves", "value", "gradient", "angle", "radius")
    return (
        tuple(layer[k] for k in shape_keys),
        tuple(layer["center"]),
        xs.shape,
        float(xs[0, 0]),
        float(xs[0, -1]),
        float(ys[0, 0]),
        float(ys[-1, 0]),
    )


def layer_values(layer: Mapping[str, Any], xs: np.ndarray, ys: np.ndarray, images: Mapping[str, np.ndarray]):
    """A layer's raw values over the field. Procedural layers are cached, so that re-compositing after a
    brush stroke on an image layer only recomputes that image."""
    if layer["kind"] == "image":
        return _image_values(layer, xs.shape, images)
    key = _cache_key(layer, xs, ys)
    if key not in _CACHE:
        if len(_CACHE) >= _CACHE_SIZE:
            _CACHE.pop(next(iter(_CACHE)))
        _CACHE[key] = _procedural_values(layer, xs, ys)
        _CACHE[key].setflags(write=False)
    return _CACHE[key]


def _procedural_values(layer: Mapping[str, Any], xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    kind = layer["kind"]
    if kind in ("perlin", "worley", "perlin_worley"):
        u, v = xs / layer["scale"], ys / layer["scale"]
        seed, octaves = layer["seed"], layer["octaves"]
        if kind == "perlin":
            return world_fbm_2d("perlin", u, v, octaves, seed)
        if kind == "worley":
            return world_fbm_2d("worley", u, v, octaves, seed)
        # GPU Pro 7, S15: Worley dilates the Perlin, keeping its connectedness with billowy rims
        # (docs/sources.md#perlin-worley).
        p = world_fbm_2d("perlin", u, v, octaves, seed)
        w = world_fbm_2d("worley", u * 2, v * 2, max(1, octaves - 1), seed + 101)
        return np.clip((p - (w - 1.0)) / (2.0 - w), 0.0, 1.0)
    if kind == "constant":
        return np.full(xs.shape, layer["value"])
    if kind == "gradient":
        cx, cy = layer["center"]
        if layer["gradient"] == "radial":
            return np.clip(1.0 - np.hypot(xs - cx, ys - cy) / layer["radius"], 0.0, 1.0)
        a = np.radians(layer["angle"])
        along = (xs - cx) * np.cos(a) + (ys - cy) * np.sin(a)
        return np.clip(0.5 + along / (2.0 * layer["radius"]), 0.0, 1.0)
    raise NubisError(f"field layer '{layer['name']}' has an unknown kind '{kind}'")


def _image_values(layer: Mapping[str, Any], shape: tuple[int, int], images: Mapping[str, np.ndarray]) -> np.ndarray:
    name = layer["image"]
    if name not in images:
        raise NubisError(f"field layer '{layer['name']}' uses the image '{name}', which is missing: load or paint it")
    img = np.asarray(images[name], dtype=np.float64)
    if img.ndim == 3:
        img = img[..., 0]
    if img.size == 0:
        raise NubisError(f"the image '{name}' of field layer '{layer['name']}' is empty: paint or reload it")
    if not np.all(np.isfinite(img)):
        raise NubisError(
            f"the image '{name}' of field layer '{layer['name']}' holds NaN or infinite pixels: repaint it"
        )
    # Bilinear resample of the painted image onto the field's pixel grid.
    h, w = img.shape
    ty = np.clip((np.arange(shape[0]) + 0.5) / shape[0] * h - 0.5, 0, h - 1)
    tx = np.clip((np.arange(shape[1]) + 0.5) / shape[1] * w - 0.5, 0, w - 1)
    y0, x0 = np.floor(ty).astype(int), np.floor(tx).astype(int)
    y1, x1 = np.minimum(y0 + 1, h - 1), np.minimum(x0 + 1, w - 1)
    fy, fx = (ty - y0)[:, None], (tx - x0)[None, :]
    top = img[y0][:, x0] * (1 - fx) + img[y0][:, x1] * fx
    bot = img[y1][:, x0] * (1 - fx) + img[y1][:, x1] * fx
    return top * (1 - fy) + bot * fy


def _remap(values: np.ndarray, window) -> np.ndarray:
    in_lo, in_hi, out_lo, out_hi = window
    t = np.clip((values - in_lo) / (in_hi - in_lo), 0.0, 1.0)
    return out_lo + t * (out_hi - out_lo)


def _blend(dst: np.ndarray, src: np.ndarray, mode: str, alpha: np.ndarray | float) -> np.ndarray:
    if mode == "replace":
        target = src
    elif mode == "add":
        target = dst + src
    elif mode == "multiply":
        target = dst * src
    elif mode == "min":
        target = np.minimum(dst, src)
    elif mode == "max":
        target = np.maximum(dst, src)
    else:
        raise NubisError(f"unknown blend mode '{mode}': use replace, add, multiply, min or max")
    return dst + (target - dst) * alpha


# Seconds per million field pixels and octave of the procedural noises, and per million pixels of any
# layer (remap and blend), measured on the 2-core test machine (docs/measurements.md#machine); a faster machine only
# finishes early.
_NOISE_COST = {"perlin": 0.25, "worley": 0.18, "perlin_worley": 0.40}
_LAYER_COST = 0.03


def composite_seconds(layers: list[Mapping[str, Any]], resolution: int) -> float:
    """About how long :func:`composite` takes for this stack (ignoring its cache of unchanged layers)."""
    mpx = resolution * resolution / 1e6
    total = 0.0
    for layer in layers:
        if layer.get("enabled", True):
            total += mpx * (_LAYER_COST + _NOISE_COST.get(layer.get("kind", ""), 0.0) * layer.get("octaves", 1))
    return total


def composite(
    layers: list[Mapping[str, Any]],
    params: Mapping[str, Any],
    images: Mapping[str, np.ndarray] | None = None,
    progress: Callable[[float], None] | None = None,
) -> dict[str, np.ndarray]:
    """Composite the layer stack, top of the list first, into the field images; ``progress`` gets the
    fraction done after each layer."""
    images = images or {}
    fields = base_fields(params["field_resolution"])
    xs, ys = pixel_centres(params)
    raw: dict[str, np.ndarray] = {}
    for i, layer in enumerate(layers):
        if progress is not None and i:
            progress(i / len(layers))
        if not layer["enabled"] or layer["kind"] == "paint":
            continue  # paint layers act after the stack, the rules and the storms (core/paint.py)
        values = _remap(layer_values(layer, xs, ys, images), layer["remap"])
        raw[layer["name"]] = values
        channel = layer["channel"]
        if channel == "none":
            continue
        alpha = layer["opacity"]
        if layer["mask"]:
            if layer["mask"] not in raw:
                raise NubisError(
                    f"field layer '{layer['name']}' is masked by '{layer['mask']}', an unknown layer above it"
                )
            mask = raw[layer["mask"]]
            alpha = alpha * (1.0 - mask if layer["invert_mask"] else mask)
        image, index = CHANNELS[channel]
        plane = fields[image][..., index].astype(np.float64)
        fields[image][..., index] = _blend(plane, values, layer["blend"], alpha)
    for arr in fields.values():
        np.nan_to_num(arr, copy=False)
    clamp_fields(fields)
    if progress is not None:
        progress(1.0)
    return fields


def clamp_fields(fields: dict[str, np.ndarray]) -> None:
    """Probabilities stay in [0, 1]; heights and the density multiplier may exceed 1 but not go negative."""
    np.clip(fields["a"], 0.0, 1.0, out=fields["a"])
    np.clip(fields["cirrus"], 0.0, 1.0, out=fields["cirrus"])
    np.clip(fields["b"][..., 0], 0.0, 1.0, out=fields["b"][..., 0])
    np.clip(fields["b"][..., 1:], 0.0, 8.0, out=fields["b"][..., 1:])
    bad = fields["b"][..., 2] < fields["b"][..., 1] + 0.01
    fields["b"][..., 2][bad] = fields["b"][..., 1][bad] + 0.01


def apply_rain_rule(fields: dict[str, np.ndarray], cumulonimbus_top: float = 1.0) -> None:
    """GPU Pro 7, S15: where it rains, clouds turn to cumulonimbus, covering at least 70 %
    (docs/sources.md#rain-rule).

    ``cumulonimbus_top`` is the raised max-height fraction for full rain (e.g. 8 km in a 1.5-4 km layer)."""
    a, b = fields["a"], fields["b"]
    rain = a[..., 1]
    a[..., 0] = a[..., 0] + (np.maximum(a[..., 0], 0.7) - a[..., 0]) * rain
    a[..., 2] = a[..., 2] + (1.0 - a[..., 2]) * rain
    b[..., 2] = b[..., 2] + (np.maximum(b[..., 2], cumulonimbus_top) - b[..., 2]) * rain


def apply_horizon_rule(
    fields: dict[str, np.ndarray], params: Mapping[str, Any], center: tuple[float, float], start: float = 15000.0
) -> None:
    """S15: from 15 km out to the draw radius, blend towards cumulus at about 50 % coverage, so the
    horizon always holds clouds that poke above the mountains (docs/sources.md#horizon-rule)."""
    xs, ys = pixel_centres(params)
    end = max(params["layer_draw_radius"], start + 1.0)
    t = np.clip((np.hypot(xs - center[0], ys - center[1]) - start) / (end - start), 0.0, 1.0)
    t = t * t * (3 - 2 * t)
    a = fields["a"]
    a[..., 0] = a[..., 0] + (0.5 - a[..., 0]) * t
    a[..., 2] = a[..., 2] + (1.0 - a[..., 2]) * t
