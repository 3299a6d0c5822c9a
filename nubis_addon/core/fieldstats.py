"""A field channel's least and greatest value, remembered per array.

A redraw asks for the cloud layers' height ranges (cloudlayers.LayerField.extent) and whether the cirrus
sheet has any cover dozens of times, once for each uniform it packs and each light-volume key it builds.
Each answer is a reduction over a whole field channel: about 0.7 ms at 1024x1024 on the suite's machine,
so a two-layer sky spent about 100 ms of CPU a redraw on them (docs/measurements.md#a-layered-sky).

Fields are replaced, never edited in place, by everything that changes them but a live brush stroke
(blender/sidebar/paint.py), which says so with `edited`. An array's entry goes when the array does. No bpy here.
"""

from __future__ import annotations

import weakref

import numpy as np

# id(array) -> (a weak reference to the array, {(channel, the reduction's name): value})
_REMEMBERED: dict[int, tuple[weakref.ref, dict[tuple[int, str], float]]] = {}


def _forget(key: int, ref: weakref.ref) -> None:
    held = _REMEMBERED.get(key)
    if held is not None and held[0] is ref:
        del _REMEMBERED[key]


def _values(array: np.ndarray) -> dict[tuple[int, str], float]:
    key = id(array)
    held = _REMEMBERED.get(key)
    if held is not None and held[0]() is array:
        return held[1]
    ref = weakref.ref(array, lambda r, k=key: _forget(k, r))
    _REMEMBERED[key] = (ref, {})
    return _REMEMBERED[key][1]


def _reduced(array: np.ndarray, channel: int, reduce) -> float:
    values = _values(array)
    key = (channel, reduce.__name__)
    if key not in values:
        values[key] = float(reduce(array[..., channel]))
    return values[key]


def channel_min(array: np.ndarray, channel: int) -> float:
    """The least value of `array[..., channel]`."""
    return _reduced(array, channel, np.min)


def channel_max(array: np.ndarray, channel: int) -> float:
    """The greatest value of `array[..., channel]`."""
    return _reduced(array, channel, np.max)


def edited(array: np.ndarray) -> None:
    """`array`'s pixels changed in place: its values are found again when next asked for."""
    held = _REMEMBERED.get(id(array))
    if held is not None and held[0]() is array:
        held[1].clear()
