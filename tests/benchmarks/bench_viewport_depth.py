"""What the clouds in front of the scene cost the viewport (docs/viewport.md#clouds-in-front-of-the-scene).

The peak scene (a 5 km cone through the default cloudscape, 16 km ahead of a camera 1 km up: its flanks
behind clouds) from its camera, drawn in one run without the scene's depth (the clouds behind the objects
only, the path before the change at rest) and with it (each pixel the clouds in front of what it shows):
  - at rest: the redraw of a converged view (the upscale alone), median of 200 redraws in rounds that
    alternate the two ways;
  - moving: the redraw while the view pans 0.2 degrees per redraw (march, resolve, upscale), median of
    48 redraws a way, alternating;
  - the depth's read-back, as the 3D view pays it once per change of the view (a float texture from the
    framebuffer's depth): its median over 20 reads.

Run from the repository root:
    .venv-5.3/bin/python tests/benchmarks/bench_viewport_depth.py [WIDTH HEIGHT]
(default 640 360). Times on a software rasterizer (llvmpipe) and a 2-core CPU are for comparing.
"""

from __future__ import annotations

import math
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))


def _timed(tv, clouds, state, view, depth) -> float:
    t = time.perf_counter()
    tv.redraw(clouds, state, view, 1.0, 8, depth=depth, depth_key=1 if depth is not None else None)
    tv.upscale(clouds)
    tv.sync()
    return (time.perf_counter() - t) * 1000.0


def main() -> None:
    import bpy  # noqa: F401 - Blender's modules (gpu) come with it
    import gpu
    import numpy as np
    from peak import peak_scene

    import nubis_addon
    from nubis_addon.blender.host import runtime
    from nubis_addon.blender.jobs import preview
    from nubis_addon.blender.live import viewport
    from nubis_addon.blender.scene import cloudstate
    from nubis_addon.render import offscreens, temporal
    from nubis_addon.render.gpu_context import ensure_gpu_context, renderer_name

    width, height = (int(a) for a in (sys.argv[1:3] if len(sys.argv) > 2 else (640, 360)))
    nubis_addon.register()
    ensure_gpu_context()
    scene = peak_scene()
    clouds = runtime.cloud_gpu(scene.nubis.noise_seed)
    state = cloudstate.state_from_scene(scene)
    view = preview.camera_view(scene, width, height)
    ways = ("behind the objects", "in front of the scene")
    rest: dict[str, list[float]] = {w: [] for w in ways}
    moving: dict[str, list[float]] = {w: [] for w in ways}
    with preview.scene_depth(scene, view) as (deep, depth):
        views = {
            ways[0]: (temporal.TemporalViewport(), view, None),
            ways[1]: (temporal.TemporalViewport(), deep, depth),
        }
        off = offscreens.new_offscreen(width, height)
        with off.bind():
            for tv, v, d in views.values():  # converge both
                while not tv.converged:
                    tv.redraw(clouds, state, v, 1.0, 8, depth=d, depth_key=1 if d is not None else None)
            for _ in range(10):
                for way, (tv, v, d) in views.items():
                    rest[way] += [_timed(tv, clouds, state, v, d) for _ in range(20)]
            for step in range(48):
                for way, (tv, v, d) in views.items():
                    turn = _turn(0.2 * (step + 1), v.eye)
                    mapping = (v.depth_map, v.axis)
                    turned = temporal.View.of(turn @ np.array(v.inv_view_proj), v.eye, v.width, v.height, mapping)
                    moving[way].append(_timed(tv, clouds, state, turned, d))
            fb = gpu.state.active_framebuffer_get()
            reads = []
            for i in range(20):
                t = time.perf_counter()
                viewport._scene_depth(fb, width, height, ("bench", i), "bench")
                reads.append((time.perf_counter() - t) * 1000.0)
        off.free()
        for tv, _v, _d in views.values():
            tv.free()
    print(f"GPU: {renderer_name()}; the peak scene at {width}x{height}")
    print(f"{'redraw':<12}{ways[0]:>22}{ways[1]:>24}{'ratio':>8}")
    for name, times in (("at rest", rest), ("moving", moving)):
        a, b = (statistics.median(times[w]) for w in ways)
        print(f"{name:<12}{a:>19.2f} ms{b:>21.2f} ms{b / a:>7.2f}x")
    print(f"the depth's read-back once per change of the view: {statistics.median(reads):.2f} ms")


def _turn(degrees: float, eye):
    """A turn of the view about the vertical through the eye, applied to the ray matrix's world side."""
    import numpy as np

    a = math.radians(degrees)
    rotate, to_eye, back = np.eye(4), np.eye(4), np.eye(4)
    rotate[0, 0], rotate[0, 1], rotate[1, 0], rotate[1, 1] = math.cos(a), -math.sin(a), math.sin(a), math.cos(a)
    to_eye[:3, 3], back[:3, 3] = eye[:3], [-e for e in eye[:3]]
    return to_eye @ rotate @ back


if __name__ == "__main__":
    main()
