"""What each cloud layer of a layered sky costs the viewport (docs/layers.md#step-length).

The altocumulus-over-stratocumulus preset from its camera between the layers, drawn four ways in one run:
no layer, the deck alone, the altocumulus alone, both. For each: the temporal redraw (the viewport's
per-frame work, finished on the GPU, median over rounds of 16 redraws from a restart, the rounds of the
four alternating so a load that comes and goes weighs on all alike), and the view march's samples per
pixel above and below the horizon (its own count, NUBIS_FETCH_STATS), then the redraw of each against the
deck alone.

Run from the repository root:
    .venv-5.3/bin/python tests/benchmarks/bench_layers.py [WIDTH HEIGHT ROUNDS]
(default 320 180 3). Times on a software rasterizer (llvmpipe) and a 2-core CPU are for comparing.
"""

from __future__ import annotations

import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

PRESET = "altocumulus_over_stratocumulus"
DRAWN = ("no layer", "the deck alone", "the altocumulus alone", "both")


def _draw(scene, which: str) -> None:
    s = scene.nubis
    s.first_layer_enabled = which in ("the deck alone", "both")
    s.cloud_layers[0].enabled = which in ("the altocumulus alone", "both")


def main() -> None:
    import bpy
    import mathutils
    import numpy as np
    from redraws import alternating_redraws

    from nubis_addon.blender.headless.commands import load_scene
    from nubis_addon.blender.host import runtime
    from nubis_addon.blender.jobs import preview
    from nubis_addon.blender.scene import cloudstate
    from nubis_addon.core import camera
    from nubis_addon.render import engine
    from nubis_addon.render.gpu_context import ensure_gpu_context, renderer_name

    width, height, rounds = (int(a) for a in (sys.argv[1:4] if len(sys.argv) > 3 else (320, 180, 3)))
    ensure_gpu_context()
    scene = load_scene(type("Args", (), {"blend": None, "preset": PRESET})(), in_blender=False)
    s = scene.nubis
    view = preview.camera_view(scene, width, height)
    inv = mathutils.Matrix(view.inv_view_proj)
    clouds = runtime.cloud_gpu(s.noise_seed)
    rows = {}
    states = {}
    for which in DRAWN:
        _draw(scene, which)
        state = cloudstate.state_from_scene(scene)
        state.pixel_angle, state.pixel_size = camera.pixel_footprint(np.array(view.inv_view_proj), width, height)
        states[which] = state
        clouds.update(state)
        samples = engine.render_offscreen(clouds, inv, view.eye, width, height, NUBIS_FETCH_STATS=1)[..., 1]
        rows[which] = {"above": float(samples[: height // 2].mean()), "below": float(samples[height // 2 :].mean())}
    times = alternating_redraws(clouds, {which: states[which] for which in DRAWN}, view, s.viewport_resolution, rounds)
    deck = statistics.median(times["the deck alone"])
    print(f"{PRESET} at {width}x{height}, {rounds} rounds, {renderer_name()}, Blender {bpy.app.version_string}")
    print(f"{'drawn':<24}{'redraw (median)':>17}{'/ the deck':>12}{'samples above':>15}{'samples below':>15}")
    for which in DRAWN:
        ms = statistics.median(times[which])
        r = rows[which]
        print(f"{which:<24}{ms:>14.1f} ms{ms / deck:>11.2f}x{r['above']:>15.1f}{r['below']:>15.1f}")


if __name__ == "__main__":
    main()
