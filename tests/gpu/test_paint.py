"""Painting the sky: paint layers in the stack, the live stroke's in-place upload against the full
composite, the Coverage slider's normalisation left alone, saving, undo's recomposite, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from gpu_helpers import camera_view, stroke_elements

RADIUS = 2500.0


def stroke(xs, y=0.0):
    return stroke_elements(xs, y)


def cover(scene):
    """The coverage the shader sees: field A red times the stored multiplier, clamped."""
    from nubis_addon.blender.scene import datafield

    a = datafield.read_fields(scene.nubis)[0]
    return np.clip(a[..., 0] * datafield.coverage_multiplier(scene), 0.0, 1.0)


def near_stroke(scene, x0, x1, y, within):
    from nubis_addon.core.fields import pixel_centres

    xs, ys = pixel_centres(scene.nubis)
    dx = np.maximum(np.maximum(x0 - xs, xs - x1), 0.0)
    return np.hypot(dx, ys - y) < within


def test_a_stroke_raises_the_cover_under_it_and_leaves_the_rest_exactly(blender, make_scene):
    scene = make_scene("default")
    before, m_before = cover(scene), scene.nubis.density_coverage
    r = blender.ops.nubis.paint_field(channel="COVERAGE", radius=RADIUS, strength=1.0, stroke=stroke([-6000, 6000]))
    assert r == {"FINISHED"}
    layer = scene.nubis.layers[-1]
    assert layer.kind == "PAINT" and layer.channel == "COVERAGE" and len(layer.dabs) > 10
    after = cover(scene)
    # The slider's multiplier is found without the paint: painting here thins no cloud elsewhere.
    assert scene.nubis.density_coverage == pytest.approx(m_before, rel=1e-6)
    core = near_stroke(scene, -6000, 6000, 0.0, 0.15 * RADIUS)
    outside = ~near_stroke(scene, -6000, 6000, 0.0, RADIUS + 200.0)
    assert after[core].min() > 0.9
    np.testing.assert_allclose(after[outside], before[outside], atol=1e-6)
    # Subtracting the same stroke takes the layer back to nothing: the sky is as it was.
    r = blender.ops.nubis.paint_field(
        channel="COVERAGE", radius=RADIUS, strength=1.0, mode="SUBTRACT", stroke=stroke([-6000, 6000])
    )
    assert r == {"FINISHED"} and sum(x.kind == "PAINT" for x in scene.nubis.layers) == 1
    np.testing.assert_allclose(cover(scene), before, atol=1e-6)
    # Subtracting on its own clears the clouds under the stroke, and only there.
    blender.ops.nubis.paint_field(
        channel="COVERAGE", radius=RADIUS, strength=1.0, mode="SUBTRACT", stroke=stroke([-6000, 6000])
    )
    assert cover(scene)[core].max() < 0.05
    np.testing.assert_allclose(cover(scene)[outside], before[outside], atol=1e-6)


def test_paint_layers_disable_fade_reorder_and_clear_like_layers(blender, make_scene):
    from nubis_addon.blender.scene import datafield

    scene = make_scene("default")
    s = scene.nubis
    before = cover(scene)
    blender.ops.nubis.paint_field(channel="COVERAGE", radius=RADIUS, strength=1.0, stroke=stroke([-3000, 3000]))
    painted = cover(scene)
    layer = s.layers[-1]
    layer.enabled = False
    datafield.generate_fields(scene)
    np.testing.assert_allclose(cover(scene), before, atol=1e-6)
    layer.enabled = True
    layer.opacity = 0.5
    datafield.generate_fields(scene)
    half = cover(scene)
    values = datafield.paint_layers(s)[0].values
    core = near_stroke(scene, -3000, 3000, 0.0, 0.15 * RADIUS)
    np.testing.assert_allclose(half[core], np.clip(before[core] + 0.5 * values[core], 0, 1), atol=1e-5)
    assert values[core].min() > 0.9
    layer.opacity = 1.0
    # Paint acts after the stack: moving the layer to the top changes nothing.
    s.layers.move(len(s.layers) - 1, 0)
    datafield.generate_fields(scene)
    np.testing.assert_allclose(cover(scene), painted, atol=1e-6)
    s.active_layer = 0
    assert blender.ops.nubis.paint_layer_clear() == {"FINISHED"}
    assert len(s.layers[0].dabs) == 0
    np.testing.assert_allclose(cover(scene), before, atol=1e-6)


def test_painting_a_clear_sky_at_zero_coverage_paints_only_the_stroke(blender, make_scene):
    from nubis_addon.blender.scene import datafield
    from nubis_addon.core import paint

    scene = make_scene("default")
    scene.nubis.density_cover = 0.0
    datafield.generate_fields(scene)
    assert scene.nubis.density_coverage == 0.0
    blender.ops.nubis.paint_field(channel="COVERAGE", radius=RADIUS, strength=1.0, stroke=stroke([0, 1000]))
    assert scene.nubis.density_coverage == pytest.approx(paint.MULTIPLIER_FLOOR)
    c = cover(scene)
    assert c[near_stroke(scene, 0, 1000, 0.0, 0.15 * RADIUS)].min() > 0.9
    assert c[~near_stroke(scene, 0, 1000, 0.0, RADIUS + 200.0)].max() == 0.0


def test_type_and_precipitation_paint_add_to_their_channels(blender, make_scene):
    from nubis_addon.blender.scene import datafield

    scene = make_scene("default")
    a0 = datafield.read_fields(scene.nubis)[0].copy()
    blender.ops.nubis.paint_field(channel="PRECIPITATION", radius=RADIUS, strength=0.6, stroke=stroke([0, 2000]))
    blender.ops.nubis.paint_field(channel="TYPE", radius=RADIUS, strength=1.0, stroke=stroke([0, 2000]))
    a1 = datafield.read_fields(scene.nubis)[0]
    core = near_stroke(scene, 0, 2000, 0.0, 0.15 * RADIUS)
    assert np.all(a1[core, 1] >= np.minimum(a0[core, 1] + 0.54, 1.0))
    assert a1[core, 2].min() > 0.9
    far = ~near_stroke(scene, 0, 2000, 0.0, RADIUS + 200.0)
    np.testing.assert_array_equal(a1[far], a0[far])
    assert [x.channel for x in scene.nubis.layers if x.kind == "PAINT"] == ["PRECIPITATION", "TYPE"]


def test_the_live_stroke_shows_what_the_full_composite_makes(blender, make_scene, monkeypatch):
    """During a drag only the stroke's rectangle is re-composited and written into the texture in place;
    the viewport then draws what the stroke's end composites whole."""
    from types import SimpleNamespace

    import gpu

    from nubis_addon.blender.host import runtime
    from nubis_addon.blender.live import paintstroke, viewport
    from nubis_addon.blender.scene import datafield, sceneparams
    from nubis_addon.render.offscreens import read_pixels

    scene = make_scene("default")
    s = scene.nubis
    w, h = 48, 27
    rv3d = camera_view(blender, scene, w, h)
    s.viewport_samples = 1
    layer = paintstroke.paint_layer(s, "COVERAGE")
    cam_xy = sceneparams.evaluated_matrix(scene.camera).translation
    live = paintstroke.LiveStroke(scene, layer, RADIUS, 1.0, "SMOOTH", "ADD")
    live.hold_light = False  # the 3D view holds the shadows during a drag; here they follow at once
    clouds = runtime.cloud_gpu(s.noise_seed)

    def converge(key):
        region = SimpleNamespace(width=w, height=h, as_pointer=lambda: key)
        offscreen = gpu.types.GPUOffScreen(w, h, format="RGBA32F")
        try:
            with offscreen.bind():
                fb = gpu.state.active_framebuffer_get()
                for _ in range(20):
                    fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
                    tv = viewport.draw_region(scene, region, rv3d)
                assert tv.converged
                return read_pixels(fb, w, h)
        finally:
            offscreen.free()

    plain = converge(7001)
    arrays = viewport.field_arrays(scene)
    revision = clouds.field_revision
    # A drag across the view, 8 km in front of the camera.
    y = float(cam_xy.y) + 8000.0
    for i, x in enumerate(np.linspace(cam_xy.x - 5000.0, cam_xy.x + 5000.0, 12)):
        assert live.add(float(x), y, 1.0, i == 0) is not None
    assert clouds.field_revision > revision  # written in place, not re-uploaded
    assert clouds.light_held_until == 0.0
    assert viewport.field_arrays(scene) is arrays
    # to_list(): numpy's view of a multi-dimensional gpu Buffer scrambles it on Blender 4.5.
    on_gpu = np.array(clouds.field_a.read().to_list(), np.float32).reshape(arrays[0].shape)
    np.testing.assert_array_equal(on_gpu, arrays[0])
    live_image = converge(7002)
    assert np.abs(live_image - plain).max() > 0.05  # the stroke shows
    live.commit(layer)
    fresh = {k: v.copy() for k, v in zip("abc", arrays, strict=True)}
    datafield.generate_fields(scene)  # what the stroke's end owes
    full = datafield.read_fields(s)
    for k, arr in zip("abc", full, strict=True):
        np.testing.assert_allclose(arr, fresh[k], atol=1e-6)
    final = converge(7003)
    np.testing.assert_allclose(final, live_image, atol=2e-3)
    # As the 3D view drags: the shadows wait while samples come, and follow once the drag pauses.
    # (The hold made long here: how long the view waits is a setting, not what is tested, and a busy
    # machine may take longer than 0.4 s for these redraws.)
    monkeypatch.setattr(paintstroke, "LIGHT_HOLD_S", 600.0)
    held = paintstroke.LiveStroke(scene, layer, RADIUS, 1.0, "SMOOTH", "ADD")
    converge(7004)
    fills = clouds.volume_fills
    held.add(float(cam_xy.x), y - 3000.0, 1.0, True)
    converge(7005)
    assert clouds.volume_fills == fills
    clouds.hold_light(0.0)
    converge(7006)
    assert clouds.volume_fills == fills + 1


def test_strokes_are_saved_and_undo_recomposites_from_them(blender, make_scene, tmp_path):
    from nubis_addon.blender.live import events
    from nubis_addon.blender.scene import datafield

    scene = make_scene("default")
    before = cover(scene)
    blender.ops.nubis.paint_field(channel="COVERAGE", radius=RADIUS, strength=1.0, stroke=stroke([-2000, 2000]))
    painted, n = cover(scene), len(scene.nubis.layers[-1].dabs)
    path = tmp_path / "painted.blend"
    blender.ops.wm.save_as_mainfile(filepath=str(path))
    blender.ops.wm.open_mainfile(filepath=str(path))
    scene = blender.context.scene
    assert len(scene.nubis.layers[-1].dabs) == n
    np.testing.assert_allclose(cover(scene), painted, atol=1e-6)
    datafield.generate_fields(scene)  # from the saved strokes, not the saved pixels
    np.testing.assert_allclose(cover(scene), painted, atol=1e-6)
    # What Ctrl-Z restores is the layer without the stroke's dabs; the undo handler composites from it.
    scene.nubis.layers[-1].dabs.clear()
    events.on_undo_redo()
    np.testing.assert_allclose(cover(scene), before, atol=1e-6)


def test_bad_strokes_get_a_clear_message_and_change_nothing(blender, make_scene):
    from nubis_addon.blender.scene import datafield

    scene = make_scene("default")
    a = datafield.read_fields(scene.nubis)[0].copy()
    n_layers = len(scene.nubis.layers)
    cases = [
        (dict(radius=0.0, stroke=stroke([0, 100])), "smaller than half a field pixel"),
        (dict(radius=1e7, stroke=stroke([0, 100])), "larger than the whole field"),
        (dict(stroke=stroke([9e5, 9.1e5], y=9e5)), "outside the data field"),
        (dict(stroke=stroke([float("nan"), 0])), "not NaN"),
        (dict(stroke=[]), "no points"),
        (dict(channel="STORM", stroke=stroke([0, 100])), "add one"),
    ]
    for kwargs, words in cases:
        with pytest.raises(RuntimeError, match=words):
            blender.ops.nubis.paint_field(**{"channel": "COVERAGE", "radius": RADIUS, "strength": 1.0, **kwargs})
    assert len(scene.nubis.layers) == n_layers
    np.testing.assert_array_equal(datafield.read_fields(scene.nubis)[0], a)
    # A channel given as a name the operator does not know is refused by Blender itself, with the choices.
    with pytest.raises(TypeError, match="COVERAGE"):
        blender.ops.nubis.paint_field(channel="BOTTOM_TYPE", stroke=stroke([0, 100]))
    # No cloudscape: the operator says what to make first.
    blender.ops.wm.read_factory_settings(use_empty=True)
    with pytest.raises(RuntimeError, match="New Cloudscape"):
        blender.ops.nubis.paint_field(stroke=stroke([0, 100]))


FIELD = "x -35000 to 35000 m, y -35000 to 35000 m"  # the default field's extent, as the sentences give it


def refusal(blender, **kwargs) -> str:
    """The sentence `nubis.paint_field` refuses with (Blender raises it as "Error: ...")."""
    with pytest.raises(RuntimeError) as info:
        blender.ops.nubis.paint_field(**{"channel": "COVERAGE", "radius": RADIUS, "strength": 1.0, **kwargs})
    text = str(info.value).strip()
    assert text.startswith("Error: ") and "\n" not in text, text
    return text.removeprefix("Error: ")


def test_a_stroke_to_far_away_paints_its_part_over_the_field_or_is_refused(blender, make_scene):
    """A point 1e12 m away, or at infinity (which Blender stores as float32's largest, 3.4e38): the part of
    the stroke over the field is painted, in milliseconds, and a stroke with no such part is refused."""
    import time

    from nubis_addon.blender.scene import datafield

    scene = make_scene("default")
    start = time.perf_counter()
    assert blender.ops.nubis.paint_field(channel="COVERAGE", radius=RADIUS, stroke=stroke([0.0, 1e12])) == {"FINISHED"}
    assert time.perf_counter() - start < 30.0  # a composite; no billions of dabs
    dabs = datafield.paint_dabs(scene.nubis.layers[-1])
    assert len(dabs) == 76  # 0 to 37500 m (the field's edge and the radius), 500 m apart
    assert dabs[:, 0].min() == 0.0 and dabs[:, 0].max() == 37500.0
    a = datafield.read_fields(scene.nubis)[0].copy()
    n = len(dabs)
    cases = [
        (stroke([0.0, float("inf")]), "the x of stroke point 2 must be a finite number of metres, not infinite"),
        (stroke([0.0, -1e39]), "the x of stroke point 2 must be a finite number of metres, not infinite"),
        (stroke([0.0, float("nan")]), "the x of stroke point 2 must be a finite number of metres, not NaN"),
    ]
    for points, words in cases:
        assert refusal(blender, stroke=points) == f"{words}: give finite world locations"
    outside = (
        f"the stroke lies outside the data field ({FIELD}): paint over the field, or move or enlarge it "
        "(Field > Origin, Size)"
    )
    assert refusal(blender, stroke=stroke([1e12, 2e12], y=1e12)) == outside
    assert len(scene.nubis.layers[-1].dabs) == n
    np.testing.assert_array_equal(datafield.read_fields(scene.nubis)[0], a)


def test_the_brush_radius_and_strength_as_the_docs_say(blender, make_scene):
    """Radius: finite, half a field pixel to the field's width. Strength: Blender's slider clamps it to 0-1,
    as its own sliders do (5 paints at 1); 0 and NaN are refused (docs/painting.md#what-is-refused)."""
    from nubis_addon.blender.scene import datafield

    make_scene("default")
    for value in (float("inf"), float("nan")):
        shown = "infinite" if value > 0 else "NaN"
        assert refusal(blender, radius=value, stroke=stroke([0, 100])) == (
            f"the brush radius must be a finite number of metres, not {shown}: use 68.4 to 70000 m"
        )
    assert refusal(blender, radius=1e-300, stroke=stroke([0, 100])) == (
        "the brush radius 0 m is smaller than half a field pixel (68.4 m): use at least 68.4 m, "
        "or raise the field resolution"
    )
    for value in (0.0, -3.0):
        assert refusal(blender, strength=value, stroke=stroke([0, 100])) == (
            "the brush strength 0 is not in (0, 1]: use a strength between 0.01 and 1"
        )
    assert refusal(blender, strength=float("nan"), stroke=stroke([0, 100])) == (
        "the brush strength must be a finite number, not NaN: use a strength between 0.01 and 1"
    )
    assert blender.ops.nubis.paint_field(radius=RADIUS, strength=5.0, stroke=stroke([0, 100])) == {"FINISHED"}
    layer = blender.context.scene.nubis.layers[-1]
    assert datafield.paint_dabs(layer)[:, 3].max() == 1.0


def test_a_long_composite_is_announced_and_an_absurd_one_refused(blender, make_scene, monkeypatch, capfd):
    """The notice's threshold is lowered so a short stroke passes it: the Info report and the console line
    say how long the composite takes; a composite over the memory bound is refused and changes nothing."""
    import re

    from nubis_addon.blender.live import paintstroke
    from nubis_addon.blender.scene import sceneparams
    from nubis_addon.core import console, paint, paintraster

    scene = make_scene("default")
    grid = paint.Grid.of(sceneparams.params_from_scene(scene.nubis))
    layer = paintstroke.paint_layer(scene.nubis, "COVERAGE")
    dabs = paint.stroke_dabs([(0.0, 0.0, 1.0, True), (5000.0, 0.0, 1.0, False)], RADIUS, 1.0, grid=grid)
    monkeypatch.setattr(paintraster, "NOTICE_S", 0.0)
    assert re.fullmatch(
        r"compositing 11 dabs takes about \d+ s", paintstroke.composite_notice(scene.nubis, layer, dabs, grid)
    )
    printed = []
    monkeypatch.setattr(console, "current", lambda: type("C", (), {"line": staticmethod(printed.append)})())
    capfd.readouterr()
    assert blender.ops.nubis.paint_field(radius=RADIUS, stroke=stroke([0.0, 5000.0])) == {"FINISHED"}
    info = re.findall(r"^Info: (.*)$", capfd.readouterr().out, re.MULTILINE)  # the operator's report
    assert len(info) == 1 and re.fullmatch(r"compositing 11 dabs takes about \d+ s", info[0])
    assert printed == [f"Nubis: {info[0]}"]  # the console's line, from core/paint.py's raster
    monkeypatch.undo()
    n = len(layer.dabs)
    monkeypatch.setattr(paintraster, "MEMORY_MAX", 1000)
    assert re.fullmatch(
        r"compositing 11 dabs would hold about [\d.]+ GB, over the 0 GB Nubis allows: clear or disable paint "
        r"layers, or lower the field resolution",
        refusal(blender, stroke=stroke([0.0, 5000.0])),
    )
    assert len(layer.dabs) == n


def test_a_live_drag_to_far_away_lays_its_part_and_a_full_layer_stops_it(blender, make_scene, monkeypatch):
    """A grazing view ray can land a drag's sample 1e12 m away: the drag lays the part over the field; a
    sample past the float range is no sample; the dabs are counted against the layer's cap before laying."""
    from nubis_addon.blender.live import paintstroke
    from nubis_addon.core import paint
    from nubis_addon.core.errors import NubisError

    scene = make_scene("default")
    layer = paintstroke.paint_layer(scene.nubis, "COVERAGE")
    monkeypatch.setattr(paintstroke.LiveStroke, "show", lambda _self, _rect: None)  # no view to draw into
    live = paintstroke.LiveStroke(scene, layer, RADIUS, 1.0, "SMOOTH", "ADD")
    live.add(0.0, 0.0, 1.0, True)
    live.add(1e12, 0.0, 1.0, False)
    assert live.laid == 76
    assert live.add(float("inf"), 0.0, 1.0, False) is None and live.laid == 76
    live.held = paint.MAX_DABS - 80
    with pytest.raises(NubisError) as info:
        live.add(-1e12, 0.0, 1.0, False)  # back across the field: -37500 to 37500 m, 500 m apart
    assert str(info.value) == (
        "the paint layer 'Paint Coverage' holds 999,996 dabs, and this stroke would lay 151 dabs, over the "
        "1,000,000 a paint layer holds: paint shorter strokes or with a larger radius, or start a new paint layer "
        "(Data Field > +, kind Paint)"
    )
    assert live.laid == 76
    assert live.commit(layer) == 76 and len(layer.dabs) == 76


def test_a_paint_layer_offers_only_the_channels_a_brush_paints_and_refuses_another(blender, make_scene):
    """The layer's channel menu narrows for a paint layer (the schema's channel, numbered as before, so files
    read the same); a channel no brush paints is refused where it is set, in one sentence."""
    from nubis_addon.blender.scene import datafield
    from nubis_addon.core import paint, schema
    from nubis_addon.core.errors import NubisError

    scene = make_scene("default")
    layer = scene.nubis.layers.add()
    layer.kind = "PAINT"
    offered = []
    for name in schema.FIELD_CHANNELS:
        try:
            layer.channel = name.upper()
        except TypeError as err:  # Blender's own refusal lists the menu
            assert "('COVERAGE', 'PRECIPITATION', 'TYPE', 'STORM')" in str(err)
            continue
        offered.append(name)
        assert layer["channel"] == schema.FIELD_CHANNELS.index(name)  # the number Blender stores, as before
    assert offered == list(paint.PAINT_CHANNELS)
    other = scene.nubis.layers.add()
    for name in schema.FIELD_CHANNELS:  # any other layer writes any channel
        other.channel = name.upper()
        assert other.channel == name.upper()
    # A table (a duplicate, a script) naming a channel no brush paints: refused before anything is set.
    fresh = scene.nubis.layers.add()
    with pytest.raises(NubisError) as info:
        datafield.layer_from_dict(fresh, {"name": "Rain paint", "kind": "paint", "channel": "density"})
    assert str(info.value) == (
        "the paint layer 'Rain paint' writes 'density', which a brush cannot paint: set its channel to one of "
        "coverage, precipitation, type, storm"
    )
    assert fresh.kind == "PERLIN" and fresh.name == ""
    datafield.layer_from_dict(fresh, {"channel": "storm", "kind": "paint"})  # the kind is set first
    assert (fresh.kind, fresh.channel) == ("PAINT", "STORM")
    # A layer made a paint layer after its channel keeps showing it; the composite says what to change.
    other.channel, other.kind, other.name = "BOTTOM_TYPE", "PAINT", "Turned"
    assert other.channel == "BOTTOM_TYPE"
    datafield.add_dabs(other, paint.stroke_dabs([(0.0, 0.0, 1.0, True)], RADIUS, 1.0))
    with pytest.raises(NubisError, match="'Turned' writes 'bottom_type', which a brush cannot paint"):
        datafield.generate_fields(scene)


def test_a_scenes_runtime_state_lives_in_one_object_and_ends_in_one_place(blender, make_scene):
    """Stale flag, coverage histogram, pre-paint planes and raster keys: one SceneState per scene, all gone
    with forget_stale (a file load, unregister); core/paint.py caches rasters under cloudstate's numbers."""
    from nubis_addon.blender.live import events
    from nubis_addon.blender.scene import datafield, sceneparams
    from nubis_addon.core import paintraster

    scene = make_scene("default")
    blender.ops.nubis.paint_field(channel="COVERAGE", radius=RADIUS, strength=1.0, stroke=stroke([0, 2000]))
    layer = scene.nubis.layers[-1]
    state = sceneparams.scene_state(scene)
    assert state.cover_hist is not None and state.cover_painted and state.pre_paint is not None
    key = datafield.raster_key(layer)
    assert key == datafield.raster_key(layer) and key != layer.as_pointer()
    assert key in paintraster._RASTERS and layer.as_pointer() not in paintraster._RASTERS
    events.request_composite(scene)
    assert sceneparams.field_stale(scene) and sceneparams.stale_scenes() == [scene]
    sceneparams.forget_stale()
    assert not sceneparams.field_stale(scene) and datafield.pre_paint(scene) is None and not paintraster._RASTERS
    assert datafield.coverage_multiplier(scene) == scene.nubis.density_coverage  # the saved one, until a composite
    assert datafield.raster_key(layer) != key  # a new lifetime: new keys
    datafield.generate_fields(scene)
    assert sceneparams.scene_state(scene).cover_painted


def test_the_modifier_keys_pick_the_brush_mode(blender):
    from types import SimpleNamespace

    from nubis_addon.blender.live import paintstroke
    from nubis_addon.blender.sidebar import paint as blender_paint

    def event(ctrl=False, shift=False):
        return SimpleNamespace(ctrl=ctrl, shift=shift)

    assert paintstroke.mode_of_event(event(), "SMOOTH") == "SMOOTH"
    assert paintstroke.mode_of_event(event(ctrl=True), "ADD") == "SUBTRACT"
    assert paintstroke.mode_of_event(event(shift=True), "ADD") == "SMOOTH"
    assert paintstroke.mode_of_event(event(ctrl=True, shift=True), "ADD") == "SUBTRACT"
    assert blender_paint.DRAG_HINT == "Drag: add · Ctrl: subtract · Shift: smooth"
    assert blender_paint.NubisPaintSkyTool.bl_description == (
        "Paint where the clouds are, from above: drag to add, Ctrl-drag to subtract, Shift-drag to smooth"
    )
