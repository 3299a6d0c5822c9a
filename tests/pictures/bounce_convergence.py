"""How Cycles' reference converges with its volume bounces, per preset (docs/convergence.md).

Run from the repository root:
    .venv-5.3/bin/python tests/pictures/bounce_convergence.py OUT.json [--presets a,b] [--width W --height H]
        [--samples S] [--voxel-size M] [--bounces 8,16,32,...]

Each preset is baked once over the camera's view (`--voxel-size`, default 60 m), then Cycles renders that
bake at each bounce count twice with different seeds. The mean luminance of the two is the estimate; half
their difference (relative, over the cloud pixels) is Cycles' own noise. The bounce counts go up in
doublings until one doubling changes the mean luminance by less than that noise: the converged count.
Prints a markdown table and writes every number to OUT.json (rewritten after each preset).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from nubis_addon.core.jobs import BakeOptions

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def luminance(rgba: np.ndarray) -> np.ndarray:
    return 0.2126 * rgba[..., 0] + 0.7152 * rgba[..., 1] + 0.0722 * rgba[..., 2]


def measure(name: str, args) -> dict:
    import bpy

    from nubis_addon.blender import ensure_registered
    from nubis_addon.blender.jobs import comparison, pipeline
    from nubis_addon.blender.scene import scenepresets
    from nubis_addon.core.presets import load_preset

    bpy.ops.wm.read_factory_settings(use_empty=True)
    ensure_registered()
    scene = bpy.context.scene
    scenepresets.apply_preset(scene, load_preset(name))
    out = {"preset": name, "width": args.width, "height": args.height, "samples": args.samples, "rows": []}
    with tempfile.TemporaryDirectory(prefix="nubis-bounces-") as tmp:
        vdb = str(Path(tmp) / "clouds.vdb")
        t = time.perf_counter()
        baked = pipeline.bake(
            scene,
            vdb,
            BakeOptions(
                voxel_size=args.voxel_size,
                camera_only=True,
                size=(args.width, args.height),
                thin_cirrus=comparison.THIN_CIRRUS,
            ),
        )
        out["voxel_size"] = baked.plan.voxel_size
        out["bake_s"] = round(time.perf_counter() - t, 1)
        mask = None
        previous = previous_bounces = None
        for bounces in args.bounces:
            t = time.perf_counter()
            runs = []
            for seed in (0, 1):
                scene.cycles.seed = seed
                runs.append(
                    pipeline.render_cycles(
                        scene, args.width, args.height, args.samples // 2, vdb, bounces=bounces, exact_samples=True
                    )
                )
            seconds = time.perf_counter() - t
            if mask is None:  # the cloud pixels, from the first (least scattered) render
                mask = (runs[0][..., 3] + runs[1][..., 3]) / 2 > 0.05
            lum = [float(luminance(r)[mask].mean()) for r in runs]
            mean = (lum[0] + lum[1]) / 2
            noise = abs(lum[0] - lum[1]) / 2 / max(mean, 1e-9)
            change = None if previous is None else (mean - previous) / max(previous, 1e-9)
            row = {"bounces": bounces, "mean_luminance": mean, "noise": noise, "change": change, "seconds": seconds}
            out["rows"].append(row)
            print(json.dumps({name: row}), flush=True)
            if change is not None and abs(change) < max(noise, args.min_noise):
                out["converged_bounces"] = previous_bounces
                break
            previous, previous_bounces = mean, bounces
        else:
            out["converged_bounces"] = None  # not within the bounce counts tried
        out["cloud_pixels"] = int(mask.sum())
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--presets", default="")
    ap.add_argument("--width", type=int, default=96)
    ap.add_argument("--height", type=int, default=54)
    ap.add_argument("--samples", type=int, default=64, help="per bounce count, split over two seeds")
    ap.add_argument("--voxel-size", type=float, default=60.0)
    ap.add_argument("--bounces", default="8,16,32,64,128,256,512,1024")
    ap.add_argument("--min-noise", type=float, default=0.005, help="a doubling below this relative change converged")
    args = ap.parse_args()
    args.bounces = [int(b) for b in args.bounces.split(",")]

    import nubis_addon
    from nubis_addon.core.presets import list_presets
    from nubis_addon.render.gpu_context import ensure_gpu_context

    nubis_addon.register()
    ensure_gpu_context()
    names = [n for n in args.presets.split(",") if n] or list_presets()
    results = {}
    for name in names:
        results[name] = measure(name, args)
        Path(args.out).write_text(json.dumps(results, indent=1) + "\n")
    print("| preset | " + " | ".join(f"{b}" for b in args.bounces) + " | converged at | noise |")
    print("|---|" + "---|" * (len(args.bounces) + 2))
    for name, r in results.items():
        lums = {row["bounces"]: row["mean_luminance"] for row in r["rows"]}
        cells = [f"{lums[b]:.4f}" if b in lums else "" for b in args.bounces]
        noise = max(row["noise"] for row in r["rows"])
        print(f"| {name} | " + " | ".join(cells) + f" | {r['converged_bounces']} | {noise * 100:.1f} % |")


if __name__ == "__main__":
    main()
