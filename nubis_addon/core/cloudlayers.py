"""A layered sky (docs/layers.md): up to four cloud layers at their own altitudes, each with its own data
field, noise periods, density, wind and weather rules (schema.CLOUD_LAYER_KEYS), under one sky, sun,
light model, march quality and cirrus sheet.

The first layer is the cloudscape's own settings, so a one-layer sky is what it always was; the further
layers are listed after it. Layers may not overlap in altitude: a point of the sky belongs to at most
one layer, which is what lets the density, the light volumes and the bake ask "which layer is here?"
and lets the view march take each layer's segment of a ray on its own. No bpy here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import fieldstats, limits, schema
from .errors import NubisError

MAX_CLOUD_LAYERS = 4  # the first layer included (the cirrus sheet is not one of them)
MAX_ALTITUDE = 20000.0  # metres: the highest a layer's top may reach (the tropopause at the equator is ~17 km)


@dataclass
class CloudLayer:
    """A further cloud layer as a preset holds it: its name, its own settings (schema.CLOUD_LAYER_KEYS, by
    key) and its data field's layer stack ([[cloud_layers.field.layers]])."""

    name: str
    params: dict[str, Any]
    field_layers: list[dict[str, Any]] = field(default_factory=list)
    enabled: bool = True


@dataclass
class LayerField:
    """What the renderer needs of one drawn cloud layer: its own settings by key and its composited field
    (A: coverage, precipitation, top type, bottom type; B: storm coverage, min and max height, density)."""

    name: str
    params: dict[str, Any]
    field_a: np.ndarray
    field_b: np.ndarray

    def extent(self) -> tuple[float, float]:
        """The altitudes its clouds can reach: its base and top, widened by the min/max height channels."""
        bottom, top = self.params["layer_bottom"], self.params["layer_top"]
        thickness = top - bottom
        lo = fieldstats.channel_min(self.field_b, 1)
        hi = fieldstats.channel_max(self.field_b, 2)
        return bottom + min(lo, 0.0) * thickness, bottom + max(hi, 1.0) * thickness

    def reach_channels(self) -> tuple[float, float, float, float]:
        """The greatest top type, min height and max height of its field: how high its clouds can reach
        (nubis_layer_reach in shaders/nubis_march_lib.glsl)."""
        a, b = self.field_a, self.field_b
        return (fieldstats.channel_max(a, 2), fieldstats.channel_max(b, 1), fieldstats.channel_max(b, 2), 0.0)


def own_params(params: dict[str, Any]) -> dict[str, Any]:
    """The values of a layer's own settings taken from a full set of scene settings."""
    return {k: params[k] for k in schema.CLOUD_LAYER_KEYS}


def layer_params(base: dict[str, Any], own: dict[str, Any]) -> dict[str, Any]:
    """A further layer's full settings: the sky's, with the layer's own on top."""
    return {**base, **{k: own[k] for k in schema.CLOUD_LAYER_KEYS if k in own}}


def check_stack(ranges: list[tuple[str, float, float]], where: str = "") -> None:
    """Refuse a stack of layers (name, bottom, top) the sky cannot draw: more than MAX_CLOUD_LAYERS, a layer
    under the ground or above MAX_ALTITUDE, or two layers sharing altitudes. One sentence, what to do."""
    prefix = f"{where}: " if where else ""
    if len(ranges) > MAX_CLOUD_LAYERS:
        raise NubisError(
            f"{prefix}a sky holds at most {MAX_CLOUD_LAYERS} cloud layers, not {len(ranges)}: "
            f"remove {len(ranges) - MAX_CLOUD_LAYERS} of them or merge their fields"
        )
    thinnest = schema.cross_limit("layer_bottom", "layer_top").gap
    for name, bottom, top in ranges:
        limits.check_text(f"{prefix}the name of cloud layer", name)
        if bottom < 0.0:
            raise NubisError(
                f"{prefix}cloud layer '{name}' starts under the ground ({bottom:g} m): raise its base to 0 m or more"
            )
        if top > MAX_ALTITUDE:
            raise NubisError(
                f"{prefix}cloud layer '{name}' reaches {top:g} m, above the {MAX_ALTITUDE:g} m a layer may reach: "
                "lower its top (the cirrus sheet draws the highest clouds)"
            )
        # The gap as a scene stores it, in float32: within one float32 step of the altitude (0.5 mm at
        # 5 km), so a file the preset check takes renders, and one it refuses does not.
        if top - bottom < thinnest - float(np.spacing(np.float32(max(abs(top), abs(bottom))))):
            raise NubisError(
                f"{prefix}cloud layer '{name}' has its top ({top!r} m) less than {thinnest:g} m above its base "
                f"({bottom!r} m): raise its top"
            )
    ordered = sorted(ranges, key=lambda r: r[1])
    for (lo_name, _b, lo_top), (hi_name, hi_bottom, _t) in zip(ordered, ordered[1:], strict=False):
        if hi_bottom < lo_top:
            raise NubisError(
                f"{prefix}cloud layers '{lo_name}' and '{hi_name}' overlap by {lo_top - hi_bottom:g} m "
                f"({lo_name} reaches {lo_top:g} m, {hi_name} starts at {hi_bottom:g} m): layers may not share "
                "altitudes, so move one or merge them into one layer"
            )


def disjoint_extents(layers: list[LayerField]) -> list[tuple[float, float]]:
    """Each layer's extent (LayerField.extent), clipped so no two share an altitude: the min/max height
    channels may widen a layer past its base or top, but never into a neighbour's base-to-top range.
    In the layers' own order."""
    nominal = [(p.params["layer_bottom"], p.params["layer_top"]) for p in layers]
    out = []
    for i, layer in enumerate(layers):
        lo, hi = layer.extent()
        bottom, top = nominal[i]
        for j, (other_bottom, other_top) in enumerate(nominal):
            if j == i:
                continue
            if other_top <= bottom:
                lo = max(lo, other_top)
            elif other_bottom >= top:
                hi = min(hi, other_bottom)
        out.append((lo, hi))
    return out


def new_layer_params(base: dict[str, Any], ranges: list[tuple[float, float]]) -> dict[str, Any]:
    """A new layer's own settings: the sky's first layer's, moved to free altitudes above the highest layer
    (or below the lowest when there is no room above), as thick as the first layer up to the room there is."""
    own = own_params(base)
    thickness = base["layer_top"] - base["layer_bottom"]
    highest = max(top for _b, top in ranges)
    lowest = min(bottom for bottom, _t in ranges)
    gap = 0.25 * thickness
    if highest + gap + min(thickness, 500.0) <= MAX_ALTITUDE:
        bottom = highest + gap
        own.update(layer_bottom=bottom, layer_top=min(bottom + thickness, MAX_ALTITUDE))
    elif lowest - gap >= 100.0:
        top = lowest - gap
        own.update(layer_bottom=max(0.0, top - thickness), layer_top=top)
    else:
        raise NubisError("no free altitudes for another cloud layer: make the layers thinner or remove one")
    return own
