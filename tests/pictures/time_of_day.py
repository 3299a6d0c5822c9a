"""Make the time-of-day strip of the README: one New Cloudscape (default preset, physically based sky),
then only the Sun lamp is turned through sunset, from 6 degrees above the horizon to 4 below it, seen
towards the sun (top row) and away from it (bottom row). The sky, the lamp's colour (the atmosphere's
transmittance at the ground), the sun each cloud sees at its own altitude (Earth's shadow included) and
the clouds' sky light follow the lamp by themselves (blender/scene/sky.py, docs/sky.md#the-sun-each-cloud-sees);
the camera turns to frame each shot.

Run from the repository root:  .venv-5.3/bin/python tests/pictures/time_of_day.py OUT.png
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

# The sun's elevations of the strip (degrees), its azimuth (compass degrees), and the camera's pitch and
# headings towards the sun and away from it.
ELEVATIONS = (6.0, 2.0, 0.0, -2.0, -4.0)
AZIMUTH = 250.0
PITCH, TOWARDS, AWAY = 112.0, 100.0, -80.0
SHOTS = tuple(
    (f"sun {e:+g} deg, {side}", e, AZIMUTH, PITCH, heading)
    for side, heading in (("towards the sun", TOWARDS), ("away from it", AWAY))
    for e in ELEVATIONS
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
    bpy.ops.wm.read_factory_settings(use_empty=True)
    ensure_registered()
    bpy.ops.nubis.new_cloudscape(preset="default")
    scene = bpy.context.scene
    sun = scene.objects[scenepresets.SUN_NAME]
    images = []
    for label, elevation, azimuth, pitch, heading in SHOTS:
        sun.rotation_euler = Vector(sun_vector(elevation, azimuth)).to_track_quat("Z", "Y").to_euler()
        scene.camera.rotation_euler = Euler((math.radians(pitch), 0.0, math.radians(heading)), "XYZ")
        bpy.context.view_layer.update()  # the depsgraph handler moves the sky's sun and recolours the lamp
        rgba = pipeline.render_viewport(scene, 320, 180, passes=4)
        images.append(pipeline.display_image(scene, rgba))
        print(f"{label}: lamp colour {tuple(round(c, 3) for c in sun.data.color)}")
    n = len(ELEVATIONS)
    grid = np.concatenate([np.concatenate(images[:n], 1), np.concatenate(images[n:], 1)], 0)
    imageio.write_image(out, grid)
    print(f"wrote {out}: " + ", ".join(s[0] for s in SHOTS) + " (left to right, top to bottom)")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "time_of_day.png")
