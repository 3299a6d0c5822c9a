"""Test harness: Blender (the bpy module) in background mode, with a GPU context on Mesa llvmpipe.

GPU tests fail loudly when no context can be made; nothing here skips itself to green.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


@pytest.fixture(scope="session")
def cache_dir(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("nubis-cache")
    os.environ["NUBIS_CACHE_DIR"] = str(path)
    return path


@pytest.fixture(scope="session")
def blender(cache_dir):
    """bpy with the add-on registered and a working GPU context."""
    import bpy

    import nubis_addon
    from nubis_addon.render.gpu_context import ensure_gpu_context, renderer_name

    nubis_addon.register()
    ensure_gpu_context()
    print(f"GPU: {renderer_name()}")
    yield bpy


@pytest.fixture
def make_scene(blender):
    """A fresh factory scene turned into a preset's cloudscape; `overrides` edit the preset first."""
    from nubis_addon.blender import ensure_registered
    from nubis_addon.blender.scene import scenepresets
    from nubis_addon.core.presets import load_preset

    def make(name: str = "default", **overrides):
        preset = load_preset(name)
        for key, value in overrides.items():
            if key in preset.params:
                preset.params[key] = value
            else:
                section, field = key.split("__")
                preset.extra[section][field] = value
        blender.ops.wm.read_factory_settings(use_empty=True)
        ensure_registered()
        scene = blender.context.scene
        scenepresets.apply_preset(scene, preset)
        return scene

    return make


def run_cli(
    *args: str, cwd: Path = ROOT, env: dict | None = None, timeout: int = 600, preexec_fn=None
) -> subprocess.CompletedProcess:
    """`python -m nubis_addon ...` in a child process, as a user would run it (`preexec_fn` runs in the child
    first: a memory cap, say)."""
    full_env = dict(os.environ)
    full_env.update(env or {})
    return subprocess.run(
        [sys.executable, "-m", "nubis_addon", *args],
        cwd=cwd,
        env=full_env,
        capture_output=True,
        text=True,
        timeout=timeout,
        preexec_fn=preexec_fn,
    )


_exit_status: list[int] = []


def pytest_sessionfinish(session, exitstatus):
    _exit_status.append(int(exitstatus))


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    """Leave without interpreter teardown once pytest has reported: tearing down Blender's module
    (its GPU context on EGL, nanobind's bindings) can crash after every test has passed, and that
    crash would turn a green run red. The exit status is pytest's own."""
    if _exit_status and "bpy" in sys.modules:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(_exit_status[-1])


# The test files that take a worker longest (over 24 s each on the 2-core machine, docs/measurements.md#ci),
# longest first, handed out in this order (`--no-loadscope-reorder`: xdist would otherwise order the files by
# their number of tests): each file runs whole in one of the two workers (`--dist loadfile`), and a long file
# handed out last kept one worker busy alone at the end of the run.
LONGEST_FIRST = (
    "gpu/test_objects_in_clouds.py",
    "gpu/test_sky.py",
    "cli/test_robustness.py",
    "gpu/test_full_parity.py",
    "gpu/test_parity.py",
    "gpu/test_vdb_transforms.py",
    "gpu/test_reference.py",
    "cli/test_cli.py",
    "gpu/test_audit.py",
    "gpu/test_temporal.py",
    "cli/test_distributed_robustness.py",
    "cli/test_bake_vanishing_cli.py",
    "gpu/test_vdb_levels.py",
    "gpu/test_bake_cycles.py",
    "gpu/test_superstorm.py",
    "cli/test_realtime_cli.py",
    "cli/test_vdb_cli.py",
    "gpu/test_layered_sky.py",
    "gpu/test_vdb_clouds.py",
    "gpu/test_light_volumes.py",
)


# The tests CI runs on the older Blender lines too (`-m lines`; 5.3 runs every test): each surface of
# Blender's own API the extension uses, once, where the lines differ (docs/measurements.md#ci). The rest
# measure the project's own GLSL, numpy and command line, the same code on every line, on 5.3 only (the
# whole suite on an older line, `.venv-4.5/bin/python -m pytest -q`, is run by hand). By file: "*" is every
# test in it, else test names (every case of a parametrized test). A name that matches nothing fails the
# collection, so a renamed test cannot fall out of the lines unnoticed.
EVERY_LINE = {
    # the GPU module: a context in background mode, shader compiles, offscreen draws, the 3D view's handler
    "gpu/test_gpu_render.py": "*",
    "gpu/test_density.py": ("test_gpu_density_matches_oracle", "test_oracle_sampler_reproduces_the_gpu_filter"),
    "gpu/test_temporal.py": (
        "test_a_3d_view_region_draws_converges_and_culls",
        "test_viewport_reads_the_depth_once_per_change",
    ),
    # properties, panels, poll messages, operators, handlers, undo, save and reload
    "gpu/test_panels.py": "*",
    "gpu/test_live_edits.py": "*",
    "gpu/test_blend_file.py": "*",
    "gpu/test_authoring.py": "*",
    "gpu/test_bake_ui.py": "*",
    "gpu/test_snapshot.py": ("test_every_operator_that_changes_data_is_one_undo_step",),
    "gpu/test_paint.py": (
        "test_a_stroke_raises_the_cover_under_it_and_leaves_the_rest_exactly",
        "test_the_modifier_keys_pick_the_brush_mode",
    ),
    "gpu/test_layered_sky.py": ("test_a_layer_added_in_the_sidebar_is_saved_and_read_back",),
    "gpu/test_superstorm.py": ("test_lightning_keyframe_lights_its_frame_only",),
    "gpu/test_noise_and_presets.py": ("test_clear_cache_empties_it_and_the_preferences_show_it",),
    # the World's Sky Texture, F12 in EEVEE and Cycles with objects in the clouds, Render Animation
    "gpu/test_sky.py": (
        "test_new_cloudscape_builds_a_sky_tied_to_the_sun",
        "test_final_render_shows_clouds_behind_the_cube_and_their_moving_shadows",
    ),
    "gpu/test_objects_in_clouds.py": ("test_without_an_object_in_the_clouds_the_render_keeps_its_background",),
    "gpu/test_render_animation.py": "*",
    "gpu/test_sun_air.py": ("test_f12_at_minus_one_degree_shows_lit_clouds_over_an_unlit_ground",),
    # OpenVDB and Volume objects: the bake written and rendered by Cycles, marked VDB clouds, sequences
    "gpu/test_bake_cycles.py": ("test_vdb_has_density_grid_transform_and_voxels", "test_cycles_renders_the_bake"),
    "gpu/test_vdb_clouds.py": (
        "test_the_shader_reads_the_grid_where_its_object_puts_it",
        "test_a_vdb_sequence_follows_the_timeline_as_blender_reads_it",
    ),
    # the command line: OpenImageIO's images, `blender --command`, the extension built and installed
    "cli/test_cli.py": (
        "test_render_default_png_and_exr",
        "test_bake_and_cycles_commands",
        "test_openvdb_10_reads_the_bake_of_this_line",
        "test_blender_command_is_registered_and_runs",
    ),
    "cli/test_extension.py": "*",
    "cli/test_realtime_cli.py": ("test_preview_writes_each_frame_and_its_redraw_times",),
    "cli/test_robustness.py": ("test_interrupt_ends_with_one_line_its_exit_code_and_no_temp_files",),
}


def _on_every_line(items) -> None:
    """Mark EVERY_LINE's tests `lines`, and tests/core's `core`; refuse a name that matches no test."""
    found = set()
    for item in items:
        path = item.nodeid.split("::")[0].removeprefix("tests/")
        if path.startswith("core/"):
            item.add_marker(pytest.mark.core)
        names = EVERY_LINE.get(path)
        name = getattr(item, "originalname", item.name)
        if names == "*" or (names and name in names):
            item.add_marker(pytest.mark.lines)
            found.add((path, "*" if names == "*" else name))
    collected = {item.nodeid.split("::")[0].removeprefix("tests/") for item in items}
    missing = [
        (path, name)
        for path, names in EVERY_LINE.items()
        if path in collected
        for name in (("*",) if names == "*" else names)
        if (path, name) not in found
    ]
    if missing:
        raise pytest.UsageError(f"tests/conftest.py EVERY_LINE names tests that do not exist: {missing}")


def pytest_collection_modifyitems(config, items):
    """Longest files first, every file's tests together and in their own order (a stable sort)."""

    def rank(item) -> int:
        path = item.nodeid.split("::")[0].removeprefix("tests/")
        return LONGEST_FIRST.index(path) if path in LONGEST_FIRST else len(LONGEST_FIRST)

    _on_every_line(items)
    items.sort(key=rank)
