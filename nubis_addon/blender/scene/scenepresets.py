"""A preset into a scene (New Cloudscape, Load Preset) and a scene back into a preset: its settings,
field layers, cloud layers, storms, sun, sky and camera."""

from __future__ import annotations

import math
from dataclasses import dataclass

import bpy
from mathutils import Euler, Vector

from ...core import coverage, schema, userpresets
from ...core.presets import Preset
from ...core.state import MAX_STORMS, sun_vector
from ..host import ui
from . import datafield, sceneparams, sky, skyground, superstorms

SUN_NAME = "Nubis Sun"


WORLD_NAME = "Nubis Sky"


CAMERA_NAME = "Nubis Camera"


@dataclass(frozen=True)
class Keep:
    """What New Cloudscape leaves as the artist had it. Everything not kept is set up from the preset."""

    camera: bool = False  # the scene camera: not moved, not re-lensed
    world: bool = False  # the scene's World: not replaced or recolored
    render: bool = False  # resolution, frame, view transform, Cycles samples and bounces
    sun: bool = False  # light the clouds with the scene's own Sun lamp rather than the preset's
    sky: bool | None = None  # build a physical sky World (blender/scene/sky.py); None: the preset's [world] sky


def apply_preset(scene, preset: Preset, progress=None, keep: Keep = Keep()) -> None:
    """Make `scene` the preset's cloudscape: settings, layer stack, field images, and (unless `keep`
    says otherwise) its sun, world, camera and render settings; ``progress`` follows the field
    composite. The World is a physically based sky ('Nubis Sky', blender/scene/sky.py) when the preset's
    `[world] sky` (or `keep.sky`) asks for one, else the preset's flat color; an artist's World stays in
    the file. Storm Empties an artist made stay in the scene; those Nubis made for the old storms go."""
    settings = scene.nubis
    own_sun = (
        settings.sun if keep.sun and settings.sun is not None else (skyground.find_sun(scene) if keep.sun else None)
    )
    with sceneparams.batch_edit():
        for key, value in preset.params.items():
            s = schema.BY_KEY[key]
            setattr(settings, key, value.upper() if s.kind == "enum" else value)
        settings.preset = preset.path.stem if preset.path else preset.name
        settings.layers.clear()
        for data in preset.layers:
            data = dict(data)
            if data["kind"] == "image":
                data["image"] = datafield.load_layer_image(data["image"], preset.path)
            datafield.layer_from_dict(settings.layers.add(), data)
        settings.cloud_layers.clear()
        for data in preset.cloud_layers:
            datafield.add_cloud_layer(settings, data, preset.path)
        settings.active_further_layer = ui.FIRST_LAYER
        settings.first_layer_enabled, settings.first_layer_solo = True, False
        settings.sun = own_sun or _setup_sun(scene, preset.extra["sun"])
        if not keep.camera or scene.camera is None:
            _setup_camera(scene, preset.extra["camera"])
        for storm in list(settings.storms):
            if storm.empty is not None and storm.empty.get(superstorms.STORM_TAG):
                bpy.data.objects.remove(storm.empty)
        settings.storms.clear()
        for data in preset.storms:
            superstorms.add_storm(scene, data)
    datafield.generate_fields(scene, progress)  # after the camera and storms: the rules and stencils are placed by them
    if preset.legacy_coverage is not None:
        with sceneparams.batch_edit():
            settings.density_cover = coverage.covered_fraction(
                preset.legacy_coverage, sceneparams.scene_state(scene).cover_hist
            )
            settings.density_coverage = preset.legacy_coverage
    # The sky after the (possibly long) composite: its capture renders with Cycles for a second.
    if not keep.world or scene.world is None:
        build_sky = preset.extra["world"]["sky"] if keep.sky is None else keep.sky
        if build_sky:
            sky.build_world(scene, preset.extra["world"], settings.sun)
        else:
            _setup_world(scene, preset.extra["world"])
    if keep.render:
        return
    r = preset.extra["render"]
    scene.render.resolution_x, scene.render.resolution_y = r["width"], r["height"]
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = r["view_transform"]
    scene.frame_current = r["frame"]
    scene.cycles.samples = r["samples"]
    scene.cycles.volume_bounces = r["volume_bounces"]


def preset_from_scene(scene, name: str, description: str = "") -> Preset:
    """The scene's cloudscape as a preset (what Save Preset writes): every scene setting a preset
    holds, the layer stack, the storms (centred on their Empties), and the sun, world, camera and
    render sections read back from Blender's objects, the inverse of apply_preset. Floats are written
    as the shortest decimals of their float32 values (core/userpresets.py)."""
    settings = scene.nubis
    tidy = userpresets.tidy_float32
    params = {}
    for s in schema.PRESET_SCENE:
        value = sceneparams.from_blender(s, getattr(settings, s.key))
        params[s.key] = tidy(value) if s.kind in ("float", "vector", "color") else value
    layers = [datafield.layer_table(layer) for layer in settings.layers]
    storms = []
    for storm in list(settings.storms)[:MAX_STORMS]:
        data = {k: tidy(v) for k, v in sceneparams.table_to_dict(storm, schema.STORM).items()}
        data["x"], data["y"] = (tidy(v) for v in superstorms.storm_centre(storm))
        storms.append(data)
    extra = {sec: schema.table_defaults(t.values()) for sec, t in schema.EXTRA_SECTIONS.items() if sec != "preset"}
    sun = skyground.find_sun(scene)
    if sun is not None:
        d = sceneparams.evaluated_matrix(sun).to_3x3() @ Vector((0.0, 0.0, 1.0))
        d.normalize()
        extra["sun"].update(
            elevation=math.degrees(math.asin(max(-1.0, min(1.0, d.z)))),
            azimuth=math.degrees(math.atan2(d.x, d.y)) % 360.0,
            color=list(sun.data.color),
            strength=sun.data.energy,
            angle=math.degrees(sun.data.angle),
        )
    world = scene.world
    if sky.is_nubis_sky(world):
        extra["world"].update(sky.atmosphere(world))
    elif world is not None:
        extra["world"].update(sky=False)
        bg = next((n for n in world.node_tree.nodes if n.type == "BACKGROUND"), None) if world.node_tree else None
        if bg is not None:
            extra["world"].update(color=list(bg.inputs["Color"].default_value)[:3])
            extra["world"].update(strength=bg.inputs["Strength"].default_value)
        else:
            extra["world"].update(color=list(world.color))
    cam = scene.camera
    if cam is not None:
        if cam.parent is None and cam.rotation_mode == "XYZ" and not cam.constraints:
            location, rotation = list(cam.location), list(cam.rotation_euler)
        else:
            m = sceneparams.evaluated_matrix(cam)
            location, rotation = list(m.translation), list(m.to_euler("XYZ"))
        extra["camera"].update(location=location, rotation=[math.degrees(a) for a in rotation])
        if cam.type == "CAMERA":
            extra["camera"].update(lens=cam.data.lens, clip_end=cam.data.clip_end)
    r = scene.render
    pct = r.resolution_percentage / 100.0
    extra["render"].update(
        width=max(4, round(r.resolution_x * pct)), height=max(4, round(r.resolution_y * pct)), frame=scene.frame_current
    )
    cycles = getattr(scene, "cycles", None)
    if cycles is not None:
        extra["render"].update(samples=cycles.samples, volume_bounces=cycles.volume_bounces)
    if scene.view_settings.view_transform in schema.EXTRA_SECTIONS["render"]["view_transform"].choices:
        extra["render"]["view_transform"] = scene.view_settings.view_transform
    for table in extra.values():
        for key, value in table.items():
            table[key] = tidy(value)
    return Preset(
        name, None, params, extra, layers, description, storms, cloud_layers=datafield.cloud_layers_of(settings)
    )


def _setup_sun(scene, sun: dict):
    obj = scene.objects.get(SUN_NAME)
    if obj is None or obj.type != "LIGHT":
        data = bpy.data.lights.new(SUN_NAME, type="SUN")
        obj = bpy.data.objects.new(SUN_NAME, data)
        scene.collection.objects.link(obj)
    d = Vector(sun_vector(sun["elevation"], sun["azimuth"]))
    # A sun lamp shines along its local -Z; point +Z at the sun.
    obj.rotation_euler = d.to_track_quat("Z", "Y").to_euler()
    obj.location = (0.0, 0.0, 10.0)
    obj.data.color = sun["color"]
    obj.data.energy = sun["strength"]
    obj.data.angle = math.radians(sun["angle"])
    return obj


def _setup_world(scene, world_cfg: dict) -> None:
    """The preset's sky as the World "Nubis Sky"; an artist's own World is kept in the file (fake user)."""
    world = bpy.data.worlds.get(WORLD_NAME) or bpy.data.worlds.new(WORLD_NAME)
    if scene.world is not None and scene.world != world:
        scene.world.use_fake_user = True
    scene.world = world
    world.color = world_cfg["color"]
    if world.node_tree is None:  # worlds made before 5.0 may lack a node tree
        world.use_nodes = True
    if sky.MARKER in world:
        del world[sky.MARKER]
    bg = next((n for n in world.node_tree.nodes if n.type == "BACKGROUND"), None)
    if bg is None:
        bg = world.node_tree.nodes.new("ShaderNodeBackground")
        out = next((n for n in world.node_tree.nodes if n.type == "OUTPUT_WORLD"), None)
        out = out or world.node_tree.nodes.new("ShaderNodeOutputWorld")
        world.node_tree.links.new(bg.outputs[0], out.inputs["Surface"])
    bg.inputs["Color"].default_value = (*world_cfg["color"], 1.0)
    bg.inputs["Strength"].default_value = world_cfg["strength"]


def _setup_camera(scene, cam: dict) -> None:
    """The preset's view from the camera "Nubis Camera", made the scene camera; an artist's own camera
    is left where it was."""
    obj = scene.objects.get(CAMERA_NAME)
    if obj is None or obj.type != "CAMERA":
        obj = bpy.data.objects.new(CAMERA_NAME, bpy.data.cameras.new(CAMERA_NAME))
        scene.collection.objects.link(obj)
    scene.camera = obj
    obj.location = cam["location"]
    obj.rotation_euler = Euler([math.radians(a) for a in cam["rotation"]], "XYZ")
    obj.data.lens = cam["lens"]
    obj.data.clip_end = cam["clip_end"]
