"""The offline reference: the baked VDB as a Cycles volume whose material matches the viewport."""

from __future__ import annotations

import bpy

from ...core import bundled
from ...core.errors import NubisError

VOLUME_NAME = "Nubis Clouds VDB"
MATERIAL_NAME = "Nubis Cloud Volume"


def _grid_times(nt, grid: str, factor: float):
    """An Attribute node reading a VDB grid, times a factor: (attribute node, multiply node)."""
    attr = nt.nodes.new("ShaderNodeAttribute")
    attr.attribute_name = grid
    attr.attribute_type = "GEOMETRY"
    scale = nt.nodes.new("ShaderNodeMath")
    scale.operation = "MULTIPLY"
    scale.inputs[1].default_value = factor
    nt.links.new(attr.outputs["Fac"], scale.inputs[0])
    return attr, scale


def build_material(
    settings,
    with_glow: bool = False,
    with_absorption: bool = False,
    grid: str = "density",
    scale: float | None = None,
    name: str = MATERIAL_NAME,
) -> bpy.types.Material:
    """Scattering = density x sigma (the viewport's own); the viewport's two phase lobes as a mix of
    two Volume Scatter closures, which share one extinction and mix their phases (or Cycles' Mie
    phase as an option); rain's absorption grid as Volume Absorption; the storms' glow grid as
    emission. An artist's VDB cloud (blender/scene/vdbclouds.py) reads its own `grid` times its Density
    (`scale`) under its own `name`."""
    mat = bpy.data.materials.get(name) or bpy.data.materials.new(name)
    if mat.node_tree is None:  # materials made before 5.0 may lack a node tree
        mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    attr, scale = _grid_times(nt, grid, settings.density_sigma if scale is None else scale)
    if settings.lighting_cycles_mie:
        # Cycles' Mie phase for water droplets: physically richer than the viewport's lobes, so the
        # comparison then measures the phase model too.
        mie = nt.nodes.new("ShaderNodeVolumeScatter")
        mie.phase = "MIE"
        mie.inputs["Diameter"].default_value = settings.lighting_droplet_size
        nt.links.new(scale.outputs[0], mie.inputs["Density"])
        scatter = mie.outputs[0]
        lobes = [mie, mie]
    else:
        lobes = []
        for g in (settings.lighting_phase_g0, settings.lighting_phase_g1):
            node = nt.nodes.new("ShaderNodeVolumeScatter")
            node.phase = "HENYEY_GREENSTEIN"
            node.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
            node.inputs["Anisotropy"].default_value = g
            nt.links.new(scale.outputs[0], node.inputs["Density"])
            lobes.append(node)
        mix = nt.nodes.new("ShaderNodeMixShader")
        mix.inputs["Fac"].default_value = settings.lighting_phase_mix
        nt.links.new(lobes[0].outputs[0], mix.inputs[1])
        nt.links.new(lobes[1].outputs[0], mix.inputs[2])
        scatter = mix.outputs[0]
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    volume_out = scatter
    if with_absorption:
        # docs/sources.md#rain-and-storm-absorption: the viewport's rain raises extinction by absorbing; black
        # absorbs all of it.
        _absorb_attr, absorb_scale = _grid_times(nt, "absorption", settings.density_sigma)
        absorb = nt.nodes.new("ShaderNodeVolumeAbsorption")
        absorb.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        nt.links.new(absorb_scale.outputs[0], absorb.inputs["Density"])
        add = nt.nodes.new("ShaderNodeAddShader")
        nt.links.new(volume_out, add.inputs[0])
        nt.links.new(absorb.outputs[0], add.inputs[1])
        volume_out = add.outputs[0]
    if with_glow:
        # The `glow` grid holds density x glow; the march emits sigma x that per metre, in the storm's colour.
        _glow_attr, glow_scale = _grid_times(nt, "glow", settings.density_sigma)
        emission = nt.nodes.new("ShaderNodeEmission")
        colour = tuple(settings.storms[0].glow_color) if len(settings.storms) else (1.0, 0.08, 0.03)
        peak = max(colour) or 1.0
        emission.inputs["Color"].default_value = (*(c / peak for c in colour), 1.0)
        nt.links.new(glow_scale.outputs[0], emission.inputs["Strength"])
        add = nt.nodes.new("ShaderNodeAddShader")
        nt.links.new(volume_out, add.inputs[0])
        nt.links.new(emission.outputs[0], add.inputs[1])
        volume_out = add.outputs[0]
    nt.links.new(volume_out, out.inputs["Volume"])
    for i, node in enumerate(nt.nodes):
        node.location = (i * 220, -250 * (i % 2))
    return mat


def import_volume(scene, vdb_path: str, sequence: tuple[int, int, int] | None = None) -> bpy.types.Object:
    """The baked VDB as the scene's Nubis volume; `sequence` (first frame, frame count, step) loads the
    numbered files beside `vdb_path` (clouds_0001.vdb, ...) as a Volume sequence played with the frames."""
    remove_volume(scene)
    vol = bpy.data.volumes.new(VOLUME_NAME)
    vol.filepath = vdb_path
    vol.grids.load()
    if "density" not in [g.name for g in vol.grids]:
        bpy.data.volumes.remove(vol)
        raise NubisError(f"the VDB '{vdb_path}' has no 'density' grid: bake it again with Nubis")
    if sequence is not None:  # after the check, which reads the first file itself
        first, count, step = sequence
        vol.is_sequence = True
        vol.frame_start = first
        vol.frame_duration = (count - 1) * step + 1
        vol.frame_offset = first - 1  # file number = frame (Blender counts the first file as #1)
    # The reference must not round the bake: full-float grids, no clipping of thin edges.
    vol.render.precision = "FULL"
    vol.render.clipping = 0.0
    obj = bpy.data.objects.new(VOLUME_NAME, vol)
    scene.collection.objects.link(obj)
    names = [g.name for g in vol.grids]
    if "velocity" in names:
        # The bake's velocity is in metres per second of animation (docs/bake.md): Cycles motion blur.
        vol.velocity_grid = "velocity"
        vol.velocity_unit = "SECOND"
    vol.materials.append(build_material(scene.nubis, "glow" in names, "absorption" in names))
    # The grids carry their world transform; the object must stay at the identity...
    obj.matrix_world.identity()
    if bpy.app.version < (5, 0, 0):
        # ...except before Blender 5.0, whose Cycles puts voxel (i, j, k)'s value at the centre of the
        # index cell [i, i + 1], half a voxel off the grid's transform (5.0 puts it at i, as the bake
        # writes it). Measured with the single-scattering parity shot of tests/test_parity.py on 4.5.15:
        # alpha RMSE 0.022 as imported, 0.007 shifted by half a voxel back, 0.043 shifted forward
        # (docs/history.md#parity-with-cycles).
        half = _voxel_size(vdb_path) / 2
        obj.location = (-half, -half, -half)
    return obj


def _voxel_size(vdb_path: str) -> float:
    grids = bundled.openvdb().readAllGridMetadata(vdb_path)
    density = next(g for g in grids if g.name == "density")
    return float(density.transform.voxelSize()[0])


def remove_volume(scene) -> None:
    obj = bpy.data.objects.get(VOLUME_NAME)
    if obj is not None:
        vol = obj.data
        bpy.data.objects.remove(obj)
        if vol is not None and vol.users == 0:
            bpy.data.volumes.remove(vol)


def configure_render(
    scene, width: int, height: int, samples: int | None, bounces: int | None = None, exact_samples: bool = False
) -> None:
    """`exact_samples` sets Cycles up for a measurement: adaptive sampling off, so it gets the samples
    it asked for (adaptive sampling stops near a noise of 1 % whatever the count, which caps the
    reference's quality), and the samplers least noisy for clouds lit by a sun and a sky
    (docs/sources.md#cycles-reference)."""
    scene.render.engine = "CYCLES"
    if exact_samples:
        scene.cycles.use_adaptive_sampling = False
        # Measured at the default camera, 160x90, 256 samples, single scattering: the light tree's
        # noise 7.4 % of the luminance, sampling the sun and the sky alike 6.6 %.
        scene.cycles.use_light_tree = False
    scene.cycles.device = "CPU"
    if samples:
        scene.cycles.samples = samples
    if bounces is not None:
        scene.cycles.volume_bounces = bounces
    if exact_samples and hasattr(scene.cycles, "volume_biased"):
        # Blender 5.0's null-scattering volumes are unbiased but noisier than the ray marching 4.5
        # uses (at voxel-sized steps): 6.6 % against 4.9 % in the same shot, with their mean luminance
        # 0.6 % apart, within the noise. Only for single scattering, where it was measured: with
        # bounces every bounce marches, and the full comparison took longer.
        scene.cycles.volume_biased = scene.cycles.volume_bounces == 0
    scene.cycles.use_denoising = False
    # A one-pixel box filter: each pixel is the mean over its own area, what a supersampled viewport
    # render gives, so comparisons measure the clouds rather than the reconstruction filter.
    scene.cycles.pixel_filter_type = "BOX"
    scene.cycles.filter_width = 1.0
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = True
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.image_settings.color_mode = "RGBA"
    # Cloud interiors need bounces to brighten; everything else stays at Cycles' defaults.
    scene.cycles.max_bounces = max(scene.cycles.max_bounces, scene.cycles.volume_bounces)
    if scene.camera is not None:
        scene.camera.data.clip_end = max(scene.camera.data.clip_end, scene.nubis.layer_draw_radius * 3)
