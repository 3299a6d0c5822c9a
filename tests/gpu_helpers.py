"""Shared set-ups for the GPU tests."""

import numpy as np


def split_coverage_scene(make_scene, **overrides):
    """Coverage 1 on the -X half of the field and 0 on the +X half, tall cumulus, no cirrus, a camera
    12 km up looking straight down at the split."""
    from nubis_addon.blender.scene import datafield

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
    datafield.write_field_image(scene.nubis, "a", a)
    datafield.write_field_image(scene.nubis, "cirrus", np.zeros((res, res, 4), np.float32))
    return scene


def stroke_elements(xs, y=0.0, z=1500.0):
    """A brush stroke along y at the x's, as `nubis.paint_field(stroke=...)` takes it: Blender's
    OperatorStrokeElement, every key given (Blender wants them all)."""
    return [
        {
            "name": "",
            "location": (float(x), float(y), z),
            "mouse": (0.0, 0.0),
            "mouse_event": (0.0, 0.0),
            "pressure": 1.0,
            "size": 0.0,
            "x_tilt": 0.0,
            "y_tilt": 0.0,
            "time": 0.0,
            "is_start": i == 0,
        }
        for i, x in enumerate(xs)
    ]


def camera_view(bpy, scene, width: int, height: int):
    """A 3D view's region-data stand-in looking through the scene camera at width x height."""
    from types import SimpleNamespace

    from nubis_addon.blender.scene import sceneparams

    depsgraph = bpy.context.evaluated_depsgraph_get()
    cam = scene.camera.evaluated_get(depsgraph)
    return SimpleNamespace(
        window_matrix=cam.calc_matrix_camera(depsgraph, x=width, y=height, scale_x=1.0, scale_y=1.0),
        view_matrix=sceneparams.evaluated_matrix(scene.camera).inverted(),
        is_perspective=True,
    )
