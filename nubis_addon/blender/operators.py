"""Operators: every one that changes data supports undo and reports errors as a sentence."""

from __future__ import annotations

import contextlib

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty

from ..core import presets
from ..core.errors import NubisError
from . import cycles_setup, pipeline, scene_io, viewport


def _preset_items(_self, _context):
    items = []
    for name in presets.list_presets():
        try:
            label = presets.load_preset(name).name
        except NubisError:
            label = f"{name} (broken)"
        items.append((name, label, ""))
    return items or [("default", "Default", "")]


def _absolute(path: str) -> str:
    if path.startswith("//") and not bpy.data.filepath:
        raise NubisError("the path is relative to the .blend file, which is not saved yet: save it or give a full path")
    return bpy.path.abspath(path)


def _has_cloudscape(context) -> bool:
    scene = context.scene
    return scene is not None and getattr(scene, "nubis", None) is not None and scene.nubis.field_a is not None


class NubisOperator:
    def run(self, context):
        raise NotImplementedError

    def execute(self, context):
        try:
            message = self.run(context)
        except NubisError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        if message:
            self.report({"INFO"}, message)
        viewport.mark_dirty()
        for area in context.screen.areas if context.screen else ():
            area.tag_redraw()
        return {"FINISHED"}


class NeedsCloudscape:
    @classmethod
    def poll(cls, context):
        if not _has_cloudscape(context):
            cls.poll_message_set("Create a cloudscape first (Nubis > New Cloudscape)")
            return False
        return True


class NUBIS_OT_new_cloudscape(NubisOperator, bpy.types.Operator):
    """Create the cloud settings, data-field images, sun, sky and camera of a preset"""

    bl_idname = "nubis.new_cloudscape"
    bl_label = "New Cloudscape"
    bl_options = {"REGISTER", "UNDO"}

    preset: EnumProperty(name="Preset", items=_preset_items)

    def run(self, context):
        preset = presets.load_preset(self.preset)
        with _field_progress(context) as progress:
            scene_io.apply_preset(context.scene, preset, progress)
        return f"Cloudscape '{preset.name}' created"


@contextlib.contextmanager
def _field_progress(context):
    """The window manager's progress indicator while a field composite runs (slow stacks take seconds)."""
    wm = context.window_manager
    wm.progress_begin(0, 100)
    try:
        yield lambda fraction: wm.progress_update(int(fraction * 100))
    finally:
        wm.progress_end()


class NUBIS_OT_generate_field(NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Composite the layer stack into the data-field images"""

    bl_idname = "nubis.generate_field"
    bl_label = "Generate Field"
    bl_options = {"REGISTER", "UNDO"}

    def run(self, context):
        with _field_progress(context) as progress:
            scene_io.generate_fields(context.scene, progress)
        return "Data field generated"


class NUBIS_OT_layer_add(NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Add a field layer below the active one"""

    bl_idname = "nubis.layer_add"
    bl_label = "Add Layer"
    bl_options = {"REGISTER", "UNDO"}

    def run(self, context):
        from ..core.limits import MAX_LAYERS

        s = context.scene.nubis
        if len(s.layers) >= MAX_LAYERS:
            raise NubisError(f"a scene holds at most {MAX_LAYERS} field layers: merge or remove one first")
        layer = s.layers.add()
        layer.name = f"Layer {len(s.layers)}"
        s.layers.move(len(s.layers) - 1, min(s.active_layer + 1, len(s.layers) - 1))
        s.active_layer = min(s.active_layer + 1, len(s.layers) - 1)
        return None


class NUBIS_OT_layer_remove(NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Remove the active field layer"""

    bl_idname = "nubis.layer_remove"
    bl_label = "Remove Layer"
    bl_options = {"REGISTER", "UNDO"}

    def run(self, context):
        s = context.scene.nubis
        if not s.layers:
            raise NubisError("there is no layer to remove")
        s.layers.remove(s.active_layer)
        s.active_layer = max(0, min(s.active_layer, len(s.layers) - 1))
        scene_io.generate_fields(context.scene)
        return None


class NUBIS_OT_layer_move(NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Move the active field layer up or down the stack"""

    bl_idname = "nubis.layer_move"
    bl_label = "Move Layer"
    bl_options = {"REGISTER", "UNDO"}

    direction: EnumProperty(items=(("UP", "Up", ""), ("DOWN", "Down", "")))

    def run(self, context):
        s = context.scene.nubis
        target = s.active_layer + (-1 if self.direction == "UP" else 1)
        if 0 <= target < len(s.layers):
            s.layers.move(s.active_layer, target)
            s.active_layer = target
            scene_io.generate_fields(context.scene)
        return None


class NUBIS_OT_layer_duplicate(NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Duplicate the active field layer"""

    bl_idname = "nubis.layer_duplicate"
    bl_label = "Duplicate Layer"
    bl_options = {"REGISTER", "UNDO"}

    def run(self, context):
        from .properties import layer_from_dict, layer_to_dict

        s = context.scene.nubis
        if not s.layers:
            raise NubisError("there is no layer to duplicate")
        data = layer_to_dict(s.layers[s.active_layer])
        data["name"] += " copy"
        layer_from_dict(s.layers.add(), data)
        s.layers.move(len(s.layers) - 1, s.active_layer + 1)
        s.active_layer += 1
        scene_io.generate_fields(context.scene)
        return None


class NUBIS_OT_apply_weather_rules(NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Apply the rain rule (raining clouds become cumulonimbus, at least 70% coverage) and the horizon
    rule (cumulus at about 50% coverage from 15 km out) to the data field"""

    bl_idname = "nubis.apply_weather_rules"
    bl_label = "Apply Weather Rules"
    bl_options = {"REGISTER", "UNDO"}

    rain: BoolProperty(name="Rain Rule", default=True)
    horizon: BoolProperty(name="Horizon Rule", default=True)

    def run(self, context):
        s = context.scene.nubis
        s.rule_rain, s.rule_horizon = self.rain, self.horizon
        scene_io.generate_fields(context.scene)
        rules = [name for name, on in (("rain", self.rain), ("horizon", self.horizon)) if on]
        return f"Weather rules applied: {', '.join(rules) or 'none'}"


class NUBIS_OT_storm_add(NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Add a superstorm stencil at the 3D cursor, positioned by a new Empty"""

    bl_idname = "nubis.storm_add"
    bl_label = "Add Superstorm"
    bl_options = {"REGISTER", "UNDO"}

    def run(self, context):
        from ..core.state import MAX_STORMS

        s = context.scene.nubis
        if len(s.storms) >= MAX_STORMS:
            raise NubisError(f"a scene holds at most {MAX_STORMS} superstorms: remove one first")
        cursor = context.scene.cursor.location
        scene_io.add_storm(context.scene, {"name": "Superstorm", "x": cursor.x, "y": cursor.y})
        s.active_storm = len(s.storms) - 1
        scene_io.generate_fields(context.scene)
        return "Superstorm added: move its Empty to place it"


class NUBIS_OT_storm_remove(NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Remove the active superstorm and its Empty"""

    bl_idname = "nubis.storm_remove"
    bl_label = "Remove Superstorm"
    bl_options = {"REGISTER", "UNDO"}

    def run(self, context):
        s = context.scene.nubis
        if not s.storms:
            raise NubisError("there is no superstorm to remove")
        storm = s.storms[s.active_storm]
        if storm.empty is not None:
            bpy.data.objects.remove(storm.empty)
        scene_io.remove_storm_animation(context.scene, s.active_storm)
        s.storms.remove(s.active_storm)
        s.active_storm = max(0, min(s.active_storm, len(s.storms) - 1))
        scene_io.generate_fields(context.scene)
        return None


def _active_storm(context):
    s = context.scene.nubis
    if not s.storms:
        raise NubisError("add a superstorm first (Add Superstorm)")
    return s.storms[min(s.active_storm, len(s.storms) - 1)]


def _insert_keys(scene, storm, prop: str, keys, interpolation: str = "LINEAR") -> None:
    """Key `prop` of a storm at (frame, value) pairs straight into its F-curve. Setting the property
    first would not do: its update re-composites the field, which evaluates the animation and puts
    the already keyed value back before keyframe_insert reads it."""
    storm.keyframe_insert(prop, frame=keys[0][0])
    path = storm.path_from_id(prop)
    curve = next(fc for fc in scene_io.fcurves(scene) if fc.data_path == path)
    for frame, value in keys:
        curve.keyframe_points.insert(frame, value, options={"FAST"}).interpolation = interpolation
    curve.update()


class NUBIS_OT_storm_lifecycle(NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Keyframe the active storm's blend: ramp in, hold, ramp out from the current frame (GDC22)"""

    bl_idname = "nubis.storm_lifecycle"
    bl_label = "Keyframe Storm Lifecycle"
    bl_options = {"REGISTER", "UNDO"}

    ramp_in: FloatProperty(name="Ramp In (s)", default=120.0, min=0.0)
    hold: FloatProperty(name="Hold (s)", default=180.0, min=0.0)
    ramp_out: FloatProperty(name="Ramp Out (s)", default=120.0, min=0.0)

    def run(self, context):
        from ..core import storms

        scene = context.scene
        storm = _active_storm(context)
        fps = scene.render.fps / scene.render.fps_base
        keys = storms.lifecycle_keys(scene.frame_current, fps, self.ramp_in, self.hold, self.ramp_out)
        _insert_keys(context.scene, storm, "blend", keys)
        return f"Lifecycle keyed over frames {keys[0][0]}-{keys[-1][0]}"


class NUBIS_OT_lightning_sequence(NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Keyframe a lightning sequence on the active storm: intra-cloud flashes of rising intensity, then
    one or two ground discharges (GDC22 after Uman)"""

    bl_idname = "nubis.lightning_sequence"
    bl_label = "Add Lightning"
    bl_options = {"REGISTER", "UNDO"}

    flashes: IntProperty(name="Intra-cloud Flashes", default=4, min=1, max=20)
    discharges: IntProperty(name="Ground Discharges", default=2, min=0, max=2)
    peak: FloatProperty(name="Peak Intensity", default=20.0, min=0.0)
    seed: IntProperty(name="Seed", default=0, min=0)

    def run(self, context):
        from ..core import storms

        scene = context.scene
        storm = _active_storm(context)
        fps = scene.render.fps / scene.render.fps_base
        keys = storms.lightning_keys(scene.frame_current, fps, self.flashes, self.discharges, self.peak, self.seed)
        frames = [int(k["frame"]) for k in keys]
        _insert_keys(scene, storm, "flash", list(zip(frames, (k["flash"] for k in keys), strict=True)))
        # Positions jump from flash to flash, set well before each fires so the viewport's flash mask
        # is built in time (GDC22); only the intensity is interpolated.
        where = storms.lightning_position_keys(keys)
        at = [int(k["frame"]) for k in where]
        for prop, values in (
            ("flash_x", [k["x"] * storm.radius for k in where]),
            ("flash_y", [k["y"] * storm.radius for k in where]),
            ("flash_ground", [k["ground"] for k in where]),
        ):
            _insert_keys(scene, storm, prop, list(zip(at, values, strict=True)), "CONSTANT")
        return f"{self.flashes} flashes and {self.discharges} discharges keyed from frame {int(keys[0]['frame'])}"


class NUBIS_OT_render_image(NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Render the clouds from the scene camera into the image 'Nubis Render'"""

    bl_idname = "nubis.render_image"
    bl_label = "Render Clouds"

    def run(self, context):
        scene = context.scene
        w, h = pipeline.resolution(scene, None, None)
        rgba = pipeline.render_viewport(scene, w, h)
        img = bpy.data.images.get("Nubis Render") or bpy.data.images.new("Nubis Render", w, h, float_buffer=True)
        if tuple(img.size) != (w, h):
            img.scale(w, h)
        img.pixels.foreach_set(rgba[::-1].ravel())
        img.update()
        return f"Rendered {w}x{h} into the image 'Nubis Render'"


class NUBIS_OT_bake_vdb(NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Bake the viewport's cloud density to an OpenVDB file for Cycles and other renderers"""

    bl_idname = "nubis.bake_vdb"
    bl_label = "Bake OpenVDB"
    bl_options = {"REGISTER", "UNDO"}

    filepath: StringProperty(
        subtype="FILE_PATH", default="//nubis_clouds.vdb", options={"PATH_SUPPORTS_BLEND_RELATIVE"}
    )
    voxel_size: FloatProperty(
        name="Voxel Size", default=0.0, min=0.0, unit="LENGTH", description="0 uses the scene's bake voxel size"
    )

    def run(self, context):
        wm = context.window_manager
        path = _absolute(self.filepath)
        s = context.scene.nubis
        wm.progress_begin(0, 100)
        try:
            result = pipeline.bake(
                context.scene,
                path,
                self.voxel_size or None,
                lambda f: wm.progress_update(int(f * 100)),
                camera_only=s.bake_camera_only,
                half=s.bake_half,
                velocity=s.bake_velocity,
            )
        finally:
            wm.progress_end()
        cycles_setup.import_volume(context.scene, str(result.path))
        return f"Baked {result.active_voxels} voxels to {result.path} and added them as a Cycles volume"


class NUBIS_OT_bake_frames(NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Bake one VDB per frame of the scene's range (a sequence Blender's Volume object plays back)"""

    bl_idname = "nubis.bake_frames"
    bl_label = "Bake Sequence"

    directory: StringProperty(subtype="DIR_PATH", default="//nubis_vdb/", options={"PATH_SUPPORTS_BLEND_RELATIVE"})
    step: IntProperty(name="Frame Step", default=1, min=1)

    def run(self, context):
        scene = context.scene
        folder = _absolute(self.directory)
        frames = range(scene.frame_start, scene.frame_end + 1, self.step)
        wm = context.window_manager
        s = scene.nubis
        wm.progress_begin(0, 100 * len(frames))
        current = scene.frame_current
        try:
            for i, frame in enumerate(frames):
                scene.frame_set(frame)
                pipeline.bake(
                    scene,
                    f"{folder}/clouds_{frame:04d}.vdb",
                    progress=lambda f, i=i: wm.progress_update(int((i + f) * 100)),
                    camera_only=s.bake_camera_only,
                    half=s.bake_half,
                    velocity=s.bake_velocity,
                )
        finally:
            scene.frame_set(current)
            wm.progress_end()
        return f"Baked {len(frames)} frames into {folder}"


def _quality_items():
    from ..core import quality

    try:
        rows = quality.qualities()
    except NubisError as err:
        return (("standard", "Standard", str(err)),)
    return tuple((q.name, q.label, q.description) for q in rows.values())


# Built once: Blender keeps pointers to these strings for as long as the enum exists.
_QUALITY_ITEMS = _quality_items()


class NUBIS_OT_viewport_quality(NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Set the ray march and the viewport to a quality level (GDC22's PS4 and PS5 settings, or Horizon Zero Dawn's)"""

    bl_idname = "nubis.viewport_quality"
    bl_label = "Viewport Quality"
    bl_options = {"REGISTER", "UNDO"}

    quality: EnumProperty(name="Quality", items=_QUALITY_ITEMS)

    def run(self, context):
        from . import preview

        preview.apply_quality(context.scene, self.quality)
        return f"Quality '{self.quality}' applied"


class NUBIS_OT_benchmark(NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Time the viewport's redraw from the scene camera against the naive full march and EEVEE"""

    bl_idname = "nubis.benchmark"
    bl_label = "Benchmark"

    width: IntProperty(name="Width", default=480, min=16, max=7680)
    height: IntProperty(name="Height", default=270, min=16, max=4320)
    eevee: BoolProperty(name="Include EEVEE", default=True, description="Also bake and render the view with EEVEE")

    def run(self, context):
        from . import preview, runtime

        scene = context.scene
        out = runtime.cache_dir() / "benchmark"
        wm = context.window_manager
        wm.progress_begin(0, 1)
        try:
            result = preview.benchmark(scene, out, self.width, self.height, eevee=self.eevee)
        finally:
            wm.progress_end()
        viewport.last_benchmark[:] = preview.table(result).splitlines()
        eevee = f", EEVEE {result['eevee_over_redraw']:.0f}x" if "eevee_ms" in result else ""
        return (
            f"Redraw {result['redraw_ms']:.1f} ms, naive {result['naive_ms']:.0f} ms "
            f"({result['naive_over_redraw']:.1f}x){eevee}; details in {out}"
        )


CLASSES = (
    NUBIS_OT_new_cloudscape,
    NUBIS_OT_generate_field,
    NUBIS_OT_layer_add,
    NUBIS_OT_layer_remove,
    NUBIS_OT_layer_move,
    NUBIS_OT_layer_duplicate,
    NUBIS_OT_apply_weather_rules,
    NUBIS_OT_storm_add,
    NUBIS_OT_storm_remove,
    NUBIS_OT_storm_lifecycle,
    NUBIS_OT_lightning_sequence,
    NUBIS_OT_render_image,
    NUBIS_OT_bake_vdb,
    NUBIS_OT_bake_frames,
)


CLASSES += (NUBIS_OT_viewport_quality, NUBIS_OT_benchmark)

register, unregister = bpy.utils.register_classes_factory(CLASSES)
