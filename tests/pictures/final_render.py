"""Make the README's final-render pictures: New Cloudscape (default preset) plus a 40 km grey ground
plane and an 800 m cube, rendered with bpy.ops.render.render() in EEVEE and in Cycles at frames 1 and 240
(the clouds behind the cube, their shadows on the ground, moved by the wind; blender/f12/scene_render.py).

Run from the repository root:  .venv-5.3/bin/python tests/pictures/final_render.py OUT.png [WIDTH HEIGHT]
"""

from __future__ import annotations

import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def new_cloudscape():
    """Blender as a module with the extension registered and a fresh scene holding New Cloudscape (the
    default preset); the scene. The other final-render pictures start here too."""
    import bpy

    import nubis_addon
    from nubis_addon.blender import ensure_registered
    from nubis_addon.render.gpu_context import ensure_gpu_context

    nubis_addon.register()
    ensure_gpu_context()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    ensure_registered()
    bpy.ops.nubis.new_cloudscape(preset="default")
    return bpy.context.scene


def eevee_name() -> str:
    import bpy

    engines = {e.identifier for e in bpy.types.RenderSettings.bl_rna.properties["engine"].enum_items}
    return "BLENDER_EEVEE_NEXT" if "BLENDER_EEVEE_NEXT" in engines else "BLENDER_EEVEE"


def main(out: str, width: int = 320, height: int = 180) -> None:
    import bpy

    from nubis_addon.core import imageio

    scene = new_cloudscape()
    bpy.ops.mesh.primitive_plane_add(size=40000.0, location=(0.0, 0.0, 0.0))
    ground = bpy.data.materials.new("Ground")
    ground.diffuse_color = (0.3, 0.3, 0.28, 1.0)
    if ground.node_tree is None:
        ground.use_nodes = True
    ground.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.3, 0.3, 0.28, 1.0)
    bpy.context.object.data.materials.append(ground)
    bpy.ops.mesh.primitive_cube_add(size=800.0, location=(-1200.0, 1500.0, 400.0))
    cam = scene.camera
    cam.location = (0.0, -6000.0, 500.0)
    cam.rotation_euler = (math.radians(80.0), 0.0, math.radians(10.0))
    cam.data.lens = 18.0
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = width, height, 100
    scene.cycles.device = "CPU"
    scene.cycles.samples = 32
    scene.eevee.taa_render_samples = 8
    eevee = eevee_name()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for engine in (eevee, "CYCLES"):
            row = []
            for frame in (1, 240):
                scene.render.engine = engine
                scene.frame_set(frame)
                scene.render.filepath = str(Path(tmp) / f"{engine}_{frame}.png")
                t = time.perf_counter()
                bpy.ops.render.render(write_still=True)
                print(f"{engine} frame {frame}: {time.perf_counter() - t:.1f} s")
                row.append(imageio.read_image(scene.render.filepath)[..., :3])
            rows.append(np.concatenate(row, 1))
    imageio.write_image(out, np.concatenate(rows, 0))
    print(f"wrote {out}: EEVEE (top) and Cycles (bottom), frame 1 (left) and 240 (right)")


if __name__ == "__main__":
    args = sys.argv[1:]
    main(args[0] if args else "final_render.png", *(int(a) for a in args[1:3]))
