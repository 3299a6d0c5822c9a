"""VDB clouds in a scene that go wrong: a damaged file in a saved .blend, a fifth marked Volume, an object
scaled to zero, clouds over the GPU budget, an error inside the draw. The other clouds draw, the sidebar
and the commands say why in one sentence, nothing raises from the draw (docs/vdb.md#damaged-files)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from vdb_helpers import write_cumulus  # noqa: E402


@pytest.fixture(scope="module")
def small_cloud(tmp_path_factory) -> Path:
    return write_cumulus(tmp_path_factory.mktemp("vdb") / "small.vdb", n_xy=24, n_z=16)


def _scene_with(blender, make_scene, paths):
    scene = make_scene("default")
    scene.nubis.density_cover, scene.nubis.cirrus_coverage = 0.0, 0.0
    objs = []
    for name, path in paths:
        vol = blender.data.volumes.new(name)
        vol.filepath = str(path)
        obj = blender.data.objects.new(name, vol)
        scene.collection.objects.link(obj)
        vol.nubis_cloud.enabled = True
        objs.append(obj)
    return scene, objs


def test_a_damaged_file_in_a_saved_blend_is_left_out_and_said(blender, make_scene, small_cloud, tmp_path):
    from nubis_addon.blender import ensure_registered
    from nubis_addon.blender.host import status
    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.blender.scene import cloudstate, vdbclouds
    from nubis_addon.core.errors import NubisError

    cut = tmp_path / "cut.vdb"
    cut.write_bytes(small_cloud.read_bytes()[:2000])
    _scene_with(blender, make_scene, [("A good", small_cloud), ("B cut", cut)])
    blend = tmp_path / "clouds.blend"
    blender.ops.wm.save_as_mainfile(filepath=str(blend))
    blender.ops.wm.open_mainfile(filepath=str(blend))
    ensure_registered()
    scene = blender.context.scene
    status.clear_error()
    try:
        drawn = cloudstate.state_from_scene(scene, wait=False).vdb_clouds
        assert [Path(p.cloud.path).resolve() for p in drawn] == [small_cloud.resolve()]
        said = status.last_error()
        assert "the Nubis cloud 'B cut' is not drawn:" in said and "is damaged (cut short" in said, said
        assert "\n" not in said and len(said) < 1000
        assert "is damaged" in vdbclouds.problem(scene.objects["B cut"])
        with pytest.raises(NubisError, match=r"the Nubis cloud 'B cut': '.*cut.vdb' is damaged \(cut short"):
            pipeline.render_viewport(scene, 32, 18)
    finally:
        status.clear_error()


def test_nothing_raises_from_the_draw_handler(blender, make_scene, monkeypatch):
    import types

    from nubis_addon.blender.host import status
    from nubis_addon.blender.live import viewport

    scene = make_scene("default")
    context = types.SimpleNamespace(
        scene=scene,
        region=types.SimpleNamespace(width=32, height=18, as_pointer=lambda: 1),
        region_data=object(),
        space_data=types.SimpleNamespace(shading=types.SimpleNamespace(type="SOLID")),
        screen=None,
        area=None,
    )

    def broken(*_args):
        raise KeyError("Map is not registered")

    monkeypatch.setattr(viewport, "draw_region", broken)
    try:
        assert viewport.draw_in_context(context)  # no exception escapes
        assert status.last_error().startswith("the clouds could not be drawn (KeyError: 'Map is not registered')")
    finally:
        status.clear_error()


def test_a_fifth_marked_volume_is_left_out_and_said(blender, make_scene, small_cloud, capfd):
    from nubis_addon.blender.host import status
    from nubis_addon.blender.scene import cloudstate, vdbclouds
    from nubis_addon.core import console

    scene, objs = _scene_with(blender, make_scene, [(f"Cloud {n}", small_cloud) for n in range(1, 6)])
    status.clear_error()
    try:
        assert len(cloudstate.state_from_scene(scene, wait=False).vdb_clouds) == 4
        words = "the Nubis cloud 'Cloud 5' is left out: at most 4 VDB clouds are drawn at once"
        assert status.last_error().startswith(words)
        assert vdbclouds.problem(objs[4]).startswith(words) and not vdbclouds.problem(objs[0])
        capfd.readouterr()
        # As a command starts: its own terminal (the one this test captures; an earlier test's may be
        # the process's first stderr) and its own notes (an earlier test's Cloud 5 may have been told).
        terminal = console.Console()
        console.push(terminal)
        try:
            vdbclouds.forget_notes()
            assert len(vdbclouds.placements(scene, strict=True)) == 4  # a command goes on, and says so
        finally:
            console.pop(terminal)
        assert f"nubis: note: {words}" in capfd.readouterr().err
        # In a final render it is not drawn by Blender either: hidden with the four for the frame.
        vdbclouds.step_aside(scene)
        assert all(o.hide_render for o in objs)
        vdbclouds.step_back(scene)
        assert not any(o.hide_render for o in objs)
    finally:
        status.clear_error()


def test_an_object_scaled_to_zero_is_one_sentence(blender, make_scene, small_cloud):
    from nubis_addon.blender.host import status
    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.blender.scene import cloudstate
    from nubis_addon.core.errors import NubisError

    scene, (obj,) = _scene_with(blender, make_scene, [("Flat", small_cloud)])
    obj.scale = (1.0, 0.0, 1.0)
    blender.context.view_layer.update()
    status.clear_error()
    try:
        assert cloudstate.state_from_scene(scene, wait=False).vdb_clouds == ()
        assert "is scaled to zero along an axis" in status.last_error()
        with pytest.raises(NubisError, match="the Nubis cloud 'Flat': the object of the Nubis cloud 'Flat' is scaled"):
            pipeline.render_viewport(scene, 32, 18)
    finally:
        status.clear_error()


def test_a_refused_upload_leaves_no_half_made_textures(blender, make_scene, small_cloud):
    """Clouds over the GPU budget at upload: the sentence, no VDB textures bound, and the next update
    without them draws (a refused cloud used to raise a TypeError on the redraw after)."""
    import dataclasses

    from nubis_addon.blender.host import runtime
    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.blender.scene import cloudstate
    from nubis_addon.core.errors import NubisError

    scene, _objs = _scene_with(blender, make_scene, [("Cloud", small_cloud)])
    state = cloudstate.state_from_scene(scene)
    clouds = runtime.cloud_gpu(scene.nubis.noise_seed).fork()
    with pytest.raises(NubisError, match="the VDB clouds need .* on the GPU together, over the 1.0 KB"):
        clouds.update(dataclasses.replace(state, vdb_gpu_budget=1024))
    assert clouds.switches["NUBIS_VDB"] == 0 and clouds.vdb.atlas is None and clouds.vdb.key == ()
    clouds.update(dataclasses.replace(state, vdb_clouds=()))
    clouds.update(state)  # within the budget again: drawn
    assert clouds.switches["NUBIS_VDB"] == 1 and clouds.vdb.atlas is not None
    assert pipeline.render_viewport(scene, 32, 18)[..., 3].max() > 0.1
