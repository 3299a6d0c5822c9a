"""What the sun each cloud sees costs the viewport (docs/sky.md#the-sun-each-cloud-sees).

The default cloudscape with the sun at 4 degrees, from its own camera, drawn two ways in one run: every
sample lit by the lamp's one colour (the air off: the state without `sun_air`, today's path before the
change) and by the sun through the air (the table read per lit sample). For each, the temporal redraw (the
viewport's per-frame work, finished on the GPU, median over rounds of 16 redraws from a restart, the rounds
alternating so a load that comes and goes weighs on both alike), then the ratio.

Run from the repository root:
    .venv-5.3/bin/python tests/benchmarks/bench_sun_air.py [WIDTH HEIGHT ROUNDS]
(default 320 180 3). Times on a software rasterizer (llvmpipe) and a 2-core CPU are for comparing.
"""

from __future__ import annotations

import dataclasses
import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

WAYS = ("the lamp's colour", "the sun through the air")


def main() -> None:
    import bpy
    import numpy as np
    from redraws import alternating_redraws

    import nubis_addon
    from nubis_addon.blender import ensure_registered
    from nubis_addon.blender.host import runtime
    from nubis_addon.blender.jobs import preview
    from nubis_addon.blender.scene import cloudstate, scenepresets, skyground
    from nubis_addon.core import camera
    from nubis_addon.core.presets import load_preset
    from nubis_addon.render.gpu_context import ensure_gpu_context, renderer_name

    width, height, rounds = (int(a) for a in (sys.argv[1:4] if len(sys.argv) > 3 else (320, 180, 3)))
    nubis_addon.register()
    ensure_gpu_context()
    preset = load_preset("default")
    preset.extra["sun"]["elevation"] = 4.0
    bpy.ops.wm.read_factory_settings(use_empty=True)
    ensure_registered()
    scene = bpy.context.scene
    scenepresets.apply_preset(scene, preset)
    s = scene.nubis
    view = preview.camera_view(scene, width, height)
    air = cloudstate.state_from_scene(scene)
    air.pixel_angle, air.pixel_size = camera.pixel_footprint(np.array(view.inv_view_proj), width, height)
    lamp = skyground.find_sun(scene)
    plain = dataclasses.replace(air, sun_air=None, sun_radiance=tuple(c * lamp.data.energy for c in lamp.data.color))
    states = dict(zip(WAYS, (plain, air), strict=True))
    clouds = runtime.cloud_gpu(s.noise_seed)
    times = alternating_redraws(clouds, states, view, s.viewport_resolution, rounds)
    base = statistics.median(times[WAYS[0]])
    print(
        f"default, sun 4 deg, at {width}x{height}, {rounds} rounds, {renderer_name()}, Blender {bpy.app.version_string}"
    )
    print(f"{'each cloud lit by':<28}{'redraw (median)':>17}{'/ the lamp':>12}")
    for way in WAYS:
        ms = statistics.median(times[way])
        print(f"{way:<28}{ms:>14.1f} ms{ms / base:>11.2f}x")


if __name__ == "__main__":
    main()
