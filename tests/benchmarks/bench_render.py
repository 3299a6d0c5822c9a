"""Benchmark of the GPU path: noise generation, GPU texture memory, frame times, bake time.

Run from the repository root:  .venv-5.3/bin/python tests/benchmarks/bench_render.py
Prints one table; ratios are measured in the same run. Times on a software rasterizer (llvmpipe)
are for comparing changes, not a promise for a real GPU.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from nubis_addon.core.jobs import BakeOptions

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def best_of(fn, repeat: int = 3) -> float:
    best = float("inf")
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def main() -> None:
    import bpy

    import nubis_addon
    from nubis_addon.blender import ensure_registered
    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.blender.scene import cloudstate, scenepresets
    from nubis_addon.core import noise
    from nubis_addon.core.presets import load_preset
    from nubis_addon.render import engine
    from nubis_addon.render.gpu_context import ensure_gpu_context, renderer_name
    from nubis_addon.render.textures import NoiseTextures

    nubis_addon.register()
    ensure_gpu_context()
    rows = []
    t = time.perf_counter()
    ns = noise.generate_noise_set(0)
    rows.append(("noise volumes generated (LF 128^3, HF 32^3, curl, cirrus)", f"{time.perf_counter() - t:.2f} s"))
    textures = NoiseTextures(ns)
    rows.append(
        ("GPU memory of the noise texture set (padded, RGBA8, with its mips)", f"{textures.gpu_bytes / 2**20:.2f} MiB")
    )
    rows.append(("  budget of the sources (S15, GPU Pro 7)", "20 MB"))

    bpy.ops.wm.read_factory_settings(use_empty=True)
    ensure_registered()
    scene = bpy.context.scene
    scenepresets.apply_preset(scene, load_preset("default"))
    state = cloudstate.state_from_scene(scene)
    from nubis_addon.blender.host import runtime

    clouds = runtime.cloud_gpu(0)
    eye = cloudstate.camera_eye(scene)
    clouds.update(state)
    times = {}
    for w, h in ((480, 270), (960, 540), (240, 135)):
        inv = cloudstate.camera_inv_view_proj(scene, w, h)
        times[(w, h)] = best_of(lambda w=w, h=h, inv=inv: engine.render_offscreen(clouds, inv, eye, w, h))
        rows.append((f"frame {w}x{h}, default preset, real-time light march", f"{times[(w, h)] * 1000:.0f} ms"))
    rows.append(
        ("  ratio 960x540 / 240x135 (a 1/4 x 1/4 working buffer)", f"{times[(960, 540)] / times[(240, 135)]:.1f}x")
    )
    state.light_mode = 1
    clouds.update(state)
    inv = cloudstate.camera_inv_view_proj(scene, 240, 135)
    ref = best_of(lambda: engine.render_offscreen(clouds, inv, eye, 240, 135), 1)
    rows.append(("frame 240x135, reference light march and sky visibility", f"{ref * 1000:.0f} ms"))
    rows.append(("  ratio reference / real-time at 240x135", f"{ref / times[(240, 135)]:.1f}x"))
    with tempfile.TemporaryDirectory() as tmp:
        result = pipeline.bake(scene, Path(tmp) / "b.vdb", BakeOptions(voxel_size=100.0))
        size = (Path(tmp) / "b.vdb").stat().st_size
    nx, ny, nz = result.plan.dims
    rows.append((f"bake {nx}x{ny}x{nz} voxels of 100 m to OpenVDB", f"{result.seconds:.2f} s, {size / 2**20:.1f} MiB"))

    width = max(len(r[0]) for r in rows)
    print(f"GPU: {renderer_name()}")
    print(f"{'measure':<{width}}  value")
    print(f"{'-' * width}  {'-' * 16}")
    for name, value in rows:
        print(f"{name:<{width}}  {value}")


if __name__ == "__main__":
    main()
