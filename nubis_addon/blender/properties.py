"""The property groups, generated from the settings schema (core/schema.py): names, ranges, units,
soft ranges, tooltips and what a change triggers all come from there."""

from __future__ import annotations

import bpy
from bpy.props import (
    BoolProperty,
    CollectionProperty,
    EnumProperty,
    FloatProperty,
    FloatVectorProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)

from ..core import schema
from . import events

# Blender keeps pointers to enum item strings: build each list once, at import, and keep it.
_ENUM_ITEMS: dict[str, list[tuple[str, str, str]]] = {}


def enum_id(value: str) -> str:
    """A preset's enum value as Blender's identifier (upper case)."""
    return value.upper()


def _enum_items(s: schema.Setting) -> list[tuple[str, str, str]]:
    key = f"{s.group}.{s.key}"
    if key not in _ENUM_ITEMS:
        _ENUM_ITEMS[key] = [(enum_id(v), label, desc or label) for v, label, desc in s.items]
    return _ENUM_ITEMS[key]


def _is_sun(_self, obj) -> bool:
    return obj.type == "LIGHT" and obj.data.type == "SUN"


def _is_empty(_self, obj) -> bool:
    return obj.type == "EMPTY"


_OBJECT_POLLS = {"SUN": _is_sun, "EMPTY": _is_empty}


def _float_kw(s: schema.Setting) -> dict:
    kw = {"default": float(s.default)}
    for name in ("min", "max", "soft_min", "soft_max"):
        if getattr(s, name) is not None:
            kw[name] = getattr(s, name)
    if s.unit == "ROTATION":
        kw["subtype"] = "ANGLE"
    elif s.unit != "NONE":
        kw["unit"] = s.unit
    return kw


def prop_for(s: schema.Setting):
    """The bpy property of one setting."""
    common = {"name": s.label, "description": s.description}
    key = s.key if s.group == "scene" else ""
    update = {"update": events.update_callback(s.trigger, key)} if s.trigger != "none" else {}
    if s.kind == "float":
        return FloatProperty(**common, **update, **_float_kw(s))
    if s.kind == "int":
        kw = {k: int(getattr(s, k)) for k in ("min", "max", "soft_min", "soft_max") if getattr(s, k) is not None}
        return IntProperty(**common, **update, default=int(s.default), **kw)
    if s.kind == "bool":
        return BoolProperty(**common, **update, default=s.default)
    if s.kind == "enum":
        return EnumProperty(**common, **update, items=_enum_items(s), default=enum_id(s.default))
    if s.kind == "string":
        return StringProperty(**common, **update, default=s.default)
    if s.kind in ("vector", "color"):
        kw = {"size": s.size, "default": tuple(s.default)}
        if s.kind == "color":
            kw["subtype"] = "COLOR"
        for name in ("min", "max", "soft_min", "soft_max"):
            if getattr(s, name) is not None:
                kw[name] = getattr(s, name)
        return FloatVectorProperty(**common, **update, **kw)
    if s.kind == "image":
        return PointerProperty(**common, **update, type=bpy.types.Image)
    if s.kind == "object":
        poll = _OBJECT_POLLS.get(s.object_type)
        return PointerProperty(**common, **update, type=bpy.types.Object, **({"poll": poll} if poll else {}))
    raise TypeError(f"{s.key}: no property for kind {s.kind}")


def _annotations(settings, skip=()) -> dict:
    return {s.key: prop_for(s) for s in settings if s.key not in skip}


class NubisPaintDab(bpy.types.PropertyGroup):
    """One brush dab of a paint layer, in world metres (core/paint.py: DAB_COLUMNS)."""

    x: FloatProperty(name="X", subtype="DISTANCE", unit="LENGTH")
    y: FloatProperty(name="Y", subtype="DISTANCE", unit="LENGTH")
    radius: FloatProperty(name="Radius", min=0.0, subtype="DISTANCE", unit="LENGTH")
    strength: FloatProperty(name="Strength", min=-1.0, max=1.0, description="Signed: negative subtracts")
    falloff: IntProperty(name="Falloff", min=0, description="Index into core/paint.FALLOFFS")
    mode: IntProperty(name="Mode", min=0, description="Index into core/paint.MODES")
    start: BoolProperty(name="Stroke Start", description="The first dab of a stroke")


def _layer_annotations() -> dict:
    ann = _annotations(schema.LAYER)
    # A paint layer's strokes: plain data, so Blender saves and undoes them like any setting.
    ann["dabs"] = CollectionProperty(type=NubisPaintDab)
    return ann


NubisFieldLayer = type(
    "NubisFieldLayer",
    (bpy.types.PropertyGroup,),
    {"__annotations__": _layer_annotations(), "__doc__": "One layer of the data-field stack"},
)

# The storm's Empty holds its position (x, y are preset-only).
NubisStorm = type(
    "NubisStorm",
    (bpy.types.PropertyGroup,),
    {"__annotations__": _annotations(schema.STORM, skip=("x", "y")), "__doc__": "A superstorm stencil"},
)


def _scene_annotations() -> dict:
    ann = _annotations(schema.SCENE)
    ann["layers"] = CollectionProperty(type=NubisFieldLayer)
    ann["storms"] = CollectionProperty(type=NubisStorm)
    return ann


NubisSceneSettings = type(
    "NubisSceneSettings",
    (bpy.types.PropertyGroup,),
    {"__annotations__": _scene_annotations(), "__doc__": "Nubis cloudscape settings of a scene"},
)

CLASSES = (NubisPaintDab, NubisFieldLayer, NubisStorm, NubisSceneSettings)


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.nubis = PointerProperty(type=NubisSceneSettings)


def unregister() -> None:
    del bpy.types.Scene.nubis
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
