"""Full-mode comparison of every preset with Cycles, for the README's parity table.

Run from the repository root:  .venv-5.3/bin/python tests/pictures/compare_presets.py OUT_DIR [W H SAMPLES]
Writes OUT_DIR/<preset>/ (compare's outputs) and prints a markdown table of the metrics.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from nubis_addon.core.jobs import CompareOptions

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def compare_preset(name: str, out_dir: Path, width: int, height: int, samples: int):
    """A fresh scene with the preset, compared in full mode with Cycles' noise measured: (scene, metrics)."""
    import bpy

    from nubis_addon.blender import ensure_registered
    from nubis_addon.blender.jobs import comparison
    from nubis_addon.blender.scene import scenepresets
    from nubis_addon.core.presets import load_preset

    bpy.ops.wm.read_factory_settings(use_empty=True)
    ensure_registered()
    scene = bpy.context.scene
    scenepresets.apply_preset(scene, load_preset(name))
    start = time.perf_counter()
    m = comparison.compare(
        scene,
        out_dir / name,
        CompareOptions(width=width, height=height, samples=samples, mode="full", voxel_size=None, noise_estimate=True),
    )
    m["total_s"] = time.perf_counter() - start
    return scene, m


def main(out_dir: str, width: int = 320, height: int = 180, samples: int = 128) -> None:
    import nubis_addon
    from nubis_addon.core.presets import list_presets
    from nubis_addon.render.gpu_context import ensure_gpu_context

    nubis_addon.register()
    ensure_gpu_context()
    rows = []
    for name in list_presets():
        _scene, m = compare_preset(name, Path(out_dir), width, height, samples)
        rows.append((name, m))
        print(json.dumps({name: {k: m[k] for k in ("alpha_rmse", "luminance_rel_error", "luminance_bias")}}))
    print(
        "| preset | alpha RMSE | luminance error | luminance bias | IoU | Cycles noise (lum.) "
        "| cone vs reference (lum.) | voxel | time |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name, m in rows:
        cone = m["cone_march_vs_reference"]["luminance_rel_error"]
        print(
            f"| {name} | {m['alpha_rmse']:.3f} | {m['luminance_rel_error'] * 100:.1f} % | "
            f"{m['luminance_bias'] * 100:+.1f} % | {m['silhouette_iou']:.2f} | "
            f"{m['cycles_noise']['luminance_rel_error'] * 100:.1f} % | {cone * 100:.1f} % | "
            f"{m['voxel_size']:g} m | {m['total_s']:.0f} s |"
        )


if __name__ == "__main__":
    args = sys.argv[1:]
    main(args[0] if args else "compare_presets", *(int(a) for a in args[1:4]))
