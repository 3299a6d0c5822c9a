"""Shared set-ups for the GPU tests."""

import numpy as np


def split_coverage_scene(make_scene, **overrides):
    """Coverage 1 on the -X half of the field and 0 on the +X half, tall cumulus, no cirrus, a camera
    12 km up looking straight down at the split."""
    from nubis_addon.blender import scene_io

    scene = make_scene(
        "default",
        camera__location=[0.0, 0.0, 12000.0],
        camera__rotation=[0.0, 0.0, 0.0],
        camera__lens=18.0,
        **overrides,
    )
    res = scene.nubis.field_resolution
    a = np.zeros((res, res, 4), np.float32)
    a[:, : res // 2, 0] = 1.0
    a[..., 2] = 1.0
    scene_io.write_field_image(scene.nubis, "a", a)
    scene_io.write_field_image(scene.nubis, "cirrus", np.zeros((res, res, 4), np.float32))
    return scene
