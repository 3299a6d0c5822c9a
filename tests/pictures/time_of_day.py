"""Make the time-of-day pictures of the README: sunrise, noon, sunset (looking into the sun for the
silver lining) and the sun behind the camera (dark powder edges).

Run from the repository root:  .venv/bin/python tests/pictures/time_of_day.py OUT.png
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

# label, sun elevation, sun azimuth, sun colour, sun strength, world colour, camera pitch, heading.
# Into-the-sun shots aim a few degrees beside the sun so thin cloud edges around it catch the
# silver-lining lobe; the last looks away from a sun behind the camera (dark powder edges).
SHOTS = (
    ("sunrise, towards the sun", 9.0, 80.0, (1.0, 0.55, 0.3), 4.0, (0.35, 0.32, 0.45), 102.0, -70.0),
    ("noon", 70.0, 180.0, (1.0, 0.97, 0.92), 6.0, (0.25, 0.45, 0.85), 100.0, 20.0),
    ("sunset, into the sun", 10.0, 250.0, (1.0, 0.5, 0.25), 5.0, (0.32, 0.3, 0.5), 103.0, 100.0),
    ("sun behind the camera", 20.0, 200.0, (1.0, 0.93, 0.82), 5.0, (0.25, 0.45, 0.85), 100.0, 20.0),
)


def main(out: str) -> None:
    import bpy

    import nubis_addon
    from nubis_addon.blender import ensure_registered, pipeline, scene_io
    from nubis_addon.core import imageio
    from nubis_addon.core.presets import load_preset
    from nubis_addon.render.gpu_context import ensure_gpu_context

    nubis_addon.register()
    ensure_gpu_context()
    images = []
    for _label, elevation, azimuth, colour, strength, world, pitch, heading in SHOTS:
        preset = load_preset("default")
        preset.extra["sun"].update(elevation=elevation, azimuth=azimuth, color=list(colour), strength=strength)
        preset.extra["world"]["color"] = list(world)
        # Blender cameras look along -Z; heading turns about Z from +Y towards -X.
        preset.extra["camera"]["rotation"] = [pitch, 0.0, heading]
        bpy.ops.wm.read_factory_settings(use_empty=True)
        ensure_registered()
        scene = bpy.context.scene
        scene_io.apply_preset(scene, preset)
        rgba = pipeline.render_viewport(scene, 400, 225)
        images.append(pipeline.display_image(scene, rgba))
    grid = np.concatenate([np.concatenate(images[:2], 1), np.concatenate(images[2:], 1)], 0)
    imageio.write_image(out, grid)
    print(f"wrote {out}: " + ", ".join(s[0] for s in SHOTS) + " (left to right, top to bottom)")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "time_of_day.png")
