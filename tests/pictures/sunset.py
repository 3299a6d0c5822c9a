"""Make the sunset pictures of the README (docs/sky.md#the-sun-each-cloud-sees), each a New Cloudscape with
its Sun lamp turned, drawn as the viewport draws it:
- the default cloudscape at sunset, the sun 2 degrees up, looking towards it;
- its afterglow, the sun 1 degree below the horizon, looking towards it: the ground in Earth's shadow,
  the clouds above 969 m still lit, red;
- the layered sky (altocumulus over stratocumulus) from between its layers with the sun 1.5 degrees
  down: Earth's shadow stands at 2.2 km, so the altocumulus at 4.8 km glows while the deck at 1-1.8 km
  has gone grey.

Run from the repository root:  .venv-5.3/bin/python tests/pictures/sunset.py OUT.png
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

# label, preset, sun elevation, sun azimuth (compass degrees), camera pitch and heading (None: the preset's).
SHOTS = (
    ("sunset, sun +2 deg", "default", 2.0, 250.0, 112.0, 100.0),
    ("afterglow, sun -1 deg", "default", -1.0, 250.0, 108.0, 100.0),
    ("layered, sun -1.5 deg", "altocumulus_over_stratocumulus", -1.5, 345.0, None, None),
)


def main(out: str) -> None:
    import bpy
    from mathutils import Euler, Vector

    import nubis_addon
    from nubis_addon.blender import ensure_registered
    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.blender.scene import scenepresets
    from nubis_addon.core import imageio
    from nubis_addon.core.state import sun_vector
    from nubis_addon.render.gpu_context import ensure_gpu_context

    nubis_addon.register()
    ensure_gpu_context()
    images = []
    for label, preset, elevation, azimuth, pitch, heading in SHOTS:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        ensure_registered()
        bpy.ops.nubis.new_cloudscape(preset=preset)
        scene = bpy.context.scene
        sun = scene.objects[scenepresets.SUN_NAME]
        sun.rotation_euler = Vector(sun_vector(elevation, azimuth)).to_track_quat("Z", "Y").to_euler()
        if pitch is not None:
            scene.camera.rotation_euler = Euler((math.radians(pitch), 0.0, math.radians(heading)), "XYZ")
        bpy.context.view_layer.update()  # the depsgraph handler moves the sky's sun and recolours the lamp
        rgba = pipeline.render_viewport(scene, 400, 225, passes=8)
        images.append(pipeline.display_image(scene, rgba))
        print(f"{label}: lamp colour {tuple(round(c, 3) for c in sun.data.color)}")
    imageio.write_image(out, np.concatenate(images, 1))
    print(f"wrote {out}: " + ", ".join(s[0] for s in SHOTS) + " (left to right)")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "sunset.png")
