"""A cloud layer's data field, composited in one pipeline (GDC22's Data Field Generator; docs/painting.md,
docs/layers.md): the layer stack, the weather rules, the coverage slider's multiplier found from the field
before the storms, the superstorm stencils, then the artist's strokes. The cloudscape's own layer and every
further cloud layer go through it alike; blender/scene/cloudstate.py gathers the inputs and stores what it returns.
No bpy here."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import coverage, paintraster
from . import fields as fieldgen
from . import storms as stormgen


@dataclass
class StackInputs:
    """What one layer's composite reads."""

    layers: list[dict[str, Any]]  # its field layers, top of the stack first (datafield.layer_to_dict)
    params: Mapping[str, Any]  # its full settings
    images: Mapping[str, np.ndarray] = field(default_factory=dict)  # the image layers' pixels by image name
    rain: float | None = None  # the rain rule's cumulonimbus top type, None with the rule off
    horizon: float | None = None  # the horizon rule's start (metres), None with the rule off
    camera_xy: tuple[float, float] = (0.0, 0.0)  # where the horizon rule measures from
    cover: float = 0.5  # the Coverage slider: the fraction of the sky covered, seen from above
    painted: Sequence[paintraster.PaintLayer] = ()  # its enabled paint layers, rasterized
    has_paint: bool = False  # whether its stack holds paint layers at all (a live stroke re-applies onto pre)
    storms: Sequence[stormgen.Storm] = ()  # superstorm stencils (the first layer's: GDC22)
    progress: Callable[[float], None] | None = None


@dataclass
class StackResult:
    planes: dict[str, np.ndarray]  # the field images' planes ("a", "b", "c")
    cover_hist: tuple[np.ndarray, np.ndarray]  # the coverage channel's histogram before the storms
    multiplier: float  # the slider's multiplier that covers `cover` of the sky
    stored_multiplier: float  # what the shader multiplies by: floored while coverage is painted
    pre_paint: tuple[dict[str, np.ndarray], float] | None  # the planes before the paint, and the multiplier


def composite_stack(inputs: StackInputs) -> StackResult:
    """The layer's field planes, and the coverage multiplier the shader is to use with them."""
    result = fieldgen.composite(inputs.layers, inputs.params, inputs.images, inputs.progress)
    if inputs.rain is not None:
        fieldgen.apply_rain_rule(result, inputs.rain)
    if inputs.horizon is not None:
        fieldgen.apply_horizon_rule(result, inputs.params, inputs.camera_xy, inputs.horizon)
    # Coverage is the fraction of the sky covered: the multiplier on this field that gives it, found from
    # the field before the storms (a superstorm's stencil is its own system, GDC22: counting it would thin
    # the fair-weather clouds everywhere else).
    hist = coverage.histogram(result["a"][..., 0])
    m = coverage.multiplier_for(inputs.cover, hist)
    # GDC22: superstorm stencils override the field inside their radius, after everything else
    # (docs/sources.md#storm-stencil).
    if inputs.storms:
        stormgen.apply_storms(result, inputs.params, inputs.storms)
    # The strokes act last, coverage on top of the slider's cover (core/paint.py), from the planes before
    # them, which are kept so a live stroke re-applies its paint to a rectangle only.
    pre = None
    if inputs.has_paint or inputs.painted:
        planes = paintraster.pre_planes(result)
        paintraster.apply(result, planes, inputs.painted, m)
        pre = (planes, m)
    return StackResult(result, hist, m, paintraster.effective_multiplier(m, inputs.painted), pre)
