"""Settings and field images survive saving and reloading the .blend."""

import numpy as np


def test_settings_and_fields_survive_save_and_reload(make_scene, blender, tmp_path):
    from nubis_addon.blender.scene import datafield

    scene = make_scene("default")
    scene.nubis.density_sigma = 0.0731
    scene.nubis.layers[0].scale = 4321.0
    # The scale edit owes a composite; reading the fields makes it, so the pixel written next is kept.
    a = datafield.read_fields(scene.nubis)[0].copy()
    a[3, 5] = (0.25, 0.5, 0.75, 0.125)
    datafield.write_field_image(scene.nubis, "a", a)
    path = tmp_path / "clouds.blend"
    blender.ops.wm.save_as_mainfile(filepath=str(path))
    blender.ops.wm.read_factory_settings(use_empty=True)
    blender.ops.wm.open_mainfile(filepath=str(path))
    s = blender.context.scene.nubis
    assert abs(s.density_sigma - 0.0731) < 1e-6
    assert s.layers[0].scale == 4321.0 and len(s.layers) >= 2
    back = datafield.read_field_image(s.field_a, "a", s.field_resolution)
    np.testing.assert_allclose(back, a, atol=1e-3)
    assert s.field_a.packed_file is not None
