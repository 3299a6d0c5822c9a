"""The VDB bake (same GLSL density) and its Cycles render."""

import numpy as np
import pytest
from gpu_helpers import split_coverage_scene

from nubis_addon.core.jobs import BakeOptions


@pytest.fixture
def baked(make_scene, tmp_path):
    from nubis_addon.blender.jobs import pipeline

    scene = split_coverage_scene(make_scene)
    result = pipeline.bake(scene, tmp_path / "clouds.vdb", BakeOptions(voxel_size=400.0))
    return scene, result


def test_vdb_has_density_grid_transform_and_voxels(baked):
    from nubis_addon.core import vdbwrite

    scene, result = baked
    info = vdbwrite.read_grid_info(result.path)
    assert list(info) == ["density"]
    grid = info["density"]
    assert grid.voxel_size == pytest.approx(400.0)
    assert grid.origin == pytest.approx(result.plan.origin)
    assert grid.active_voxels > 1000 and grid.active_voxels == result.active_voxels
    assert 0.0 < grid.min_max[1] <= 1.0
    dense, lo = vdbwrite.read_grid_array(result.path, "density")
    z, y, x = np.nonzero(dense > 0)
    world_x = result.plan.origin[0] + (x + lo[0]) * 400.0
    world_z = result.plan.origin[2] + (z + lo[2]) * 400.0
    # Clouds only where coverage > 0 (the -X half), and only inside the layer's altitudes.
    assert world_x.max() <= 400.0
    assert world_z.min() >= scene.nubis.layer_bottom - 400.0 - 200.0  # curvature sag at the field's corners
    assert world_z.max() <= scene.nubis.layer_top + 400.0


def test_failed_bake_keeps_the_previous_vdb(baked, tmp_path):
    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.core.errors import NubisError

    scene, result = baked
    before = result.path.read_bytes()
    with pytest.raises(NubisError, match="voxel size of at least"):
        pipeline.bake(scene, result.path, BakeOptions(voxel_size=2.0))
    assert result.path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clouds.vdb"]


def test_cycles_renders_the_bake(baked):
    from nubis_addon.blender.jobs import pipeline

    scene, result = baked
    rgba = pipeline.render_cycles(scene, 48, 48, samples=4, vdb_path=str(result.path))
    viewport = pipeline.render_viewport(scene, 48, 48)
    assert rgba[:, :18, 3].mean() > 0.2  # clouds on the covered half
    assert rgba[:, 30:, 3].mean() < 0.02  # clear sky on the other
    assert rgba[:, :18, :3].mean() > 0.02  # lit by sun and sky
    overlap = ((rgba[..., 3] > 0.05) & (viewport[..., 3] > 0.05)).sum()
    union = ((rgba[..., 3] > 0.05) | (viewport[..., 3] > 0.05)).sum()
    assert overlap / union > 0.8


def test_cycles_mie_option_builds_a_mie_material(make_scene):
    from nubis_addon.blender.scene import cycles_setup

    scene = make_scene("default")
    scene.nubis.lighting_cycles_mie = True
    mat = cycles_setup.build_material(scene.nubis)
    phases = [n.phase for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeVolumeScatter"]
    assert phases == ["MIE"]
    scene.nubis.lighting_cycles_mie = False
    mat = cycles_setup.build_material(scene.nubis)
    phases = [n.phase for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeVolumeScatter"]
    assert phases == ["HENYEY_GREENSTEIN", "HENYEY_GREENSTEIN"]


def test_flash_renders_offline_through_the_glow_grid(make_scene, tmp_path):
    """The storm glow bakes to the `glow` grid, which Cycles turns into emission: a flash shows offline.

    The flash is red (the storm's glow colour), the storm's scattered light is not, so the flash must
    raise the red channel well beyond green and blue. Measured 2026-12-01 at 8 samples: red +32 to
    +45 %, green and blue -6 to +9 % on Blender 5.0.1; red +25 %, green +1 % on 4.5.15. (The test used
    to ask for +10 % of the whole frame's luminance: converged, the flash adds the same 3.5e-4 on both
    lines, which is +6.8 % on 5.0.1 and +5.0 % on 4.5, whose ray-marched volume renders the unlit storm
    30 % brighter; 5.0.1 passed only through noise, +14 % at 8 samples.) A glow grid Cycles ignores
    raises every channel alike, by noise only, and fails."""
    import math

    from nubis_addon.blender.jobs import pipeline

    scene = make_scene("superstorm")
    # A black ground: the storm's base is then lit by the flash alone, as under the Sky Texture's black
    # below the horizon when this was measured. Lit from a ground, the base is 3000 times brighter and
    # the flash's emission pushes Cycles past its closure limit, which dims the scattered light
    # (docs/limits.md).
    scene.nubis.sky_ground = (0.0, 0.0, 0.0)
    storm = scene.nubis.storms[0]
    storm.glow = 0.0
    scene.camera.location = (0.0, 3000.0, 2.0)
    scene.camera.rotation_euler = (math.radians(150), 0.0, 0.0)
    renders = []
    for flash in (0.0, 400.0):
        storm.flash = flash
        result = pipeline.bake(scene, tmp_path / f"f{int(flash)}.vdb", BakeOptions(voxel_size=400.0, camera_only=True))
        renders.append(pipeline.render_cycles(scene, 32, 18, samples=8, vdb_path=str(result.path)))
    gain = [float(renders[1][..., c].mean() / renders[0][..., c].mean()) - 1.0 for c in range(3)]
    assert gain[0] > 0.15 and gain[0] > max(gain[1], gain[2]) + 0.15, gain


def test_rain_absorbs_in_the_viewport_the_bake_and_cycles(make_scene, tmp_path):
    """Rain darkening is absorption (docs/sources.md#rain-and-storm-absorption): the viewport's raining
    clouds get darker and no thinner, the bake carries it as an `absorption` grid (density x (rain - 1))
    and Cycles adds it."""
    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.blender.scene import cycles_setup, datafield
    from nubis_addon.core import metrics, vdbwrite

    scene = split_coverage_scene(make_scene)
    scene.nubis.lighting_rain_absorption = 4.0
    dry = pipeline.render_viewport(scene, 48, 48)
    a = datafield.read_fields(scene.nubis)[0].copy()
    a[..., 1] = 1.0  # precipitation everywhere
    datafield.write_field_image(scene.nubis, "a", a)
    wet = pipeline.render_viewport(scene, 48, 48)
    covered = dry[..., 3] > 0.5
    assert covered.sum() > 100
    # Opaque pixels differ by where the march stops (transmittance < 0.005), so compare the means.
    assert wet[..., 3].mean() >= dry[..., 3].mean()
    assert metrics.luminance(wet)[covered].mean() < 0.8 * metrics.luminance(dry)[covered].mean()

    result = pipeline.bake(scene, tmp_path / "rain.vdb", BakeOptions(voxel_size=400.0))
    assert set(vdbwrite.read_grid_info(result.path)) == {"density", "absorption"}
    density, lo = vdbwrite.read_grid_array(result.path, "density")
    absorption, lo_abs = vdbwrite.read_grid_array(result.path, "absorption")
    assert lo == lo_abs and density.shape == absorption.shape
    assert absorption == pytest.approx(3.0 * density, abs=1e-4)
    obj = cycles_setup.import_volume(scene, str(result.path))
    nodes = [n.bl_idname for n in obj.data.materials[0].node_tree.nodes]
    assert "ShaderNodeVolumeAbsorption" in nodes
    cycles_setup.remove_volume(scene)
