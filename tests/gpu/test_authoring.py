"""Authoring in Blender: the operators, the layer stack, painting an image layer, the weather rules."""

import types

import numpy as np


def _coverage(scene):
    from nubis_addon.blender.scene import datafield

    return datafield.read_field_image(scene.nubis.field_a, "a", scene.nubis.field_resolution)[..., 0]


def test_new_cloudscape_operator_and_layer_stack(blender):
    bpy = blender
    bpy.ops.wm.read_factory_settings(use_empty=True)
    from nubis_addon.blender import ensure_registered

    ensure_registered()
    scene = bpy.context.scene
    assert bpy.ops.nubis.generate_field.poll() is False  # nothing to generate yet
    assert bpy.ops.nubis.new_cloudscape(preset="default") == {"FINISHED"}
    s = scene.nubis
    assert s.field_a is not None and s.field_b is not None and scene.camera is not None
    n = len(s.layers)
    before = _coverage(scene).copy()
    s.active_layer = 0
    assert bpy.ops.nubis.layer_duplicate() == {"FINISHED"}
    assert len(s.layers) == n + 1 and s.layers[1].name.endswith("copy")
    s.layers[1].blend = "MULTIPLY"
    assert bpy.ops.nubis.generate_field() == {"FINISHED"}
    squared = _coverage(scene)
    assert squared.mean() < before.mean()  # coverage x coverage thins the sky
    assert bpy.ops.nubis.layer_move(direction="UP") == {"FINISHED"} and s.active_layer == 0
    assert bpy.ops.nubis.layer_remove() == {"FINISHED"} and len(s.layers) == n
    assert bpy.ops.nubis.layer_add() == {"FINISHED"} and len(s.layers) == n + 1


def test_painting_an_image_layer_updates_the_field(make_scene, blender):
    from nubis_addon.blender.live import events
    from nubis_addon.blender.scene import sceneparams

    scene = make_scene("default")
    s = scene.nubis
    img = blender.data.images.new("Paint", 32, 32, float_buffer=True)
    layer = s.layers.add()
    layer.name, layer.kind, layer.channel, layer.image = "Painted", "IMAGE", "COVERAGE", img
    blender.ops.nubis.generate_field()
    assert _coverage(scene).max() == 0.0  # a black image replaces coverage with 0
    # A brush stroke: the right half painted white, then the update Blender sends for it.
    px = np.zeros((32, 32, 4), np.float32)
    px[:, 16:] = 1.0
    img.pixels.foreach_set(px.ravel())
    fake = types.SimpleNamespace(updates=[types.SimpleNamespace(id=img)])
    events.on_depsgraph_update(scene, fake)
    assert sceneparams.field_stale(scene)  # a composite is owed ...
    events.composite_stale()  # ... and made by the debounce timer a moment later
    assert not sceneparams.field_stale(scene)
    cov = _coverage(scene)
    assert cov[:, :200].max() < 0.01 and cov[:, 312:].min() > 0.99


def test_weather_rules_operator(make_scene, blender):
    from nubis_addon.blender.scene import datafield

    scene = make_scene("default")
    s = scene.nubis
    layer = s.layers.add()
    layer.name, layer.kind, layer.channel, layer.value = "Rain", "CONSTANT", "PRECIPITATION", 1.0
    assert blender.ops.nubis.apply_weather_rules(rain=True, horizon=False) == {"FINISHED"}
    a = datafield.read_field_image(s.field_a, "a", s.field_resolution)
    b = datafield.read_field_image(s.field_b, "b", s.field_resolution)
    assert a[..., 0].min() >= 0.7 - 1e-6 and a[..., 2].min() > 0.999
    assert b[..., 2].min() == np.float32(s.rule_cumulonimbus_top)
