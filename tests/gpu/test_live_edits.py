"""An artist's edits show without Generate Field: layer settings, storm Empties moved in the viewport,
keyed values on frame change; New Cloudscape keeps what it is asked to keep; the draw handler stays out
of Wireframe and of views whose toggle is off; slider drags repack nothing."""

from __future__ import annotations

import types

import numpy as np


def _field_a(scene):
    from nubis_addon.blender.scene import datafield

    return datafield.read_fields(scene.nubis)[0].copy()


def test_a_layer_edit_recomposites_the_field(make_scene):
    from nubis_addon.blender.live import events
    from nubis_addon.blender.scene import sceneparams

    scene = make_scene("default")
    before = _field_a(scene)
    layer = scene.nubis.layers[0]
    layer.scale *= 0.5  # what dragging the slider does
    assert sceneparams.field_stale(scene)
    events.composite_stale()  # the debounce timer, a moment after the drag
    after = _field_a(scene)
    assert not np.array_equal(before, after)
    # A rule toggle too, read straight by a render (which makes the owed composite itself).
    scene.nubis.rule_horizon = True
    assert sceneparams.field_stale(scene)
    assert not np.array_equal(after, _field_a(scene))  # cumulus at ~50 % far out
    assert not sceneparams.field_stale(scene)


def test_moving_a_storm_empty_moves_its_column(blender, make_scene):
    from nubis_addon.blender.live import events
    from nubis_addon.blender.scene import sceneparams

    scene = make_scene("default")
    blender.ops.nubis.storm_add()
    storm = scene.nubis.storms[0]
    before = _field_a(scene)
    storm.empty.location.x += 15000.0
    # The update Blender sends after a move in the viewport.
    depsgraph = blender.context.evaluated_depsgraph_get()
    update = types.SimpleNamespace(id=storm.empty.evaluated_get(depsgraph), is_updated_transform=True)
    events.on_depsgraph_update(scene, types.SimpleNamespace(updates=[update]))
    assert sceneparams.field_stale(scene)
    events.composite_stale()
    after = _field_a(scene)
    # The storm's coverage column moved with the Empty: the coverage changed where it was and where it went.
    assert np.abs(after[..., 0] - before[..., 0]).max() > 0.5


def test_a_keyed_layer_value_changes_the_field_on_frame_change(blender, make_scene):
    scene = make_scene("default")
    layer = scene.nubis.layers[0]
    layer.opacity = 1.0
    layer.keyframe_insert("opacity", frame=1)
    layer.opacity = 0.2
    layer.keyframe_insert("opacity", frame=20)
    scene.frame_set(1)
    at_1 = _field_a(scene)
    scene.frame_set(20)
    at_20 = _field_a(scene)
    assert not np.array_equal(at_1, at_20)
    assert abs(scene.nubis.layers[0].opacity - 0.2) < 1e-6


def test_new_cloudscape_keeps_the_artists_camera_and_world_when_asked(blender):
    from nubis_addon.blender import ensure_registered
    from nubis_addon.blender.scene import scenepresets, skyground

    blender.ops.wm.read_factory_settings(use_empty=True)
    ensure_registered()
    scene = blender.context.scene
    cam = blender.data.objects.new("My Camera", blender.data.cameras.new("My Camera"))
    scene.collection.objects.link(cam)
    cam.location, cam.data.lens = (1.0, 2.0, 3.0), 85.0
    scene.camera = cam
    world = blender.data.worlds.new("My HDRI")
    scene.world = world
    scene.render.resolution_x = 1234
    sun = blender.data.objects.new("My Sun", blender.data.lights.new("My Sun", "SUN"))
    scene.collection.objects.link(sun)
    assert blender.ops.nubis.new_cloudscape(
        preset="default", keep_camera=True, keep_world=True, keep_render=True, keep_sun=True
    ) == {"FINISHED"}
    assert scene.camera == cam and tuple(cam.location) == (1.0, 2.0, 3.0) and cam.data.lens == 85.0
    assert scene.world == world and scene.render.resolution_x == 1234
    assert scene.nubis.sun == sun and skyground.find_sun(scene) == sun
    # Not kept: the preset's camera and sky, the artist's still in the file.
    assert blender.ops.nubis.new_cloudscape(preset="default") == {"FINISHED"}
    assert scene.camera.name == scenepresets.CAMERA_NAME and tuple(cam.location) == (1.0, 2.0, 3.0)
    assert scene.world.name == scenepresets.WORLD_NAME and world.use_fake_user
    assert scene.nubis.sun.name == scenepresets.SUN_NAME and "My Sun" in scene.objects
    assert scene.render.resolution_x == 640


def test_an_artists_storm_empty_survives_a_new_cloudscape(blender, make_scene):
    scene = make_scene("default")
    mine = blender.data.objects.new("My Storm Marker", None)
    scene.collection.objects.link(mine)
    blender.ops.nubis.storm_add()
    made = scene.nubis.storms[0].empty.name
    storm = scene.nubis.storms.add()
    storm.empty = mine
    assert blender.ops.nubis.new_cloudscape(preset="default") == {"FINISHED"}
    assert "My Storm Marker" in scene.objects and made not in blender.data.objects


def _fake_view(scene, shading="SOLID", screen=None, area=None):
    return types.SimpleNamespace(
        scene=scene,
        region=types.SimpleNamespace(width=32, height=18, as_pointer=lambda: 1),
        region_data=object(),
        space_data=types.SimpleNamespace(shading=types.SimpleNamespace(type=shading)),
        screen=screen,
        area=area,
    )


def test_the_draw_handler_stays_out_of_wireframe_and_switched_off_views(make_scene, monkeypatch):
    from nubis_addon.blender.live import viewport

    scene = make_scene("default")
    calls = []
    monkeypatch.setattr(viewport, "draw_region", lambda *args: calls.append(args))
    assert viewport.draw_in_context(_fake_view(scene, "SOLID")) and len(calls) == 1
    assert not viewport.draw_in_context(_fake_view(scene, "WIREFRAME")) and len(calls) == 1
    # This view's own toggle, kept in its screen's ID properties (a dict here).
    area = object()

    class Screen(dict):
        areas = [object(), area]

    real = Screen()
    context = _fake_view(scene, "MATERIAL", real, area)
    viewport.set_view_toggle(context, False)
    assert real[viewport.HIDDEN_KEY] == [1]
    assert not viewport.draw_in_context(context) and len(calls) == 1
    viewport.set_view_toggle(context, True)
    assert viewport.draw_in_context(context) and len(calls) == 2
    scene.nubis.enabled = False
    assert not viewport.draw_in_context(_fake_view(scene, "SOLID")) and len(calls) == 2


def test_rendered_mode_leaves_a_baked_volume_to_the_engine(blender, make_scene, monkeypatch):
    from nubis_addon.blender.live import viewport
    from nubis_addon.blender.scene import cycles_setup

    scene = make_scene("default")
    monkeypatch.setattr(viewport, "draw_region", lambda *args: None)
    assert viewport.draw_in_context(_fake_view(scene, "RENDERED"))
    obj = blender.data.objects.new(cycles_setup.VOLUME_NAME, blender.data.volumes.new("v"))
    scene.collection.objects.link(obj)
    assert not viewport.draw_in_context(_fake_view(scene, "RENDERED"))
    assert viewport.draw_in_context(_fake_view(scene, "SOLID"))


def test_slider_drags_repack_nothing_and_saving_packs_the_field(blender, make_scene, tmp_path):
    from nubis_addon.blender.scene import datafield, sceneparams

    scene = make_scene("default")
    s = scene.nubis
    generation = datafield.field_generation()
    for value in np.linspace(0.1, 0.9, 9):  # a drag of a lighting slider: no composite, no image written
        s.lighting_powder = float(value)
    assert datafield.field_generation() == generation and not sceneparams.field_stale(scene)
    assert s.field_a.packed_file is None  # composites leave the images unpacked ...
    path = tmp_path / "sky.blend"
    blender.ops.wm.save_as_mainfile(filepath=str(path))
    assert s.field_a.packed_file is not None  # ... saving packs them
    packed = s.field_a.packed_file
    s.lighting_powder = 0.5
    blender.ops.wm.save_as_mainfile(filepath=str(path))
    assert s.field_a.packed_file == packed  # unchanged pixels are not packed again


def test_dragging_a_layer_base_above_its_top_carries_the_top(make_scene):
    scene = make_scene("default")
    s = scene.nubis
    s.layer_bottom = s.layer_top + 500.0
    assert s.layer_top > s.layer_bottom
    s.march_steps_max = 10
    assert s.march_steps_min <= s.march_steps_max
