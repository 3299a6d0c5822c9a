"""Make the README's peak-through-the-clouds picture: New Cloudscape (default preset), a 5 km rocky peak
16 km ahead of a camera 1 km up, piercing the cloud layer, and a ground plane; F12
(bpy.ops.render.render()) in EEVEE (left) and Cycles (right). The clouds in front of the peak's flanks
veil them, the peak stands above the layer, and the clouds' shadows fall on it (blender/f12/composition.py,
blender/f12/shadows.py).

Run from the repository root:  .venv-5.3/bin/python tests/pictures/peak_render.py OUT.png [WIDTH HEIGHT]
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


def _peak(bpy):
    """A cone roughened by a noise displacement, with a rock-grey diffuse material."""
    bpy.ops.mesh.primitive_cone_add(vertices=96, radius1=7000.0, depth=5000.0, location=(0.0, 16000.0, 2300.0))
    peak = bpy.context.object
    subdivide = peak.modifiers.new("Detail", "SUBSURF")
    subdivide.subdivision_type, subdivide.levels, subdivide.render_levels = "SIMPLE", 5, 5
    texture = bpy.data.textures.new("Rock", "CLOUDS")
    texture.noise_scale, texture.noise_depth = 1800.0, 4  # metres: ridges a few kilometres across
    displace = peak.modifiers.new("Rock", "DISPLACE")
    displace.texture, displace.strength, displace.texture_coords = texture, 1600.0, "GLOBAL"
    displace.mid_level = 0.5
    rock = bpy.data.materials.new("Rock")
    if rock.node_tree is None:
        rock.use_nodes = True
    rock.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.32, 0.28, 0.25, 1.0)
    peak.data.materials.append(rock)


def main(out: str, width: int = 480, height: int = 270) -> None:
    import bpy
    from final_render import eevee_name, new_cloudscape

    from nubis_addon.core import imageio

    scene = new_cloudscape()
    bpy.ops.mesh.primitive_plane_add(size=80000.0, location=(0.0, 20000.0, 0.0))
    land = bpy.data.materials.new("Land")
    if land.node_tree is None:
        land.use_nodes = True
    land.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.09, 0.1, 0.07, 1.0)
    bpy.context.object.data.materials.append(land)
    _peak(bpy)
    cam = scene.camera
    cam.location = (0.0, 0.0, 1000.0)
    cam.rotation_euler = (math.radians(93.0), 0.0, 0.0)
    cam.data.lens, cam.data.clip_end = 30.0, 100000.0
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = width, height, 100
    scene.cycles.device = "CPU"
    scene.cycles.samples = 32
    scene.eevee.taa_render_samples = 8
    eevee = eevee_name()
    row = []
    with tempfile.TemporaryDirectory() as tmp:
        for engine in (eevee, "CYCLES"):
            scene.render.engine = engine
            scene.render.filepath = str(Path(tmp) / f"{engine}.png")
            t = time.perf_counter()
            bpy.ops.render.render(write_still=True)
            print(f"{engine}: {time.perf_counter() - t:.1f} s")
            row.append(imageio.read_image(scene.render.filepath)[..., :3])
    imageio.write_image(out, np.concatenate(row, 1))
    print(f"wrote {out}: EEVEE (left) and Cycles (right)")


if __name__ == "__main__":
    args = sys.argv[1:]
    main(args[0] if args else "peak_render.png", *(int(a) for a in args[1:3]))
