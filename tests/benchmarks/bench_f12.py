"""What the clouds add to an F12 frame: the default cloudscape with a ground plane and a cube, rendered
with `bpy.ops.render.render()` in EEVEE and Cycles with the clouds off and on, and the clouds' own
parts (the camera's view, the panorama, the shadow map: blender/f12/scene_render.py) timed inside; the
camera's view is split into its depth composition's parts (the depth pre-pass, the split march, the
veil and its images: blender/f12/composition.py).

Run from the repository root:
    .venv-5.3/bin/python tests/benchmarks/bench_f12.py [WIDTH HEIGHT [CYCLES_SAMPLES]]
(default 1920 1080 16). Prints one table; both renders of an engine run in the same process, the one
without clouds first. Times on a software rasterizer (llvmpipe) and a 2-core CPU are for comparing,
not a promise for a workstation.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def main() -> None:
    import bpy

    import nubis_addon
    from nubis_addon.blender import ensure_registered
    from nubis_addon.blender.f12 import scene_render
    from nubis_addon.blender.scene import scenepresets
    from nubis_addon.core.presets import load_preset
    from nubis_addon.render.gpu_context import ensure_gpu_context, renderer_name

    width, height = (int(sys.argv[1]), int(sys.argv[2])) if len(sys.argv) > 2 else (1920, 1080)
    samples = int(sys.argv[3]) if len(sys.argv) > 3 else 16
    nubis_addon.register()
    ensure_gpu_context()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    ensure_registered()
    scene = bpy.context.scene
    scenepresets.apply_preset(scene, load_preset("default"))
    bpy.ops.mesh.primitive_plane_add(size=20000.0)
    bpy.ops.mesh.primitive_cube_add(size=300.0, location=(0.0, -1500.0, 150.0))
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = width, height, 100
    scene.cycles.device, scene.cycles.samples, scene.cycles.use_denoising = "CPU", samples, False
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for engine in ("BLENDER_EEVEE_NEXT" if bpy.app.version < (5, 0, 0) else "BLENDER_EEVEE", "CYCLES"):
            scene.render.engine = engine
            times = {}
            for clouds in (False, True):
                scene.nubis.sky_render_clouds = clouds
                scene.render.filepath = str(Path(tmp) / f"{engine}_{clouds}.png")
                t = time.perf_counter()
                bpy.ops.render.render(write_still=True)
                times[clouds] = time.perf_counter() - t
            parts = ", ".join(f"{k} {v:.1f} s" for k, v in scene_render.last_seconds.items())
            rows.append((engine.replace("BLENDER_", "").replace("_NEXT", ""), times[False], times[True], parts))
    print(f"F12 of the default cloudscape at {width}x{height} (Cycles {samples} samples, CPU), {renderer_name()}")
    print(f"{'engine':8} {'no clouds':>10} {'clouds':>10} {'added':>10}  the clouds' parts")
    for name, off, on, parts in rows:
        print(f"{name:8} {off:9.1f}s {on:9.1f}s {on - off:9.1f}s  {parts}")


if __name__ == "__main__":
    main()
