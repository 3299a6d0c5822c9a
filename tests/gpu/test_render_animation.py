"""Render Animation with an object in the clouds (blender/f12/scene_render.py begin/finish, blender/f12/composition.py
ready/stow/put_away; docs/sky.md#render-animation), each engine in a child process of its own
(tests/gpu/render_animation_child.py), as a pipeline's bpy script renders:

- every frame renders and is written, the veil coming in at frame 2 and the casters' stack growing with
  it, a marked VDB cloud beside them (Render Animation segfaulted after frame 1 whenever the veil was in
  use or a VDB cloud was marked: their render visibility changed between frames under the animation's
  one dependency graph);
- the World, the veil and the casters are put back after the last frame and after a frame that could not
  be written (render_cancel, with no render_post);
- a still F12 at a percentage that does not divide evenly gives the clouds the frame's own size;
- the script ends with exit status 0 (the depth pre-pass's shader, kept in a module, was freed after
  Blender's GPU context and crashed the interpreter's exit)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

CHILD = Path(__file__).with_name("render_animation_child.py")


def _run(engine: str, out: Path, renders: str) -> dict[str, dict]:
    proc = subprocess.run(
        [sys.executable, str(CHILD), engine, str(out), renders],
        capture_output=True,
        text=True,
        timeout=900,
        env=dict(os.environ),
    )
    results = {}
    for line in proc.stdout.splitlines():
        if line.startswith("RESULT "):
            rec = json.loads(line[len("RESULT ") :])
            results[rec.pop("render")] = rec
    tail = "\n".join((proc.stdout + proc.stderr).splitlines()[-25:])
    assert proc.returncode == 0, f"the script ended with {proc.returncode} (139 is a segfault):\n{tail}"
    assert set(results) == set(renders.split(",")) - {"vdb"}, f"renders reported: {sorted(results)}\n{tail}"
    return results


def _put_back(rec: dict, what: str) -> None:
    assert rec["world_back"] and rec["veil_out"] and rec["casters_out"] and not rec["swapped"], (what, rec)
    assert rec["volumes_back"], (what, rec)  # the marked VDB cloud renders again as the artist left it


def _check_animation(rec: dict) -> None:
    assert rec["files"] == ["f_0001.png", "f_0002.png", "f_0003.png"], rec
    frames = {f["frame"]: f for f in rec["frames"]}
    assert sorted(frames) == [1, 2, 3], rec["frames"]
    # Frame 1: the wall under the ground, no veil; frames 2 and 3: the wall in the clouds, veiled.
    assert frames[1]["veil"] == 0.0 and not frames[1]["veil_shown"], frames[1]
    for f in (2, 3):
        assert frames[f]["veil"] == 1.0 and frames[f]["veil_shown"], frames[f]
    assert frames[2]["casters"] > frames[1]["casters"] >= 1, rec["frames"]  # the stack climbs into the layer
    _put_back(rec, "after the animation")


def test_cycles_renders_every_frame_puts_everything_back_and_the_script_exits_cleanly(blender, tmp_path):
    results = _run("CYCLES", tmp_path, "still,anim,failing,vdb")
    still = results["still"]
    # 101 x 57 at 33 %: Blender truncates to 33 x 18; the clouds had 33 x 19 (rounded).
    assert still["image"] == [18, 33] and still["clouds"] == [33, 18], still
    _put_back(still, "after the still")
    _check_animation(results["anim"])
    failing = results["failing"]
    assert "f_0002.png" in failing["refused"], failing
    assert [f["frame"] for f in failing["frames"]] == [1, 2], failing  # frame 2 rendered, not written
    assert failing["frames"][1]["veil_shown"], failing  # ... with the veil in use when it failed
    _put_back(failing, "after the frame that could not be written")


def test_eevee_renders_every_frame_of_an_animation_with_the_veil(blender, tmp_path):
    _check_animation(_run(EEVEE_ENGINE(blender), tmp_path, "anim")["anim"])


def EEVEE_ENGINE(blender) -> str:  # noqa: N802 - reads as the constant it is
    engines = {e.identifier for e in blender.types.RenderSettings.bl_rna.properties["engine"].enum_items}
    return next(e for e in ("BLENDER_EEVEE_NEXT", "BLENDER_EEVEE") if e in engines)


@pytest.fixture(autouse=True)
def _noise_cache(cache_dir):
    """The child reads the noise from the suite's cache (NUBIS_CACHE_DIR), not made again."""
    yield
