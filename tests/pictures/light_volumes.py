"""The real-time light against the reference march, with and without the optical-depth volumes, on
every preset (docs/viewport.md#light-volumes). compare reports the same number as "cone vs reference"
for one preset; this runs them all without baking, in one process.

Run from the repository root:
    .venv-5.3/bin/python tests/pictures/light_volumes.py [W H PASSES] [PRESET ...]
Prints a markdown table: luminance error and bias of each real-time variant against the reference
march, and the time of one pass of each.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


OVERRIDES: dict = {}
SAVE = os.environ.get(
    "NUBIS_LIGHT_VOLUMES_OUT", ""
)  # a folder for each preset's three pictures side by side (reference, long tap, volumes)


def measure(name: str, width: int, height: int, passes: int) -> dict:
    import bpy

    from nubis_addon.blender import ensure_registered
    from nubis_addon.blender.host import runtime
    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.blender.scene import scenepresets
    from nubis_addon.core import metrics
    from nubis_addon.core.presets import load_preset

    bpy.ops.wm.read_factory_settings(use_empty=True)
    ensure_registered()
    scene = bpy.context.scene
    scenepresets.apply_preset(scene, load_preset(name))
    for key, value in OVERRIDES.items():
        setattr(scene.nubis, key, value)
    clouds = runtime.cloud_gpu(scene.nubis.noise_seed)
    row = {}
    images = {}
    for label, light_mode, volume in (("reference", 1, 1), ("long tap", 0, 0), ("volumes", 0, 1)):
        clouds.switches["NUBIS_LIGHT_VOLUME"] = volume
        shot = pipeline.viewport_shot(scene, width, height, light_mode, "full")
        start = time.perf_counter()
        images[label] = pipeline.render_shot(shot, passes)
        row[f"{label} s"] = (time.perf_counter() - start) / passes
    clouds.switches["NUBIS_LIGHT_VOLUME"] = 1
    if SAVE:
        from nubis_addon.core import imageio

        Path(SAVE).mkdir(parents=True, exist_ok=True)
        strip = np.concatenate([pipeline.display_image(scene, images[k]) for k in images], axis=1)
        imageio.write_image(Path(SAVE) / f"{name}.png", strip)
    for label in ("long tap", "volumes"):
        m = metrics.compare(images[label], images["reference"])
        row[label] = (m["luminance_rel_error"], m["luminance_bias"])
    return row


def main(width: int = 160, height: int = 90, passes: int = 4, names: list[str] | None = None) -> None:
    import nubis_addon
    from nubis_addon.core.presets import list_presets
    from nubis_addon.render.gpu_context import ensure_gpu_context

    nubis_addon.register()
    ensure_gpu_context()
    print(f"| preset ({width}x{height}, {passes} passes) | long tap: error | bias | volumes: error | bias |")
    print("|---|---|---|---|---|")
    for name in names or list_presets():
        r = measure(name, width, height, passes)
        (e0, b0), (e1, b1) = r["long tap"], r["volumes"]
        print(f"| {name} | {e0 * 100:.1f} % | {b0 * 100:+.1f} % | {e1 * 100:.1f} % | {b1 * 100:+.1f} % |", flush=True)


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if "=" not in a]
    OVERRIDES.update({k: float(v) for k, v in (a.split("=") for a in sys.argv[1:] if "=" in a)})
    numbers = [int(a) for a in args if a.isdigit()]
    main(*numbers[:3], names=[a for a in args if not a.isdigit()] or None)
