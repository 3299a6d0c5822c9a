"""Scene settings, generated from core/params.py so presets, UI and shaders share one list."""

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

from ..core.params import PARAMS, Param
from ..core.presets import LAYER_SCHEMA, STORM_SCHEMA


def _tag_redraw(_self, context) -> None:
    from . import viewport

    viewport.mark_dirty()
    screen = getattr(context, "screen", None)
    for area in screen.areas if screen else ():
        if area.type == "VIEW_3D":
            area.tag_redraw()


def _prop_for(p: Param):
    label = p.name.replace("_", " ").title()
    common = {"name": label, "description": p.description, "update": _tag_redraw}
    if p.kind == "float":
        kw = {"default": p.default, "min": p.min, "max": p.max, "unit": p.unit}
        if p.soft_max is not None:
            kw["soft_max"] = p.soft_max
        if p.unit == "ROTATION":
            kw["subtype"] = "ANGLE"
            kw.pop("unit")
        return FloatProperty(**common, **kw)
    if p.kind == "int":
        return IntProperty(**common, default=p.default, min=int(p.min), max=int(p.max))
    if p.kind == "bool":
        return BoolProperty(**common, default=p.default)
    raise TypeError(f"unsupported parameter kind {p.kind}")


def _enum(choices: tuple[str, ...]) -> list[tuple[str, str, str]]:
    return [(c.upper(), c.replace("_", " ").title(), "") for c in choices]


def _layer_annotations() -> dict:
    ann = {}
    for key, spec in LAYER_SCHEMA.items():
        typ, default = spec[0], spec[1]
        label = key.replace("_", " ").title()
        if key == "image":
            ann[key] = PointerProperty(name="Image", type=bpy.types.Image, description="Painted image for image layers")
        elif key == "name":
            ann[key] = StringProperty(name="Name", default="Layer")
        elif typ is str and len(spec) == 3:
            ann[key] = EnumProperty(name=label, items=_enum(spec[2]), default=default.upper())
        elif typ is str:
            ann[key] = StringProperty(name=label, default=default)
        elif typ is bool:
            ann[key] = BoolProperty(name=label, default=default)
        elif typ is int:
            ann[key] = IntProperty(name=label, default=default, min=spec[2], max=spec[3])
        elif typ is float:
            unit = "LENGTH" if key in ("scale", "radius") else "NONE"
            ann[key] = FloatProperty(name=label, default=default, min=spec[2], max=spec[3], unit=unit)
        elif typ is list:
            ann[key] = FloatVectorProperty(name=label, size=len(default), default=default)
    return ann


NubisFieldLayer = type(
    "NubisFieldLayer",
    (bpy.types.PropertyGroup,),
    {"__annotations__": _layer_annotations(), "__doc__": "One layer of the data-field stack"},
)


_STORM_UNITS = {"x": "LENGTH", "y": "LENGTH", "radius": "LENGTH", "anvil_offset": "LENGTH"}
_STORM_HELP = {
    "blend": "Lifecycle blend factor: animate it for the storm to form and dissipate (GDC22)",
    "height": "Top of the storm at its centre, in layer thicknesses",
    "base": "Height of the storm's flat foot, in layer thicknesses (negative lowers it)",
    "bottom_type": "Raggedness of the underside",
    "spin": "Vortex rotation at the centre in radians per second; outer rings turn slower",
    "darkening": "Optical-depth scale of the light reaching the storm's centre",
    "glow": "Intensity of the internal glow",
    "ambient_boost": "Ambient light under the storm relative to the other clouds",
    "anvil_offset": "How far downwind the cirrus anvil sits",
}


def _storm_annotations() -> dict:
    ann = {
        "empty": PointerProperty(
            type=bpy.types.Object,
            name="Position",
            update=_storm_changed,
            description="An Empty whose location is the storm's centre; move it in the viewport",
        ),
        "flash": FloatProperty(
            name="Flash",
            default=0.0,
            min=0.0,
            soft_max=500.0,
            update=_tag_redraw,
            description="Lightning flash intensity; keyframed by Add Lightning",
        ),
        "flash_x": FloatProperty(
            name="Flash X",
            default=0.0,
            unit="LENGTH",
            update=_tag_redraw,
            description="Where the flash is, relative to the storm centre",
        ),
        "flash_y": FloatProperty(
            name="Flash Y",
            default=0.0,
            unit="LENGTH",
            update=_tag_redraw,
            description="Where the flash is, relative to the storm centre",
        ),
        "flash_ground": FloatProperty(
            name="Ground Discharge",
            default=0.0,
            min=0.0,
            max=1.0,
            update=_tag_redraw,
            description="1 while the flash is a ground discharge (adds the external flash)",
        ),
    }
    for key, spec in STORM_SCHEMA.items():
        typ, default = spec[0], spec[1]
        label = key.replace("_", " ").title()
        desc = _STORM_HELP.get(key, "")
        if key in ("x", "y"):
            continue  # the Empty holds the position
        if typ is str:
            ann[key] = StringProperty(name=label, default=default)
        elif typ is int:
            ann[key] = IntProperty(name=label, default=default, min=spec[2], max=spec[3], update=_storm_changed)
        elif typ is float:
            update = _tag_redraw if key in ("spin", "darkening", "glow", "ambient_boost") else _storm_changed
            ann[key] = FloatProperty(
                name=label,
                default=default,
                min=spec[2],
                max=spec[3],
                description=desc,
                unit=_STORM_UNITS.get(key, "NONE"),
                update=update,
            )
        elif typ is list:
            ann[key] = FloatVectorProperty(
                name=label, size=3, default=default, subtype="COLOR", min=0.0, update=_tag_redraw
            )
    return ann


def _storm_changed(_self, context) -> None:
    from . import scene_io

    scene = getattr(context, "scene", None)
    if scene is not None and getattr(scene, "nubis", None) is not None and scene.nubis.field_a is not None:
        scene_io.generate_fields(scene)
    _tag_redraw(_self, context)


NubisStorm = type(
    "NubisStorm",
    (bpy.types.PropertyGroup,),
    {"__annotations__": _storm_annotations(), "__doc__": "A superstorm stencil"},
)


def _settings_annotations() -> dict:
    ann = {p.key: _prop_for(p) for p in PARAMS}
    ann.update(
        enabled=BoolProperty(
            name="Show Clouds", default=True, update=_tag_redraw, description="Draw the clouds in the 3D viewport"
        ),
        preset=StringProperty(name="Preset", default="default", description="The preset this cloudscape came from"),
        field_a=PointerProperty(
            type=bpy.types.Image,
            name="Field A",
            update=_tag_redraw,
            description="Coverage, precipitation, cloud type, bottom type",
        ),
        field_b=PointerProperty(
            type=bpy.types.Image,
            name="Field B",
            update=_tag_redraw,
            description="Storm coverage, min height, max height, density multiplier",
        ),
        field_cirrus=PointerProperty(
            type=bpy.types.Image, name="Cirrus Field", update=_tag_redraw, description="Cirrus coverage and type"
        ),
        layers=CollectionProperty(type=NubisFieldLayer),
        storms=CollectionProperty(type=NubisStorm),
        active_storm=IntProperty(name="Active Storm", default=0),
        rule_rain=BoolProperty(
            name="Rain Rule",
            default=False,
            description="Where it rains, turn clouds to cumulonimbus covering at least 70% (GPU Pro 7)",
        ),
        rule_horizon=BoolProperty(
            name="Horizon Rule",
            default=False,
            description="Blend towards cumulus at ~50% coverage far from the camera (S15)",
        ),
        rule_cumulonimbus_top=FloatProperty(
            name="Cumulonimbus Top",
            default=2.6,
            min=0.0,
            max=8.0,
            description="Max height, in layer thicknesses, of fully raining clouds",
        ),
        rule_horizon_start=FloatProperty(
            name="Horizon Start",
            default=15000.0,
            min=0.0,
            unit="LENGTH",
            description="Distance from the camera where the horizon rule begins (S15: 15 km)",
        ),
        active_layer=IntProperty(name="Active Layer", default=0),
        ambient_source=EnumProperty(
            name="Ambient",
            items=(
                ("WORLD", "World", "Sky light from the World's radiance in every direction (an HDRI, a sky, a colour)"),
                ("COLOR", "Colour", "Sky light from an explicit colour"),
            ),
            default="WORLD",
            update=_tag_redraw,
        ),
        ambient_color=FloatVectorProperty(
            name="Ambient Colour",
            subtype="COLOR",
            size=3,
            min=0.0,
            soft_max=1.0,
            default=(0.3, 0.45, 0.8),
            update=_tag_redraw,
        ),
        viewport_quality=StringProperty(
            name="Quality",
            default="standard",
            description="The quality level last applied (presets/quality/quality.toml); 'custom' once edited",
        ),
    )
    return ann


NubisSceneSettings = type(
    "NubisSceneSettings",
    (bpy.types.PropertyGroup,),
    {"__annotations__": _settings_annotations(), "__doc__": "Nubis cloudscape settings of a scene"},
)

CLASSES = (NubisFieldLayer, NubisStorm, NubisSceneSettings)


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.nubis = PointerProperty(type=NubisSceneSettings)


def unregister() -> None:
    del bpy.types.Scene.nubis
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)


def params_from_scene(settings) -> dict:
    return {p.key: getattr(settings, p.key) for p in PARAMS}


def layer_to_dict(layer) -> dict:
    out = {}
    for key in LAYER_SCHEMA:
        value = getattr(layer, key)
        if key == "image":
            value = value.name if value else ""
        elif isinstance(value, str) and len(LAYER_SCHEMA[key]) == 3:
            value = value.lower()
        elif hasattr(value, "__len__") and not isinstance(value, str):
            value = list(value)
        out[key] = value
    return out


def layer_from_dict(layer, data: dict) -> None:
    for key, value in data.items():
        if key == "image":
            layer.image = bpy.data.images.get(value) if value else None
        elif isinstance(value, str) and len(LAYER_SCHEMA[key]) == 3:
            setattr(layer, key, value.upper())
        else:
            setattr(layer, key, value)
