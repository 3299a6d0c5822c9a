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
    from nubis_addon.blender import ensure_registered, scene_io
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
        scene_io.apply_preset(scene, preset)
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


def pytest_collection_modifyitems(config, items):
    """Longest files first, every file's tests together and in their own order (a stable sort)."""

    def rank(item) -> int:
        path = item.nodeid.split("::")[0].removeprefix("tests/")
        return LONGEST_FIRST.index(path) if path in LONGEST_FIRST else len(LONGEST_FIRST)

    items.sort(key=rank)
