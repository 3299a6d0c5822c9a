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
    scene.nubis.density_cover = 1.0  # overcast where there is coverage: the -X half at full coverage
    return scene


def keep_multiplier(scene, multiplier: float = 1.0) -> None:
    """Set Coverage to the fraction `multiplier` covers on the scene's (hand-written) field, so the
    shaders multiply the field by it as before Coverage was a fraction (core/coverage.py)."""
    from nubis_addon.blender import scene_io
    from nubis_addon.core import coverage

    field = scene_io.read_fields(scene.nubis)[0][..., 0]
    scene.nubis.density_cover = coverage.covered_fraction(multiplier, coverage.field_histogram(field))
