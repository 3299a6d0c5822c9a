"""Make the superstorm pictures of the README: from 30 km, from the ground beneath it, and a strip of
frames looking up into the mesocyclone while it turns, the last one lit by a lightning flash.

Run from the repository root:  .venv-5.3/bin/python tests/pictures/superstorm.py OUT_DIR
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def main(out_dir: str) -> None:
    import bpy

    import nubis_addon
    from nubis_addon.blender import ensure_registered
    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.blender.scene import scenepresets
    from nubis_addon.core import imageio
    from nubis_addon.core.presets import load_preset
    from nubis_addon.render.gpu_context import ensure_gpu_context

    nubis_addon.register()
    ensure_gpu_context()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)

    def scene_for(camera: dict):
        preset = load_preset("superstorm")
        preset.extra["camera"].update(camera)
        bpy.ops.wm.read_factory_settings(use_empty=True)
        ensure_registered()
        scene = bpy.context.scene
        scenepresets.apply_preset(scene, preset)
        return scene

    def shot(scene, name: str, w: int, h: int, passes: int = 4) -> np.ndarray:
        img = pipeline.display_image(scene, pipeline.render_viewport(scene, w, h, passes=passes))
        imageio.write_image(out / f"{name}.png", img)
        return img

    shot(scene_for({}), "superstorm_30km", 640, 360)
    ground = scene_for({"location": [0.0, 3000.0, 2.0], "rotation": [150.0, 0.0, 0.0], "lens": 16.0})
    shot(ground, "superstorm_ground", 640, 360)
    # The vortex turning: 60 s apart; the last frame holds a lightning flash (an intra-cloud flash keyed
    # on the storm, as the Add Lightning operator does).
    storm = ground.nubis.storms[0]
    frames = []
    for i, seconds in enumerate((0.0, 60.0, 120.0, 120.0)):
        ground.nubis.wind_time_offset = seconds
        storm.flash = 400.0 if i == 3 else 0.0
        frames.append(shot(ground, f"superstorm_frame{i}", 320, 180, passes=2))
    imageio.write_image(out / "superstorm_strip.png", np.concatenate(frames, axis=1))
    print(f"wrote the superstorm pictures into {out}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "superstorm_pictures")
