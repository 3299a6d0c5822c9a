"""Memory over a long Render Animation with an object in the clouds: the process's resident memory after each
frame, and Blender's data-block counts, so a leak per frame shows as a slope.

    .venv-5.3/bin/python tests/benchmarks/bench_anim_memory.py [--frames 250] [--engine CYCLES|EEVEE]
        [--size 160x90] [--out DIR]

The default cloudscape with a 5 km peak 16 km ahead of a camera 1 km up (the veil in use on every frame,
the shadow casters' stack through the layer), the wind moving the clouds from frame to frame, rendered by
`bpy.ops.render.render(animation=True)` as a pipeline's script does. Prints a table: resident memory at
frames 1, 10, 50, 100, ... and the last, the growth after frame 10 in MB and per frame, the data-blocks
(images, materials, objects, meshes, worlds) at frame 10 and at the end. The goal: less than 50 MB
of growth after frame 10 over 250 frames at 160 x 90.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # peak.py


def rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=250)
    ap.add_argument("--engine", choices=("CYCLES", "EEVEE"), default="CYCLES")
    ap.add_argument("--size", default="160x90")
    ap.add_argument("--out", default="")
    args = ap.parse_args()
    import bpy
    from peak import peak_scene

    scene = peak_scene()
    w, h = (int(v) for v in args.size.split("x"))
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = w, h, 100
    engines = {e.identifier for e in bpy.types.RenderSettings.bl_rna.properties["engine"].enum_items}
    eevee = "BLENDER_EEVEE_NEXT" if "BLENDER_EEVEE_NEXT" in engines else "BLENDER_EEVEE"
    r.engine = "CYCLES" if args.engine == "CYCLES" else eevee
    scene.cycles.device, scene.cycles.samples, scene.cycles.use_denoising = "CPU", 1, False
    scene.eevee.taa_render_samples = 1
    scene.nubis.sky_environment_width = 128
    scene.nubis.sky_shadow_resolution = 128
    out = args.out or tempfile.mkdtemp(prefix="nubis-anim-memory-")
    r.filepath = os.path.join(out, "f_####")
    scene.frame_start, scene.frame_end = 1, args.frames
    samples: dict[int, tuple[float, dict[str, int]]] = {}
    from nubis_addon.blender.f12 import composition

    veiled = []

    def on_post(sc, *_a) -> None:
        if sc.name != scene.name:
            return
        counts = {k: len(getattr(bpy.data, k)) for k in ("images", "materials", "objects", "meshes", "worlds")}
        samples[sc.frame_current] = (rss_mb(), counts)
        veiled.append(composition.last_frame.get("veil", 0.0))

    bpy.app.handlers.render_post.append(on_post)
    t = time.perf_counter()
    bpy.ops.render.render(animation=True)
    seconds = time.perf_counter() - t
    frames = sorted(samples)
    print(f"# Render Animation, {args.engine}, {w}x{h}, {len(frames)} frames in {seconds:.0f} s; the veil in use on")
    print(f"# {int(sum(veiled))} of {len(veiled)} frames; Blender {bpy.app.version_string}")
    print("| frame | resident MB | images | materials | objects | meshes | worlds |")
    print("|---|---|---|---|---|---|---|")
    marks = [f for f in frames if f in (1, 10) or f % 50 == 0 or f == frames[-1]]
    for f in marks:
        mb, c = samples[f]
        print(f"| {f} | {mb:.0f} | {c['images']} | {c['materials']} | {c['objects']} | {c['meshes']} | {c['worlds']} |")
    if 10 in samples and frames[-1] > 10:
        growth = samples[frames[-1]][0] - samples[10][0]
        per = growth / (frames[-1] - 10)
        print(
            f"\ngrowth after frame 10: {growth:+.1f} MB ({per * 1024:+.0f} kB a frame; "
            "goal under 50 MB over 250 frames)"
        )
    return 0


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    os._exit(code)
