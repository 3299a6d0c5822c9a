"""Stroke-to-redraw latency of live painting (blender/sidebar/paint.py), for 512x512 and 2048x2048 fields.

For each brush sample along a drag over the default cloudscape: the dabs are rasterized, the stroke's
rectangle of the field re-composited and written into the GPU texture in place, and the 3D view (480x270,
the scene camera's view, standard quality) redrawn once, finished on the GPU (a pixel read back). In the
same run, the path without the dirty rectangle: the whole field composited, its images written and read
back, uploaded whole and the view redrawn (with its shadows). The live path holds the shadows (the light
volumes) while the drag goes on, as the 3D view does; a second live run refills them at every sample.

Run from the repository root:
    .venv-5.3/bin/python tests/benchmarks/bench_paint.py [SAMPLES]
(default 12 samples per field size). Prints one table of medians. Times on a software rasterizer
(llvmpipe) and a 2-core CPU are for comparing, not a promise for a workstation.
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path
from types import SimpleNamespace

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

W, H = 480, 270
RADIUS = 2500.0


def main() -> None:
    import bpy
    import gpu
    import numpy as np
    from gpu_helpers import camera_view

    import nubis_addon
    from nubis_addon.blender import ensure_registered
    from nubis_addon.blender.host import runtime
    from nubis_addon.blender.live import paintstroke, viewport
    from nubis_addon.blender.scene import datafield, sceneparams, scenepresets
    from nubis_addon.core import paint
    from nubis_addon.core.presets import load_preset
    from nubis_addon.render.gpu_context import ensure_gpu_context, renderer_name
    from nubis_addon.render.offscreens import read_pixels

    samples = int(sys.argv[1]) if len(sys.argv) > 1 else 12
    nubis_addon.register()
    ensure_gpu_context()
    rows = []
    for resolution in (512, 2048):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        ensure_registered()
        scene = bpy.context.scene
        preset = load_preset("default")
        preset.params["field_resolution"] = resolution
        scenepresets.apply_preset(scene, preset)
        s = scene.nubis
        s.viewport_samples = 1
        rv3d = camera_view(bpy, scene, W, H)
        region = SimpleNamespace(width=W, height=H, as_pointer=lambda: 99)
        offscreen = gpu.types.GPUOffScreen(W, H, format="RGBA16F")
        cam_xy = sceneparams.evaluated_matrix(scene.camera).translation
        xs = np.linspace(cam_xy.x - 6000.0, cam_xy.x + 6000.0, samples)
        y = float(cam_xy.y) + 9000.0

        def redraw(fb, scene=scene, region=region, rv3d=rv3d):
            fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
            viewport.draw_region(scene, region, rv3d)
            read_pixels(fb, 1, 1)  # wait for the GPU

        with offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            layer = paintstroke.paint_layer(s, "COVERAGE")
            datafield.generate_fields(scene)
            redraw(fb)
            redraw(fb)
            clouds = runtime.cloud_gpu(s.noise_seed)
            # Live: the dirty rectangle, in place; the shadows held while dragging, then refilled each sample.
            timing = {}
            for held, dy in ((True, 0.0), (False, -3000.0)):
                live = paintstroke.LiveStroke(scene, layer, RADIUS, 1.0, "SMOOTH", "ADD")
                live.hold_light = held
                redraw(fb)
                total, cpu, fills = [], [], clouds.volume_fills
                for i, x in enumerate(xs):
                    t0 = time.perf_counter()
                    live.add(float(x), y + dy, 1.0, i == 0)
                    t1 = time.perf_counter()
                    redraw(fb)
                    total.append(time.perf_counter() - t0)
                    cpu.append(t1 - t0)
                timing[held] = (statistics.median(total), statistics.median(cpu), clouds.volume_fills - fills)
                live.commit(layer)
                datafield.generate_fields(scene)
                clouds.hold_light(0.0)
            # Whole: each sample composites the field and uploads it whole.
            whole_t = []
            for i, x in enumerate(xs):
                t0 = time.perf_counter()
                paintstroke.append_dabs(layer, paint.stroke_dabs([(float(x), y + 3000.0, 1.0, i == 0)], RADIUS, 1.0))
                datafield.generate_fields(scene)
                viewport.invalidate()
                redraw(fb)
                whole_t.append(time.perf_counter() - t0)
        offscreen.free()
        rows.append((f"{resolution}x{resolution}", timing[True], timing[False], statistics.median(whole_t)))
    print(f"Live painting, stroke sample to redrawn view ({W}x{H}, standard), median of {samples}; {renderer_name()}")
    print("live: the stroke's rectangle composited and written into the texture in place; its CPU part; light")
    print("fills: how many samples refilled the shadows' volumes; whole: the field composited and uploaded whole")
    print(
        f"{'field':10} {'live ms':>8} {'CPU ms':>7} {'fills':>6} | {'+shadows ms':>11} {'fills':>6} | {'whole ms':>9}"
    )
    for name, (held_ms, cpu_s, held_fills), (lit_ms, _c, lit_fills), whole in rows:
        print(
            f"{name:10} {held_ms * 1000:8.1f} {cpu_s * 1000:7.1f} {held_fills:6d} | {lit_ms * 1000:11.1f} "
            f"{lit_fills:6d} | {whole * 1000:9.1f}   whole / live {whole / held_ms:.1f}x"
        )


if __name__ == "__main__":
    main()
