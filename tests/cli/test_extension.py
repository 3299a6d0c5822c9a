"""The extension as Blender sees it: Blender's own validator, a built zip, install, enable, disable."""

import os
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

from conftest import ROOT


def _blender_ext() -> str:
    out = subprocess.run(
        [sys.executable, "-c", "import bpy; print(bpy.utils.system_resource('SCRIPTS'))"],
        capture_output=True,
        text=True,
        check=True,
    )
    scripts = out.stdout.strip().splitlines()[-1]
    return os.path.join(scripts, "addons_core", "bl_pkg", "cli", "blender_ext.py")


def test_manifest_passes_blenders_validator():
    r = subprocess.run([sys.executable, _blender_ext(), "validate", str(ROOT)], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


def test_built_zip_installs_enables_and_unregisters_cleanly(tmp_path):
    build = tmp_path / "build"
    build.mkdir()
    r = subprocess.run(
        [sys.executable, _blender_ext(), "build", "--source-dir", str(ROOT), "--output-dir", str(build)],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    (zip_path,) = build.glob("*.zip")
    assert zip_path.stat().st_size < 2_000_000, "the zip holds more than the extension (a virtual environment?)"
    names = zipfile.ZipFile(zip_path).namelist()
    assert "blender_manifest.toml" in names and "__init__.py" in names
    assert any(n.startswith("shaders/") for n in names) and any(n.startswith("presets/") for n in names)
    assert not any(n.startswith(("tests/", ".ci/", ".venv", ".git/")) for n in names), names
    assert sum(zipfile.ZipFile(zip_path).getinfo(n).file_size for n in names) < 2_000_000

    script = textwrap.dedent(f"""
        import sys, bpy, addon_utils
        bpy.ops.extensions.package_install_files(filepath={str(zip_path)!r}, repo="user_default",
                                                 enable_on_install=True)
        mod = "bl_ext.user_default.nubis"
        assert mod in {{a.module for a in bpy.context.preferences.addons}}, "not enabled"
        assert hasattr(bpy.types.Scene, "nubis"), "settings not registered"
        pkg = sys.modules[mod + ".nubis_addon.blender"]
        assert sys.modules[mod + ".nubis_addon.blender.headless.blender_command"].is_registered()
        assert sys.modules[mod + ".nubis_addon.blender.live.viewport"].is_registered()
        bpy.ops.nubis.new_cloudscape(preset="default")
        assert bpy.context.scene.nubis.field_a is not None
        cache = sys.modules[mod + ".nubis_addon.blender.host.runtime"].cache_dir()
        assert str(cache).startswith(bpy.utils.extension_path_user(mod)), cache
        assert {str(ROOT)!r} not in str(cache)
        prefs = bpy.context.preferences.addons[mod].preferences
        assert prefs is not None and type(prefs).bl_idname == mod, "no add-on preferences"
        user_presets = sys.modules[mod + ".nubis_addon.blender.host.runtime"].user_preset_dir()
        assert str(user_presets).startswith(bpy.utils.extension_path_user(mod)), user_presets
        assert bpy.ops.nubis.clear_cache() == {{"FINISHED"}}
        assert bpy.ops.nubis.preset_add(name="Installed") == {{"FINISHED"}}
        assert (user_presets / "installed.toml").is_file()
        bpy.ops.preferences.addon_disable(module=mod)
        assert not hasattr(bpy.types.Scene, "nubis"), "settings left behind"
        assert not [c for c in dir(bpy.types) if c.startswith("NUBIS_")], "classes left behind"
        assert not sys.modules[mod + ".nubis_addon.blender.headless.blender_command"].is_registered()
        assert not sys.modules[mod + ".nubis_addon.blender.live.viewport"].is_registered()
        print("EXTENSION-OK")
    """)
    env = dict(os.environ, HOME=str(tmp_path / "home"))
    env.pop("NUBIS_CACHE_DIR", None)
    env.pop("BLENDER_USER_RESOURCES", None)
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=600)
    assert "EXTENSION-OK" in r.stdout, r.stdout[-3000:] + r.stderr[-3000:]


def test_ci_runs_readme_command_2_on_every_blender_line():
    """CI (`.ci/run`) runs exactly the README's test command: the suite on 5.3, the `lines` tests on 5.2 LTS
    and 4.5 LTS, each line with its own pinned requirements and virtual environment, tests/core on 4.5's
    Python too, then the real-application stage's quick set. 5.2 runs no tests/core because its Python and
    numpy are 5.3's: this test keeps that true."""
    import re

    root = Path(__file__).resolve().parents[2]
    readme = (root / "README.md").read_text()
    blocks = re.findall(r"```\n(.*?)```", readme, re.S)
    command_2 = [ln for ln in blocks[1].splitlines() if ln.strip()]
    assert command_2 == [
        "./.ci/setup 5.3 && .venv-5.3/bin/python -m pytest -q && ./.ci/setup 5.2 && .venv-5.2/bin/python -m pytest -q"
        ' -m lines && ./.ci/setup 4.5 && .venv-4.5/bin/python -m pytest -q -m "lines or core" && tests/app/run --quick'
    ]
    run = (root / ".ci" / "run").read_text()
    assert command_2[0] in run.splitlines()
    assert blocks[0].strip().splitlines() == [
        "./.ci/setup 5.3 && .venv-5.3/bin/python -m nubis_addon compare --out out/default --draft"
    ]
    pins = {
        line: (root / ".ci" / f"requirements-{line}.txt").read_text().splitlines() for line in ("5.3", "5.2", "4.5")
    }
    assert "bpy==5.3.0" in pins["5.3"] and "bpy==5.2.3" in pins["5.2"] and "bpy==4.5.15" in pins["4.5"]
    assert [p for p in pins["5.2"] if not p.startswith(("#", "bpy=="))] == [
        p for p in pins["5.3"] if not p.startswith(("#", "bpy=="))
    ], "5.2 runs without tests/core only while its requirements besides bpy are 5.3's"
    setup = (root / ".ci" / "setup").read_text()
    assert "5.3 | 5.2) pyver=3.13" in setup, "... and its Python is 5.3's"
    manifest = (root / "blender_manifest.toml").read_text()
    assert 'blender_version_min = "4.5.0"' in manifest
