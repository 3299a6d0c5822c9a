"""The sidebar draws every setting the schema gives a panel: each panel's draw() runs against a layout
that records what it is asked to show, for every layer kind and with a storm present."""

from __future__ import annotations

import types

import pytest


class RecordingLayout:
    """Stands in for bpy's UILayout: records every property drawn; sub-layouts share the record."""

    def __init__(self, record: list | None = None, texts: list | None = None):
        self.drawn: list = [] if record is None else record
        self.texts: list = [] if texts is None else texts  # every label's and prop's own text
        self.use_property_split = False
        self.use_property_decorate = False
        self.active = True

    def _sub(self, *_args, **_kwargs):
        return RecordingLayout(self.drawn, self.texts)

    row = column = box = split = _sub

    def prop(self, owner, key, **kwargs):
        assert hasattr(owner, key), f"{type(owner).__name__} has no property {key}"
        self.drawn.append((owner, key))
        if kwargs.get("text"):
            self.texts.append(("prop", kwargs["text"]))

    def template_list(self, _type, _id, owner, collection, _active_owner, _active, **_kwargs):
        # The list draws each entry's name.
        for item in getattr(owner, collection):
            self.drawn.append((item, "name"))

    def prop_search(self, owner, key, _search_owner, _search_collection, **_kwargs):
        self.prop(owner, key)

    def template_ID(self, owner, key, **_kwargs):
        self.drawn.append((owner, key))

    def operator(self, *_args, **_kwargs):
        return types.SimpleNamespace()

    def operator_menu_enum(self, *_args, **_kwargs):
        return None

    def menu(self, *_args, **_kwargs):
        return None

    def separator(self, *_args, **_kwargs):
        return None

    def label(self, **kwargs):
        self.texts.append(("label", kwargs.get("text", "")))


def _draw_all(panels, context, texts: list | None = None) -> list:
    drawn: list = []
    texts = [] if texts is None else texts
    for cls in panels.CLASSES:
        if not hasattr(cls, "bl_label"):  # the layer list draws its items itself
            continue
        fake = types.SimpleNamespace(layout=RecordingLayout(drawn, texts), panel=getattr(cls, "panel", ""))
        for name in ("draw_before", "draw_after"):
            if hasattr(cls, name):
                setattr(fake, name, getattr(cls, name).__get__(fake))
        cls.draw(fake, context)
    return drawn


def test_every_setting_with_a_panel_is_drawn(blender, make_scene):
    from nubis_addon.blender.sidebar import panels
    from nubis_addon.core import schema

    scene = make_scene("default")
    blender.ops.nubis.storm_add()
    s = scene.nubis
    context = types.SimpleNamespace(scene=scene)
    drawn_keys: set[tuple[str, str]] = set()
    for kind in ("PERLIN", "GRADIENT", "CONSTANT", "IMAGE"):
        s.layers[s.active_layer].kind = kind
        for owner, key in _draw_all(panels, context):
            group = {"NubisSceneSettings": "scene", "NubisFieldLayer": "layer", "NubisStorm": "storm"}.get(
                type(owner).__name__, "other"
            )
            drawn_keys.add((group, key))
    for setting in (*schema.SCENE, *schema.FIELD_LAYER, *schema.STORM):
        if setting.panel:
            assert (setting.group if setting.group != "scene" else "scene", setting.key) in drawn_keys, (
                f"{setting.group} setting {setting.key} is assigned to panel '{setting.panel}' but not drawn"
            )
    # ... and the labels are the schema's, not made from keys.
    prop = type(s).bl_rna.properties["lighting_ms_octaves"]
    assert prop.name == "Octaves" and "Wrenninge" in prop.description
    assert type(s).bl_rna.properties["noise_lf_period"].name == "Shape Size"


# Blender's property-split rows give the label 40 % of the sidebar: at the default width, labels of up to
# 13 characters showed whole in the real application and longer ones were cut ("Ambient at B...").
# A label across the whole sidebar holds about 35.
SPLIT_LABEL = 13
FULL_LABEL = 35


def test_every_label_fits_the_default_sidebar(blender, make_scene):
    from nubis_addon.blender.sidebar import panels
    from nubis_addon.core import schema

    scene = make_scene("default")
    texts: list = []
    _draw_all(panels, types.SimpleNamespace(scene=scene), texts)
    for setting in (*schema.SCENE, *schema.FIELD_LAYER, *schema.STORM):
        if setting.panel:
            assert len(setting.label) <= SPLIT_LABEL, f"{setting.key}: '{setting.label}' is cut in the sidebar"
    for kind, text in texts:
        assert len(text) <= (SPLIT_LABEL if kind == "prop" else FULL_LABEL), f"{kind} '{text}' is cut in the sidebar"


def test_the_recording_layout_notices_a_missing_setting(blender, make_scene):
    """The check above can fail: a panel that forgets a setting is caught."""
    from nubis_addon.blender.sidebar import panels

    scene = make_scene("default")
    context = types.SimpleNamespace(scene=scene)
    drawn = _draw_all(panels, context)
    keys = {key for _owner, key in drawn}
    assert "cirrus_altitude" in keys
    original = panels.PANEL_CLASSES["cirrus"].panel
    try:
        panels.PANEL_CLASSES["cirrus"].panel = "nothing"
        keys = {key for _owner, key in _draw_all(panels, context)}
        assert "cirrus_altitude" not in keys
    finally:
        panels.PANEL_CLASSES["cirrus"].panel = original


def test_units_and_soft_ranges_come_from_the_schema(blender):
    props = blender.types.Scene.bl_rna.properties["nubis"].fixed_type.properties
    assert props["wind_speed"].unit == "VELOCITY"
    assert props["wind_time_offset"].unit == "TIME_ABSOLUTE"
    assert props["wind_direction"].subtype == "ANGLE"
    assert props["layer_planet_radius"].soft_max < props["layer_planet_radius"].hard_max
    assert props["ambient_color"].name == "Ambient Color"


# Each button that needs something of the scene, the state where it cannot act, and the words it says why.
GREY_BUTTONS = [
    ("cloud_layer_remove", "first", "There is no further cloud layer to be removed: add one with + first"),
    ("cloud_layer_move", "first", "There is no further cloud layer to move: add one with + first"),
    ("cloud_layer_remove", "first chosen", "The first cloud layer is the cloudscape's own and cannot be removed"),
    ("cloud_layer_add", "four layers", "A sky holds at most 4 cloud layers: remove one before adding another"),
    ("storm_remove", "no storm", "There is no superstorm to remove: add one with Add Superstorm"),
    ("storm_add", "every storm", "A scene holds at most 4 superstorms: remove one first"),
    ("layer_remove", "no field layer", "There is no layer to remove: add one with + first"),
    ("layer_duplicate", "no field layer", "There is no layer to duplicate: add one with + first"),
    ("layer_add", "128 field layers", "A scene holds at most 128 field layers: merge or remove one first"),
]


@pytest.mark.parametrize(("op", "state", "words"), GREY_BUTTONS, ids=[f"{o}-{s}" for o, s, _w in GREY_BUTTONS])
def test_a_grey_button_says_why_in_the_sentence_its_click_would_refuse_with(make_scene, op, state, words):
    """Blender shows a failed poll's message as the button's tooltip ("Disabled: ..."); the same sentence is
    what the operator refuses with when run anyway (stated once: `unavailable`)."""
    import bpy

    from nubis_addon.blender.sidebar import operators, skylayers, stormbuttons
    from nubis_addon.core.errors import NubisError
    from nubis_addon.core.state import MAX_STORMS

    scene = make_scene("default")
    s = scene.nubis
    if state == "first chosen":
        assert bpy.ops.nubis.cloud_layer_add() == {"FINISHED"}
        s.active_further_layer = -1
    elif state == "four layers":
        for _ in range(3):
            assert bpy.ops.nubis.cloud_layer_add() == {"FINISHED"}
    elif state == "no storm":
        assert not s.storms
    elif state == "every storm":
        for _ in range(MAX_STORMS):
            assert bpy.ops.nubis.storm_add() == {"FINISHED"}
    elif state == "no field layer":
        s.layers.clear()
    elif state == "128 field layers":
        while len(s.layers) < 128:
            s.layers.add()
    fn = getattr(bpy.ops.nubis, op)
    assert not fn.poll()
    with pytest.raises(RuntimeError) as err:
        fn()
    assert words in str(err.value), str(err.value)
    classes = (*operators.CLASSES, *skylayers.CLASSES, *stormbuttons.CLASSES)
    cls = next(c for c in classes if getattr(c, "bl_idname", "") == f"nubis.{op}")
    with pytest.raises(NubisError) as refused:
        cls.refuse_if_unavailable(cls, scene)
    assert words.lower() in str(refused.value).lower()
