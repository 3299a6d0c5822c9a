"""The noise cache in the interface and the user's presets, in background Blender: noise for a new seed
is made off the draw callback and a seed drag leaves the cache bounded; Clear Cache empties it; a
saved preset loads back to every setting, and only the user's own presets can be removed."""

from __future__ import annotations

import math
import shutil
import time
import types

import numpy as np
import pytest


class LabelLayout:
    """Stands in for bpy's UILayout: records the labels and operators a draw() asks for."""

    def __init__(self, record: list | None = None):
        self.record = [] if record is None else record
        self.use_property_split = self.use_property_decorate = False
        self.active = True

    def _sub(self, *_args, **_kwargs):
        return LabelLayout(self.record)

    row = column = box = split = _sub

    def label(self, text="", **_kwargs):
        self.record.append(("label", text))

    def operator(self, idname, **_kwargs):
        self.record.append(("operator", idname))
        return types.SimpleNamespace()

    def prop(self, _owner, key, **_kwargs):
        self.record.append(("prop", key))

    def menu(self, idname, text="", **_kwargs):
        self.record.append(("menu", text))

    def separator(self, **_kwargs):
        pass

    operator_menu_enum = template_list = prop_search = template_ID = lambda self, *a, **k: None

    def labels(self) -> str:
        return "\n".join(text for kind, text in self.record if kind == "label")


@pytest.fixture
def own_cache(tmp_path, monkeypatch, blender):
    """An empty cache folder of the test's own, and no noise on the GPU or on the worker."""
    from nubis_addon.blender.host import runtime

    folder = tmp_path / "cache"
    monkeypatch.setenv("NUBIS_CACHE_DIR", str(folder))
    runtime.free()
    yield folder
    runtime.wait_for_noise(120)
    runtime.free()


def _draw(scene, viewport, w=32, h=18):
    """One interface-style draw of the scene camera's view (the noise not waited for), timed; returns the
    temporal view or None, the seconds it took and the drawn pixels."""
    import gpu

    from nubis_addon.blender.scene import cloudstate
    from nubis_addon.render.offscreens import read_pixels

    inv = cloudstate.camera_inv_view_proj(scene, w, h)
    offscreen = gpu.types.GPUOffScreen(w, h, format="RGBA32F")
    try:
        with offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
            t0 = time.perf_counter()
            request = viewport.ViewDraw(inv, scene.camera.matrix_world.translation, w, h, key="async")
            tv = viewport.draw_view(scene, request, wait_for_noise=False)
            seconds = time.perf_counter() - t0
            pixels = read_pixels(fb, w, h)
    finally:
        offscreen.free()
    return tv, seconds, pixels


def test_noise_is_made_off_the_draw_and_a_seed_drag_keeps_the_cache_bounded(make_scene, own_cache):
    from nubis_addon.blender.host import runtime
    from nubis_addon.blender.live import viewport
    from nubis_addon.blender.sidebar import panels
    from nubis_addon.core import noise

    scene = make_scene("default")
    s = scene.nubis
    s.noise_seed = 101
    s.viewport_samples = 1
    tv, seconds, pixels = _draw(scene, viewport)
    # Nothing on the GPU yet: the draw returns at once and draws nothing; the sidebar says why.
    assert tv is None and pixels.max() == 0.0
    assert seconds < 1.0, seconds  # generating a set takes seconds (about 4 s on the 2-core machine)
    assert runtime.noise_generating() == 101
    layout = LabelLayout()
    panels.NUBIS_PT_main.draw(types.SimpleNamespace(layout=layout), types.SimpleNamespace(scene=scene))
    assert "Generating noise for seed 101..." in layout.labels()
    # A drag through ten values while the first is made: every draw returns at once.
    slowest = 0.0
    for seed in range(102, 111):
        s.noise_seed = seed
        slowest = max(slowest, _draw(scene, viewport)[1])
    assert slowest < 1.0, slowest
    runtime.wait_for_noise(120)
    # The first set is ready: the next draw takes it and shows seed 101's clouds while it asks for 110.
    tv, _seconds, pixels = _draw(scene, viewport)
    assert tv is not None and pixels[..., 3].max() > 0.0
    assert runtime.noise_generating() == 110
    runtime.wait_for_noise(120)
    tv, _seconds, pixels = _draw(scene, viewport)
    assert runtime.cloud_gpu_nowait(110).noise.seed == 110 and runtime.noise_generating() is None
    layout = LabelLayout()
    panels.NUBIS_PT_main.draw(types.SimpleNamespace(layout=layout), types.SimpleNamespace(scene=scene))
    assert "Generating" not in layout.labels()
    # Only the first and the last seed of the drag were made, and the cache stays within its bounds.
    assert sorted(p.name for p in own_cache.glob("noise_*.npz")) == [noise.cache_file_name(x) for x in (101, 110)]
    usage = noise.cache_usage(own_cache)
    assert usage.sets <= noise.CACHE_MAX_SEEDS and usage.nbytes <= noise.CACHE_MAX_BYTES
    assert usage.nbytes < 2 * 0.65 * 9_322_496  # compressed: two sets in less than 1.3 uncompressed ones
    # Headless callers still get their noise at once, from the cache the worker wrote.
    assert runtime.cloud_gpu(101).noise.seed == 101


def test_clear_cache_empties_it_and_the_preferences_show_it(blender, own_cache, cache_dir):
    from nubis_addon.blender.host import preferences, runtime
    from nubis_addon.core import noise

    noise.load_or_generate(cache_dir, 0)  # the session's cache holds seed 0 now
    own_cache.mkdir(parents=True, exist_ok=True)
    for seed in (0, 5):
        shutil.copy(cache_dir / noise.cache_file_name(0), own_cache / noise.cache_file_name(seed))
    assert noise.cache_usage(own_cache).sets == 2
    prefs = preferences.NubisPreferences
    assert prefs.bl_idname == runtime._EXT_PACKAGE == "nubis_addon"
    assert prefs.is_registered
    layout = LabelLayout()
    prefs.draw(types.SimpleNamespace(layout=layout), blender.context)
    assert str(own_cache) in layout.labels() and "2 noise sets" in layout.labels()
    assert ("operator", "nubis.clear_cache") in layout.record
    assert blender.ops.nubis.clear_cache() == {"FINISHED"}
    assert noise.cache_usage(own_cache) == noise.CacheUsage(own_cache, 0, 0)
    layout = LabelLayout()
    prefs.draw(types.SimpleNamespace(layout=layout), blender.context)
    assert "0 noise sets, 0.0 MB" in layout.labels()


def _f32(x):
    return float(np.float32(x))


def _edit_everything(scene, blender):
    """Move every setting of the cloudscape off the preset's value: scene settings, a layer, a storm and
    its Empty, the sun, the World, the camera and the render settings."""
    from nubis_addon.blender.scene import sceneparams, sky, skyground
    from nubis_addon.core import schema

    s = scene.nubis
    with sceneparams.batch_edit():
        for i, setting in enumerate(schema.PRESET_SCENE):
            if setting.key in ("layer_bottom", "layer_top", "march_steps_min", "march_steps_max", "field_resolution"):
                continue
            value = getattr(s, setting.key)
            if setting.kind == "bool":
                setattr(s, setting.key, not value)
            elif setting.kind == "int":
                setattr(s, setting.key, value + 1 if value + 1 <= (setting.max or value + 1) else value - 1)
            elif setting.kind == "float":
                lo = setting.min if setting.min is not None else value - 1.0
                hi = setting.max if setting.max is not None else value + 1.0
                setattr(s, setting.key, lo + (hi - lo) * (0.31 + 0.01 * (i % 5)))
        s.layer_bottom, s.layer_top = 1234.5, 4321.25
        s.march_steps_min, s.march_steps_max = 33, 77
        s.field_resolution = 64
        layer = s.layers[0]
        layer.opacity, layer.seed, layer.blend, layer.remap = 0.7, 99, "MAX", (0.1, 0.8, 0.05, 0.95)
        s.storms[0].radius, s.storms[0].glow_color = 9876.5, (0.2, 0.4, 0.6)
    s.storms[0].empty.location = (3210.0, -4567.5, 0.0)
    sun = skyground.find_sun(scene)
    sun.rotation_euler = (math.radians(30.0), math.radians(10.0), math.radians(200.0))
    sun.data.color, sun.data.energy, sun.data.angle = (0.9, 0.8, 0.7), 7.5, math.radians(1.5)
    from nubis_addon.blender.scene import skyground

    assert sky.is_nubis_sky(scene.world)  # the preset's physically based sky: its atmosphere round-trips
    scene.world.color = (0.1, 0.2, 0.3)
    scene.world[sky.STRENGTH_KEY] = 1.75
    node = sky.sky_node(scene.world)
    node.air_density, node.ozone_density = 1.5, 0.5
    scene.camera.location = (100.0, -200.0, 30.0)
    scene.camera.rotation_euler = (math.radians(85.0), 0.0, math.radians(-20.0))
    scene.camera.data.lens, scene.camera.data.clip_end = 35.0, 150000.0
    scene.render.resolution_x, scene.render.resolution_y = 320, 200
    scene.frame_current = 17
    scene.cycles.samples, scene.cycles.volume_bounces = 48, 5
    scene.view_settings.view_transform = "Standard"
    blender.context.view_layer.update()


def _snapshot(scene):
    """Every setting as Blender holds it: the schema's, the layers', the storms', and the objects'."""
    from nubis_addon.blender.scene import datafield, sceneparams, sky, skyground, superstorms
    from nubis_addon.core import schema

    s = scene.nubis
    sun = skyground.find_sun(scene)
    direction = sceneparams.evaluated_matrix(sun).to_3x3().col[2]
    from nubis_addon.blender.scene import skyground

    return {
        "settings": {k.key: sceneparams.from_blender(k, getattr(s, k.key)) for k in schema.PRESET_SCENE},
        "layers": [datafield.layer_to_dict(layer) for layer in s.layers],
        "storms": [(sceneparams.table_to_dict(st, schema.STORM), superstorms.storm_centre(st)) for st in s.storms],
        "sun": (list(direction), list(sun.data.color), sun.data.energy, sun.data.angle),
        "world": sky.atmosphere(scene.world),
        "camera": (
            list(scene.camera.location),
            list(scene.camera.rotation_euler),
            scene.camera.data.lens,
            scene.camera.data.clip_end,
        ),
        "render": (
            scene.render.resolution_x,
            scene.render.resolution_y,
            scene.frame_current,
            scene.cycles.samples,
            scene.cycles.volume_bounces,
            scene.view_settings.view_transform,
        ),
    }


def test_a_saved_user_preset_loads_back_to_every_setting(make_scene, blender, tmp_path, monkeypatch):
    from nubis_addon.blender.scene import datafield
    from nubis_addon.blender.sidebar import operators
    from nubis_addon.core import presets, schema

    monkeypatch.setenv("NUBIS_PRESET_DIR", str(tmp_path / "presets"))
    scene = make_scene("superstorm")
    _edit_everything(scene, blender)
    before = _snapshot(scene)
    r = blender.ops.nubis.preset_add(name="Dusk Storm", preset_description="A storm at dusk, saved by the test")
    assert r == {"FINISHED"}
    path = tmp_path / "presets" / "dusk_storm.toml"
    assert path.is_file() and scene.nubis.preset == "dusk_storm"
    assert sorted(p.name for p in path.parent.iterdir()) == ["dusk_storm.toml"]
    # The menu lists it after the shipped ones, with its description as the tooltip.
    from nubis_addon.blender.host import presetlist

    entries = presetlist.preset_entries()
    assert [e.user for e in entries] == [False] * len(presets.list_presets()) + [True]
    assert entries[-1].name == "Dusk Storm"
    props = types.SimpleNamespace(filepath=str(path))
    assert operators.NUBIS_OT_preset_load.description(None, props) == "A storm at dusk, saved by the test"
    assert presetlist.active_preset(blender.context).path == path
    # The main panel's preset row: the menu shows the active preset, with + and - beside it.
    from nubis_addon.blender.sidebar import panels

    layout = LabelLayout()
    panels.NUBIS_PT_main.draw(types.SimpleNamespace(layout=layout), types.SimpleNamespace(scene=scene))
    row = layout.record[layout.record.index(("menu", "Dusk Storm")) :][:3]
    assert row == [("menu", "Dusk Storm"), ("operator", "nubis.preset_add"), ("operator", "nubis.preset_remove")]
    layout = LabelLayout()
    panels.NUBIS_MT_presets.draw(types.SimpleNamespace(layout=layout), blender.context)
    assert [k for k in layout.record if k[0] == "operator"] == [("operator", "nubis.preset_load")] * len(entries)

    # A different cloudscape in a fresh file, then the saved preset loaded from the menu.
    scene = make_scene("clear_sky")
    other = _snapshot(scene)["settings"]
    assert sum(other[k] != v for k, v in before["settings"].items()) > 0.9 * len(before["settings"])
    assert blender.ops.nubis.preset_load(filepath=str(path)) == {"FINISHED"}
    blender.context.view_layer.update()
    after = _snapshot(scene)
    for setting in schema.PRESET_SCENE:
        if setting.key == "density_coverage":  # derived from Coverage for the field at each composite
            continue
        assert after["settings"][setting.key] == before["settings"][setting.key], setting.key
    # ... and the multiplier a composite finds from the saved Coverage is the one the saved scene drew with.
    assert after["settings"]["density_coverage"] == pytest.approx(datafield.coverage_multiplier(scene), rel=1e-4)
    assert after["layers"] == before["layers"]
    assert after["storms"] == before["storms"]
    np.testing.assert_allclose(after["sun"][0], before["sun"][0], atol=1e-5)
    assert after["sun"][1:3] == before["sun"][1:3]  # color and strength
    assert after["sun"][3] == pytest.approx(before["sun"][3], rel=1e-6)  # the angle, through degrees
    assert after["world"] == before["world"]
    assert after["camera"][0] == before["camera"][0]
    np.testing.assert_allclose(after["camera"][1], before["camera"][1], atol=1e-6)
    assert after["camera"][2:] == before["camera"][2:]
    assert after["render"] == before["render"]
    # The field was composited from the loaded stack: the sidebar and the viewport are up to date.
    assert scene.nubis.field_a is not None and tuple(scene.nubis.field_a.size) == (64, 64)


def test_remove_deletes_the_users_preset_and_refuses_a_shipped_one(make_scene, blender, tmp_path, monkeypatch):
    from nubis_addon.core import presets

    monkeypatch.setenv("NUBIS_PRESET_DIR", str(tmp_path / "presets"))
    scene = make_scene("default")
    assert not blender.ops.nubis.preset_remove.poll()  # the active preset is a shipped one
    assert blender.ops.nubis.preset_add(name="Mine") == {"FINISHED"}
    mine = tmp_path / "presets" / "mine.toml"
    assert mine.is_file() and blender.ops.nubis.preset_remove.poll()
    shipped = presets.find_preset("default")
    with pytest.raises(RuntimeError, match="shipped with Nubis"):
        blender.ops.nubis.preset_remove(name="default")
    assert shipped.is_file() and mine.is_file()
    with pytest.raises(RuntimeError, match="shipped with Nubis"):
        blender.ops.nubis.preset_add(name="Default")
    assert blender.ops.nubis.preset_remove() == {"FINISHED"}
    assert not mine.exists() and shipped.is_file()
    assert not blender.ops.nubis.preset_remove.poll()
    assert scene.nubis.preset == "mine"  # the cloudscape itself is untouched
