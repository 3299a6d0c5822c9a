"""Cloud types measured on the baked VDB: stratus sits in a thinner band than cumulus
(docs/sources.md#vertical-profile)."""

import numpy as np

from nubis_addon.core.jobs import BakeOptions


def _band(make_scene, tmp_path, cloud_type: float) -> float:
    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.blender.scene import datafield
    from nubis_addon.core import vdbwrite

    scene = make_scene("default", cirrus_coverage=0.0)
    res = scene.nubis.field_resolution
    a = np.zeros((res, res, 4), np.float32)
    a[..., 0] = 0.8  # the same coverage everywhere: only the type differs
    a[..., 2] = cloud_type
    datafield.write_field_image(scene.nubis, "a", a)
    result = pipeline.bake(scene, tmp_path / f"type_{cloud_type}.vdb", BakeOptions(voxel_size=250.0))
    dense, lo = vdbwrite.read_grid_array(result.path, "density")
    z = np.nonzero(dense > 1e-3)[0] + lo[2]
    altitude = result.plan.origin[2] + z * result.plan.voxel_size
    assert len(altitude) > 1000
    top, bottom = np.percentile(altitude, [98, 2])
    return float(top - bottom)


def test_stratus_band_is_thinner_than_cumulus(make_scene, tmp_path):
    stratus = _band(make_scene, tmp_path, 0.0)
    stratocumulus = _band(make_scene, tmp_path, 0.5)
    cumulus = _band(make_scene, tmp_path, 1.0)
    # Profiles (shaders/nubis_density_lib.glsl): stratus ends by 20 % of the layer, cumulus by 100 %.
    assert stratus < stratocumulus < cumulus
    assert stratus < 0.5 * cumulus
