"""Work that runs while the artist keeps working: a bake or a render is a snapshot of the moment it
started (blender/jobs/snapshot.py, blender/jobs/work.py).

The modal operators step their work from a timer; here the same jobs (work.bake_jobs, sequence_jobs,
render_jobs) are stepped by hand, and between two steps the test does what an artist does meanwhile: the
viewport redraws (uploading its own state to the shared GPU inputs, as its draw does), the timeline moves,
a setting or a layer changes, Ctrl-Z, a save, the camera or the cloudscape is deleted. The result must be
the undisturbed one: the same active voxels and values within 1e-6, the same pixels."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT

from nubis_addon.core.jobs import BakeOptions

VOXEL = 300.0  # four tiles of the default cloudscape: steps to disturb between, seconds to bake


def _viewport_redraw(scene, light: bool = True) -> None:
    """What the 3D viewport's draw does on every redraw: its own state onto the shared GPU inputs. A bake
    reads the fields and the uniforms, never the light volumes: with `light` False the redraw leaves the
    volumes unfilled (over a second each on the suite's software rasterizer) and uploads the rest."""
    from nubis_addon.blender.host import runtime
    from nubis_addon.blender.scene import cloudstate

    runtime.cloud_gpu(scene.nubis.noise_seed).update(cloudstate.state_from_scene(scene), light=light)


def _step_all(jobs, disturb, least: int = 4) -> list:
    """Run `jobs` as the modal operator does, calling disturb(n) after the n-th step (at least `least`
    steps before the last write)."""
    from nubis_addon.blender.jobs import work

    running = work.start(work.Work("baking", jobs))
    try:
        n = 0
        while not running.done:
            running.step()
            n += 1
            disturb(n)
    finally:
        work.finish(running)
        running.close()
    assert n >= least
    return running.results


def _same_grid(a: Path, b: Path) -> None:
    from nubis_addon.core import vdbwrite

    ia, ib = vdbwrite.read_grid_info(a)["density"], vdbwrite.read_grid_info(b)["density"]
    assert ia.active_voxels == ib.active_voxels > 1000
    da, lo_a = vdbwrite.read_grid_array(a, "density")
    db, lo_b = vdbwrite.read_grid_array(b, "density")
    assert lo_a == lo_b and da.shape == db.shape
    assert float(np.abs(da - db).max()) <= 1e-6


def _metadata(path: Path) -> dict:
    from nubis_addon.core import bundled

    _grids, meta = bundled.openvdb().readAll(str(path))
    return meta


def test_a_disturbed_bake_writes_the_undisturbed_grid(make_scene, tmp_path):
    """The issue's case: viewport uploads after every step, the timeline moved 200 frames on after the
    first, the Erosion slider moved by 0.4 after the third (scene.frame_current 1 at the start)."""
    from nubis_addon.blender.jobs import pipeline, work

    scene = make_scene("default")
    start_frame, erosion = scene.frame_current, scene.nubis.density_erosion
    calm = pipeline.bake(scene, tmp_path / "calm.vdb", BakeOptions(voxel_size=VOXEL))
    jobs = work.bake_jobs(scene, str(tmp_path / "busy.vdb"), VOXEL, tiles_per_step=1)

    def disturb(n):
        _viewport_redraw(scene, light=False)
        if n == 1:
            scene.frame_set(scene.frame_current + 200)
        if n == 3:
            scene.nubis.density_erosion = erosion + 0.4
        _viewport_redraw(scene, light=False)

    [busy] = _step_all(jobs, disturb)
    _same_grid(calm.path, busy.path)
    assert busy.frame == start_frame and busy.active_voxels == calm.active_voxels
    meta = _metadata(busy.path)
    assert meta["nubis_frame"] == start_frame
    settings = json.loads(meta["nubis_settings"])
    assert settings["density_erosion"] == pytest.approx(erosion)
    assert meta["nubis_noise_seed"] == scene.nubis.noise_seed and "lighting_ambient" not in settings
    # The disturbances were real: the scene as the artist left it bakes other clouds.
    after = pipeline.bake(scene, tmp_path / "after.vdb", BakeOptions(voxel_size=VOXEL))
    assert after.active_voxels != calm.active_voxels


def test_a_disturbed_sequence_bake_writes_the_undisturbed_grids(make_scene, tmp_path):
    """Bake Sequence takes every frame's snapshot at its start and puts the timeline back on its frame;
    scrubbing, edits and viewport uploads during it change no file."""
    from nubis_addon.blender.jobs import pipeline, work

    scene = make_scene("default")
    scene.frame_set(5)
    frames = [1, 40, 80]
    calm = tmp_path / "calm"
    calm.mkdir()
    for frame in frames:
        scene.frame_set(frame)
        pipeline.bake(scene, calm / f"clouds_{frame:04d}.vdb", BakeOptions(voxel_size=VOXEL))
    scene.frame_set(5)
    scene.nubis.bake_voxel_size = VOXEL
    busy = tmp_path / "busy"
    busy.mkdir()
    jobs = work.sequence_jobs(scene, str(busy), frames, tiles_per_step=1)
    assert scene.frame_current == 5  # the snapshot of every frame is taken, and the timeline is back
    erosion = scene.nubis.density_erosion

    def disturb(n):
        scene.frame_set(scene.frame_current + 37)
        _viewport_redraw(scene, light=False)
        if n == 2:
            scene.nubis.density_erosion = erosion + 0.4
            scene.nubis.layers[0].opacity *= 0.5
            from nubis_addon.blender.scene import datafield

            datafield.generate_fields(scene)  # the layer edit's composite, as the debounced timer makes it
            _viewport_redraw(scene, light=False)

    results = _step_all(jobs, disturb)
    assert [r.frame for r in results] == frames
    for frame in frames:
        name = f"clouds_{frame:04d}.vdb"
        _same_grid(calm / name, busy / name)
        assert _metadata(busy / name)["nubis_frame"] == frame


def test_a_disturbed_render_gives_the_undisturbed_image(make_scene):
    """Render Clouds: its shot is read at the start and its GPU inputs are its own."""
    from nubis_addon.blender.jobs import pipeline, work

    scene = make_scene("default")
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 300, 140, 100
    calm = pipeline.render_viewport(scene, 300, 140)
    jobs = work.render_jobs(scene)
    camera = scene.camera

    def disturb(n):
        scene.frame_set(scene.frame_current + 200)
        scene.nubis.density_erosion += 0.1
        camera.rotation_euler.z += 0.3  # an orbit of the scene camera
        _viewport_redraw(scene)

    [busy] = _step_all(jobs, disturb, least=6)  # 3x2 tiles
    assert calm[..., 3].max() > 0.5
    np.testing.assert_allclose(busy, calm, atol=1e-6)
    assert np.abs(pipeline.render_viewport(scene, 300, 140) - calm).max() > 0.05  # the edits were real


def _undo_step(blender, scene, message):
    blender.ops.ed.undo_push(message=message)


def _act_orbit(blender, scene, tmp_path):
    scene.camera.location.x += 3000.0
    scene.camera.rotation_euler.z += 0.5


def _act_play(blender, scene, tmp_path):
    for _ in range(5):
        scene.frame_set(scene.frame_current + 1)
        _viewport_redraw(scene, light=False)


def _act_edit_layer(blender, scene, tmp_path):
    from nubis_addon.blender.scene import datafield

    scene.nubis.layers[0].opacity *= 0.3
    datafield.generate_fields(scene)


def _act_undo_redo(blender, scene, tmp_path):
    blender.ops.ed.undo_push(message="before the edit")
    scene.nubis.density_erosion += 0.4
    blender.ops.ed.undo_push(message="the edit")
    assert blender.ops.ed.undo() == {"FINISHED"}
    assert blender.ops.ed.redo() == {"FINISHED"}
    assert blender.ops.ed.undo() == {"FINISHED"}


def _act_save(blender, scene, tmp_path):
    blender.ops.wm.save_as_mainfile(filepath=str(tmp_path / "during.blend"))
    assert (tmp_path / "during.blend").exists()


def _act_delete_camera(blender, scene, tmp_path):
    blender.data.objects.remove(scene.camera)


def _act_delete_cloudscape(blender, scene, tmp_path):
    from nubis_addon.blender.host import ui
    from nubis_addon.blender.scene import datafield

    for attr, _name in datafield.FIELD_IMAGES.values():
        img = getattr(scene.nubis, attr)
        if img is not None:
            blender.data.images.remove(img)
    assert not ui.has_cloudscape(blender.context.scene)


ACTIONS = {
    "orbit": _act_orbit,
    "play the timeline": _act_play,
    "edit a layer": _act_edit_layer,
    "undo and redo": _act_undo_redo,
    "save": _act_save,
    "delete the camera": _act_delete_camera,
    "delete the cloudscape": _act_delete_cloudscape,
}


@pytest.fixture(scope="module")
def calm_bake(tmp_path_factory, make_scene_module):
    from nubis_addon.blender.jobs import pipeline

    scene = make_scene_module("default")
    path = tmp_path_factory.mktemp("calm") / "calm.vdb"
    pipeline.bake(scene, path, BakeOptions(voxel_size=VOXEL))
    return path


@pytest.fixture(scope="module")
def make_scene_module(blender):
    from nubis_addon.blender import ensure_registered
    from nubis_addon.blender.scene import scenepresets
    from nubis_addon.core.presets import load_preset

    def make(name):
        blender.ops.wm.read_factory_settings(use_empty=True)
        ensure_registered()
        scene = blender.context.scene
        scenepresets.apply_preset(scene, load_preset(name))
        return scene

    return make


@pytest.mark.parametrize("action", list(ACTIONS))
def test_what_the_artist_does_during_a_bake_leaves_its_result_alone(blender, make_scene, calm_bake, tmp_path, action):
    """Each action between the bake's steps, with the viewport redrawing after it: the result is exactly
    the snapshot's. (A scrub, a slider and the frame sequence: the tests above.)"""
    from nubis_addon.blender.jobs import work

    scene = make_scene("default")
    jobs = work.bake_jobs(scene, str(tmp_path / "busy.vdb"), VOXEL, tiles_per_step=1)

    def disturb(n):
        if n == 2:
            ACTIONS[action](blender, blender.context.scene, tmp_path)
            if blender.context.scene.camera is not None and action != "delete the cloudscape":
                _viewport_redraw(blender.context.scene, light=False)

    [busy] = _step_all(jobs, disturb)
    _same_grid(calm_bake, busy.path)


def test_a_second_bake_or_render_is_refused_while_one_runs(blender, make_scene, tmp_path):
    from nubis_addon.blender.jobs import work
    from nubis_addon.core.errors import NubisError

    scene = make_scene("default")
    running = work.start(work.Work("baking", work.bake_jobs(scene, str(tmp_path / "first.vdb"), VOXEL, 1)))
    try:
        running.step()
        # An operator's error report raises in a script (in the interface it is the status bar's message).
        with pytest.raises(
            RuntimeError, match="Nubis is already baking first.vdb: wait for it to finish, or press Esc"
        ):
            blender.ops.nubis.bake_vdb(filepath=str(tmp_path / "second.vdb"), voxel_size=VOXEL)
        with pytest.raises(RuntimeError, match="already baking"):
            blender.ops.nubis.render_image()
        assert blender.data.images.get("Nubis Render") is None
        second = work.Work("rendering", work.render_jobs(scene))
        with pytest.raises(NubisError, match="already baking first.vdb: wait for it to finish, or press Esc"):
            work.start(second)
        assert second.done  # refused work is closed, not left half-run
        assert work.current() is running
    finally:
        work.finish(running)
        running.close()
    assert not (tmp_path / "second.vdb").exists() and not (tmp_path / "first.vdb").exists()
    assert blender.ops.nubis.bake_vdb(filepath=str(tmp_path / "second.vdb"), voxel_size=VOXEL) == {"FINISHED"}


@pytest.mark.parametrize("how", ["open another file", "file new"])
def test_opening_a_file_cancels_the_work_and_keeps_the_earlier_file(blender, make_scene, tmp_path, how):
    from nubis_addon.blender.jobs import pipeline, work

    scene = make_scene("default")
    path = tmp_path / "clouds.vdb"
    pipeline.bake(scene, path, BakeOptions(voxel_size=2 * VOXEL))
    before = path.read_bytes()
    other = tmp_path / "other.blend"
    blender.ops.wm.save_as_mainfile(filepath=str(other), copy=True)
    running = work.start(work.Work("baking", work.bake_jobs(scene, str(path), VOXEL, 1)))
    running.step()
    if how == "file new":
        blender.ops.wm.read_homefile(use_empty=True)
    else:
        blender.ops.wm.open_mainfile(filepath=str(other))
    assert work.current() is None and running.cancelled == "another file was opened" and running.done
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clouds.vdb", "other.blend"]


def test_quitting_during_a_bake_cancels_it_and_keeps_the_earlier_file(cache_dir, tmp_path):
    """Blender quits (here the process exits) half way through a bake: the old file stays byte for byte,
    nothing is left beside it, and the console says why."""
    path = tmp_path / "clouds.vdb"
    script = tmp_path / "quit.py"
    script.write_text(
        textwrap.dedent(
            f"""
            import atexit, os, sys
            sys.path.insert(0, {str(ROOT)!r})
            # Registered first, so it runs last: no teardown of Blender as a module after the extension's
            # own exit handler (4.5's crashes in it, as the command line's would: nubis_addon/__main__.py).
            atexit.register(lambda: (sys.stdout.flush(), sys.stderr.flush(), os._exit(0)))
            import bpy, nubis_addon
            from nubis_addon.render.gpu_context import ensure_gpu_context
            nubis_addon.register()
            ensure_gpu_context()
            from nubis_addon.blender.scene import datafield, cloudstate, scenepresets
            from nubis_addon.blender.jobs import pipeline, work
            from nubis_addon.core.jobs import BakeOptions
            from nubis_addon.core.presets import load_preset
            scene = bpy.context.scene
            scenepresets.apply_preset(scene, load_preset("default"))
            pipeline.bake(scene, {str(path)!r}, BakeOptions(voxel_size={2 * VOXEL}))
            open({str(path)!r} + ".before", "wb").write(open({str(path)!r}, "rb").read())
            running = work.start(work.Work("baking", work.bake_jobs(scene, {str(path)!r}, {VOXEL}, 1)))
            running.step()
            print("QUITTING", flush=True)
            sys.exit(0)
            """
        )
    )
    env = {**os.environ, "NUBIS_CACHE_DIR": str(cache_dir)}
    proc = subprocess.run([sys.executable, str(script)], env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "QUITTING" in proc.stdout
    assert "Baking cancelled (Blender quit): nothing was written" in proc.stderr
    assert path.read_bytes() == (tmp_path / "clouds.vdb.before").read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clouds.vdb", "clouds.vdb.before", "quit.py"]


def test_ctrl_z_after_a_bake_removes_the_volume_and_keeps_the_file(blender, make_scene, tmp_path):
    """Bake VDB is one undo step (Blender pushes it when an UNDO operator finishes; background mode does not,
    so the test pushes where the interface would)."""
    from nubis_addon.blender.scene import cycles_setup
    from nubis_addon.blender.sidebar import operators

    make_scene("default")
    path = tmp_path / "clouds.vdb"
    blender.ops.ed.undo_push(message="before the bake")
    assert blender.ops.nubis.bake_vdb(filepath=str(path), voxel_size=VOXEL) == {"FINISHED"}
    blender.ops.ed.undo_push(message=operators.NUBIS_OT_bake_vdb.bl_label)
    assert blender.data.objects.get(cycles_setup.VOLUME_NAME) is not None
    assert blender.ops.ed.undo() == {"FINISHED"}
    assert blender.data.objects.get(cycles_setup.VOLUME_NAME) is None
    assert path.stat().st_size > 1000
    assert blender.ops.ed.redo() == {"FINISHED"}
    assert blender.data.objects.get(cycles_setup.VOLUME_NAME) is not None


# Operators that change no undoable data, and why.
NO_UNDO = {
    "nubis.view_toggle": "shows or hides the clouds in this view: a view setting, as Blender's overlays are",
    "nubis.render_image": "writes an image's pixels, which Blender's undo does not keep (as its Render Result)",
    "nubis.benchmark": "measures; changes nothing",
    "nubis.clear_cache": "deletes cache files on disk, which undo cannot bring back",
    "nubis.report": "shows a message",
    "nubis.preset_remove": "deletes a preset file on disk, which undo cannot bring back",
}


def test_every_operator_that_changes_data_is_one_undo_step(blender):
    import bpy

    import nubis_addon.blender.host.mainthread as mainthread
    import nubis_addon.blender.sidebar.operators as operators
    import nubis_addon.blender.sidebar.skylayers as skylayers
    import nubis_addon.blender.sidebar.stormbuttons as stormbuttons

    classes = [*operators.CLASSES, *skylayers.CLASSES, *stormbuttons.CLASSES, mainthread.NUBIS_OT_report]
    missing = []
    for cls in classes:
        if not issubclass(cls, bpy.types.Operator):
            continue
        if "UNDO" not in getattr(cls, "bl_options", set()) and cls.bl_idname not in NO_UNDO:
            missing.append(cls.bl_idname)
    assert missing == []
    assert {"nubis.preset_add", "nubis.bake_vdb", "nubis.bake_frames"} <= {
        c.bl_idname for c in classes if "UNDO" in getattr(c, "bl_options", set())
    }
