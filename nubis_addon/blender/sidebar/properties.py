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

from ...core import paint, schema
from ..host import ui
from ..live import events

# Blender keeps pointers to enum item strings: build each list once, at import, and keep it.
_ENUM_ITEMS: dict[str, list[tuple[str, str, str]]] = {}
_CALLBACK_ITEMS: list[list[tuple]] = []


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


def _common(s: schema.Setting, owner: str = "scene") -> tuple[dict, dict]:
    """A setting's name and tooltip, and its update callback (none when a change triggers nothing);
    `owner` "cloud_layer" for a further cloud layer's own copy of a scene setting."""
    key = s.key if s.group == "scene" else ""
    callback = events.cloud_layer_callback if owner == "cloud_layer" else events.update_callback
    update = {"update": callback(s.trigger, key)} if s.trigger != "none" else {}
    return {"name": s.label, "description": s.description}, update


def prop_for(s: schema.Setting, owner: str = "scene"):
    """The bpy property of one setting (of the scene, or of a further cloud layer: `owner`)."""
    common, update = _common(s, owner)
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


def _dab_prop(column: paint.DabColumn):
    """The bpy property of one dab column (core/paint.py: DABS)."""
    kw = {"name": column.label, "description": column.description}
    if column.kind == "bool":
        return BoolProperty(**kw)
    bounds = {b: getattr(column, b) for b in ("min", "max") if getattr(column, b) is not None}
    if column.kind == "int":
        return IntProperty(**kw, **{b: int(v) for b, v in bounds.items()})
    if column.metres:
        kw.update(subtype="DISTANCE", unit="LENGTH")
    return FloatProperty(**kw, **{b: float(v) for b, v in bounds.items()})


NubisPaintDab = type(
    "NubisPaintDab",
    (bpy.types.PropertyGroup,),
    {
        "__annotations__": {column.name: _dab_prop(column) for column in paint.DABS},
        "__doc__": "One brush dab of a paint layer, in world metres (core/paint.py: DABS)",
    },
)


def _layer_channel_items(s: schema.Setting):
    """The items callback of a field layer's channel: a paint layer offers the channels a brush paints
    (core/paint.py: PAINT_CHANNELS), any other layer every channel. Each item keeps its position in the
    schema's list as its number, the number Blender stores, so files and presets read as they did."""
    every = [(enum_id(v), label, desc or label, number) for number, (v, label, desc) in enumerate(s.items)]
    paintable = [item for item, v in zip(every, s.choices, strict=True) if v in paint.PAINT_CHANNELS]
    # A paint layer holding a channel no brush paints (its kind was changed after its channel) lists that
    # channel too, so it still reads as itself and the composite says what to change (check_paint_channel).
    holding = {item[3]: sorted([*paintable, item], key=lambda i: i[3]) for item in every if item not in paintable}
    # Blender keeps pointers to the strings an items callback returns: these lists live as long as the add-on.
    _CALLBACK_ITEMS.extend([every, paintable, *holding.values()])
    default = s.choices.index(s.default)

    def items(layer, _context):
        if layer.kind != "PAINT":
            return every
        return holding.get(layer.get(s.name, default), paintable)

    return items, default


def _layer_channel_prop(s: schema.Setting):
    """A field layer's channel (core/schema.py) with a paint layer's menu narrowed (_layer_channel_items)."""
    common, update = _common(s)
    items, default = _layer_channel_items(s)
    return EnumProperty(**common, **update, items=items, default=default)


def _layer_annotations() -> dict:
    ann = _annotations(schema.FIELD_LAYER)
    ann["channel"] = _layer_channel_prop(schema.FIELD_LAYER_BY_NAME["channel"])
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


def _cloud_layer_annotations() -> dict:
    """A further cloud layer (core/cloudlayers.py): its own copy of the settings a layer holds, under the
    scene's keys, so the sidebar draws it with the panels' own code; its field stack and images."""
    redraw = events.update_callback("redraw")
    ann = {s.key: prop_for(s, "cloud_layer") for s in schema.CLOUD_LAYER_SETTINGS}
    ann["name"] = StringProperty(name="Name", description="The cloud layer's name", default="Layer")
    ann["enabled"] = BoolProperty(name="Enabled", description="Draw this cloud layer", default=True, update=redraw)
    ann["solo"] = BoolProperty(
        name="Solo", description="Draw only the soloed cloud layers while any is soloed", update=redraw
    )
    ann["layers"] = CollectionProperty(type=NubisFieldLayer)
    ann["active_layer"] = IntProperty(name="Active Field Layer", min=0)
    for which, label in (("field_a", "Field A"), ("field_b", "Field B")):
        ann[which] = PointerProperty(name=label, description=f"This cloud layer's {label}", type=bpy.types.Image)
    return ann


NubisCloudLayer = type(
    "NubisCloudLayer",
    (bpy.types.PropertyGroup,),
    {"__annotations__": _cloud_layer_annotations(), "__doc__": "A further cloud layer of a layered sky"},
)


def _scene_annotations() -> dict:
    ann = _annotations(schema.SCENE)
    ann["layers"] = CollectionProperty(type=NubisFieldLayer)
    ann["storms"] = CollectionProperty(type=NubisStorm)
    redraw = events.update_callback("redraw")
    # A layered sky (docs/layers.md): the first layer is these settings; the further ones follow.
    ann["cloud_layers"] = CollectionProperty(type=NubisCloudLayer)
    # The further layer the per-layer panels act on; ui.FIRST_LAYER: the first layer (ui.active_cloud_layer).
    ann["active_further_layer"] = IntProperty(
        name="Active Cloud Layer",
        description="The cloud layer the panels below act on",
        min=ui.FIRST_LAYER,
        default=ui.FIRST_LAYER,
    )
    ann["first_layer_name"] = StringProperty(name="Name", description="The first cloud layer's name", default="Layer 1")
    ann["first_layer_enabled"] = BoolProperty(
        name="Enabled", description="Draw the first cloud layer", default=True, update=redraw
    )
    ann["first_layer_solo"] = BoolProperty(
        name="Solo", description="Draw only the soloed cloud layers while any is soloed", update=redraw
    )
    return ann


NubisSceneSettings = type(
    "NubisSceneSettings",
    (bpy.types.PropertyGroup,),
    {"__annotations__": _scene_annotations(), "__doc__": "Nubis cloudscape settings of a scene"},
)

CLASSES = (NubisPaintDab, NubisFieldLayer, NubisStorm, NubisCloudLayer, NubisSceneSettings)


register, unregister = ui.property_group_registration(CLASSES, bpy.types.Scene, "nubis", NubisSceneSettings)
