"""The benchmarks' shared peak scene: the default cloudscape with a 5 km cone through its layer, 16 km ahead
of the camera 1 km up (its flanks behind clouds), as tests/gpu/test_objects_in_clouds.py has it."""

from __future__ import annotations

import math


def peak_scene():
    """A fresh factory scene made into the peak scene; returns the scene."""
    import bpy

    from nubis_addon.blender import ensure_registered

    bpy.ops.wm.read_factory_settings(use_empty=True)
    ensure_registered()
    bpy.ops.nubis.new_cloudscape(preset="default")
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_cone_add(vertices=64, radius1=6000.0, depth=5000.0, location=(0, 16000, 2500))
    cam = scene.camera
    cam.location, cam.rotation_euler = (0.0, 0.0, 1000.0), (math.radians(92.0), 0.0, 0.0)
    cam.data.lens, cam.data.clip_end = 30.0, 100000.0
    return scene
