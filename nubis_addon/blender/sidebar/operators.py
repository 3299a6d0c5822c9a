"""Operators: every one that changes data supports undo and reports errors as a sentence."""

from __future__ import annotations

import contextlib
import os

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty

from ...core import noise, presets, quality, userpresets
from ...core.errors import NubisError
from ...core.jobs import BenchmarkOptions
from ...core.limits import MAX_FIELD_LAYERS
from ..host import runtime, status, ui
from ..host.presetlist import active_preset, find_preset_entry, preset_entries
from ..host.ui import NeedsCloudscape
from ..jobs import preview, work
from ..live import viewport
from ..scene import cycles_setup, datafield, sceneparams, scenepresets, skycapture

_PRESET_ITEMS: dict = {}  # id(entries) -> items: Blender keeps pointers to these strings


def preset_items(_self=None, _context=None):
    """The New Cloudscape menu: the shipped presets, then the user's, each with its description as the
    tooltip. Built once per change of the preset folders (preset_entries), and the same list returned, so
    Blender's pointers to the strings stay valid."""
    entries = preset_entries()
    key = id(entries)
    if key not in _PRESET_ITEMS:
        _PRESET_ITEMS.clear()
        items = [(e.stem, e.name + (" (yours)" if e.user else ""), e.description) for e in entries]
        _PRESET_ITEMS[key] = (entries, items or [("default", "Default", "The default cloudscape")])
    return _PRESET_ITEMS[key][1]


def _absolute(path: str) -> str:
    if path.startswith("//") and not bpy.data.filepath:
        raise NubisError("the path is relative to the .blend file, which is not saved yet: save it or give a full path")
    return bpy.path.abspath(path)


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
        viewport.invalidate()
        ui.redraw_views()
        return {"FINISHED"}


class KeepOptions:
    """What New Cloudscape and Load Preset leave as the artist had it (scenepresets.Keep)."""

    keep_camera: BoolProperty(
        name="Keep Scene Camera", default=False, description="Render from the scene's camera, unmoved and unchanged"
    )
    keep_world: BoolProperty(name="Keep World", default=False, description="Keep the scene's World as the sky")
    keep_render: BoolProperty(
        name="Keep Render Settings",
        default=False,
        description="Keep resolution, frame, view transform and Cycles samples and bounces",
    )
    keep_sun: BoolProperty(
        name="Use Scene Sun", default=False, description="Light the clouds with the scene's own Sun lamp"
    )
    build_sky: BoolProperty(
        name="Build Sky",
        default=True,
        description="Make a new World with Blender's physical Sky Texture, its sun tied to the Sun lamp (the "
        "scene's own World is kept in the file); off sets the preset's flat color",
    )

    def keep(self):
        return scenepresets.Keep(self.keep_camera, self.keep_world, self.keep_render, self.keep_sun, self.build_sky)


class NUBIS_OT_new_cloudscape(KeepOptions, NubisOperator, bpy.types.Operator):
    """Create the cloud settings, data-field images, sun, sky and camera of a preset"""

    bl_idname = "nubis.new_cloudscape"
    bl_label = "New Cloudscape"
    bl_options = {"REGISTER", "UNDO"}

    preset: EnumProperty(name="Preset", items=preset_items)

    def invoke(self, context, _event):
        """In a scene that already has a camera, World or Sun of the artist's, ask what to keep."""
        scene = context.scene
        own_camera = scene.camera is not None and scene.camera.name != scenepresets.CAMERA_NAME
        own_world = scene.world is not None and scene.world.name != scenepresets.WORLD_NAME
        own_sun = any(
            o.type == "LIGHT" and o.data.type == "SUN" and o.name != scenepresets.SUN_NAME for o in scene.objects
        )
        if not (own_camera or own_world or own_sun):
            return self.execute(context)
        self.keep_camera, self.keep_world, self.keep_render, self.keep_sun = own_camera, own_world, True, own_sun
        return context.window_manager.invoke_props_dialog(self)

    def run(self, context):
        entry = find_preset_entry(self.preset)
        preset = presets.load_preset(str(entry.path) if entry else self.preset)
        keep = self.keep()
        with _field_progress(context) as progress:
            scenepresets.apply_preset(context.scene, preset, progress, keep)
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


class NUBIS_OT_view_toggle(NeedsCloudscape, bpy.types.Operator):
    """Show or hide the clouds in this 3D viewport only"""

    bl_idname = "nubis.view_toggle"
    bl_label = "Clouds in This Viewport"

    def execute(self, context):
        viewport.set_view_toggle(context, not viewport.view_toggle(context))
        ui.redraw_views()
        return {"FINISHED"}


class NUBIS_OT_generate_field(NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Composite the layer stack into the data-field images"""

    bl_idname = "nubis.generate_field"
    bl_label = "Generate Field"
    bl_options = {"REGISTER", "UNDO"}

    def run(self, context):
        with _field_progress(context) as progress:
            datafield.generate_fields(context.scene, progress)
        return "Data field generated"


class NUBIS_OT_layer_add(NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Add a field layer below the active one"""

    bl_idname = "nubis.layer_add"
    bl_label = "Add Layer"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def unavailable(cls, scene) -> str:
        if len(ui.active_cloud_layer(scene).layers) >= MAX_FIELD_LAYERS:
            return f"a scene holds at most {MAX_FIELD_LAYERS} field layers: merge or remove one first"
        return ""

    def run(self, context):
        self.refuse_if_unavailable(context.scene)
        s = ui.active_cloud_layer(context.scene)
        layer = s.layers.add()
        layer.name = f"Layer {len(s.layers)}"
        s.layers.move(len(s.layers) - 1, min(s.active_layer + 1, len(s.layers) - 1))
        s.active_layer = min(s.active_layer + 1, len(s.layers) - 1)
        return None


def _no_active_layer(settings, doing: str) -> str:
    """Why there is no active field layer to `doing`, or ""."""
    if not settings.layers or not 0 <= settings.active_layer < len(settings.layers):
        return f"there is no layer to {doing}: add one with + first"
    return ""


def _active_layer(settings, doing: str):
    """The active field layer, or the sentence that there is none to `doing`."""
    why = _no_active_layer(settings, doing)
    if why:
        raise NubisError(why)
    return settings.layers[settings.active_layer]


class ActsOnFieldLayer(NeedsCloudscape):
    """Grey, and says why, while the chosen cloud layer's field has no active layer to act on."""

    doing = "act on"

    @classmethod
    def unavailable(cls, scene) -> str:
        return _no_active_layer(ui.active_cloud_layer(scene), cls.doing)


class NUBIS_OT_layer_remove(ActsOnFieldLayer, NubisOperator, bpy.types.Operator):
    """Remove the active field layer"""

    doing = "remove"

    bl_idname = "nubis.layer_remove"
    bl_label = "Remove Layer"
    bl_options = {"REGISTER", "UNDO"}

    def run(self, context):
        s = ui.active_cloud_layer(context.scene)
        _active_layer(s, "remove")
        s.layers.remove(s.active_layer)
        s.active_layer = max(0, min(s.active_layer, len(s.layers) - 1))
        datafield.generate_fields(context.scene)
        return None


class NUBIS_OT_layer_move(ActsOnFieldLayer, NubisOperator, bpy.types.Operator):
    """Move the active field layer up or down the stack"""

    doing = "move"

    bl_idname = "nubis.layer_move"
    bl_label = "Move Layer"
    bl_options = {"REGISTER", "UNDO"}

    direction: EnumProperty(items=(("UP", "Up", ""), ("DOWN", "Down", "")))

    def run(self, context):
        s = ui.active_cloud_layer(context.scene)
        target = s.active_layer + (-1 if self.direction == "UP" else 1)
        if 0 <= target < len(s.layers):
            s.layers.move(s.active_layer, target)
            s.active_layer = target
            datafield.generate_fields(context.scene)
        return None


class NUBIS_OT_layer_duplicate(ActsOnFieldLayer, NubisOperator, bpy.types.Operator):
    """Duplicate the active field layer"""

    doing = "duplicate"

    bl_idname = "nubis.layer_duplicate"
    bl_label = "Duplicate Layer"
    bl_options = {"REGISTER", "UNDO"}

    def run(self, context):
        s = ui.active_cloud_layer(context.scene)
        data = datafield.layer_to_dict(_active_layer(s, "duplicate"))
        data["name"] += " copy"
        with sceneparams.batch_edit():
            copy = s.layers.add()
            try:
                datafield.layer_from_dict(copy, data)
                datafield.copy_dabs(s.layers[s.active_layer], copy)
            except NubisError:  # a copy refused (a paint layer on a channel no brush paints) leaves none
                s.layers.remove(len(s.layers) - 1)
                raise
        s.layers.move(len(s.layers) - 1, s.active_layer + 1)
        s.active_layer += 1
        datafield.generate_fields(context.scene)
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
        with sceneparams.batch_edit():
            s.rule_rain, s.rule_horizon = self.rain, self.horizon
        datafield.generate_fields(context.scene)
        rules = [name for name, on in (("rain", self.rain), ("horizon", self.horizon)) if on]
        return f"Weather rules applied: {', '.join(rules) or 'none'}"


def _default_bake_path(name: str) -> str:
    """Beside the .blend when it is saved, else in the home folder: never a `//` path nothing resolves."""
    return f"//{name}" if bpy.data.filepath else os.path.join(os.path.expanduser("~"), name)


class NUBIS_OT_render_image(NeedsCloudscape, work.ModalSteps, bpy.types.Operator):
    """Render the clouds from the scene camera into the image 'Nubis Render' (Esc cancels)"""

    bl_idname = "nubis.render_image"
    bl_label = "Render Clouds"

    doing = "rendering"
    cancelled = "Render cancelled: the image 'Nubis Render' is untouched"

    def jobs(self, context):
        return work.render_jobs(context.scene)

    def finished(self, context, results) -> str:
        rgba = results[0]
        h, w = rgba.shape[:2]
        img = bpy.data.images.get("Nubis Render") or bpy.data.images.new("Nubis Render", w, h, float_buffer=True)
        if tuple(img.size) != (w, h):
            img.scale(w, h)
        img.pixels.foreach_set(rgba[::-1].ravel())
        img.update()
        return f"Rendered {w}x{h} into the image 'Nubis Render'"


class NUBIS_OT_bake_vdb(NeedsCloudscape, work.ModalSteps, bpy.types.Operator):
    """Bake the viewport's cloud density to an OpenVDB file for Cycles and other renderers (Esc cancels)"""

    bl_idname = "nubis.bake_vdb"
    bl_label = "Bake OpenVDB"
    bl_options = {"REGISTER", "UNDO"}  # Ctrl-Z takes the imported Volume away; the file stays on disk

    filepath: StringProperty(subtype="FILE_PATH", default="", options={"PATH_SUPPORTS_BLEND_RELATIVE"})
    filter_glob: StringProperty(default="*.vdb", options={"HIDDEN"})
    voxel_size: FloatProperty(
        name="Voxel Size", default=0.0, min=0.0, unit="LENGTH", description="0 uses the scene's bake voxel size"
    )

    def invoke(self, context, _event):
        if not self.filepath:
            self.filepath = _default_bake_path("nubis_clouds.vdb")
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def jobs(self, context):
        return work.bake_jobs(
            context.scene, _absolute(self.filepath or _default_bake_path("nubis_clouds.vdb")), self.voxel_size or None
        )

    def finished(self, context, results) -> str:
        result = results[0]
        cycles_setup.import_volume(context.scene, str(result.path))
        return f"Baked {result.active_voxels} voxels to {result.path} and added them as a Cycles volume"


class NUBIS_OT_bake_frames(NeedsCloudscape, work.ModalSteps, bpy.types.Operator):
    """Bake one VDB per frame of the scene's range into a folder, and load them as a Volume sequence
    (Esc cancels; frames already baked stay)"""

    bl_idname = "nubis.bake_frames"
    bl_label = "Bake Sequence"
    bl_options = {"REGISTER", "UNDO"}

    directory: StringProperty(subtype="DIR_PATH", default="", options={"PATH_SUPPORTS_BLEND_RELATIVE"})
    step: IntProperty(name="Frame Step", default=1, min=1, description="Bake every Nth frame of the range")

    def invoke(self, context, _event):
        if not self.directory:
            self.directory = _default_bake_path("nubis_vdb") + os.sep
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def jobs(self, context):
        scene = context.scene
        folder = _absolute(self.directory or _default_bake_path("nubis_vdb"))
        try:
            os.makedirs(folder, exist_ok=True)
        except OSError as err:
            raise NubisError(
                f"cannot create the folder '{folder}' ({err.strerror}): choose a writable folder"
            ) from None
        self._frames = list(range(scene.frame_start, scene.frame_end + 1, self.step))
        self._folder = folder
        return work.sequence_jobs(scene, folder, self._frames)

    def finished(self, context, results) -> str:
        first = results[0].path
        cycles_setup.import_volume(context.scene, str(first), sequence=(self._frames[0], len(self._frames), self.step))
        return f"Baked {len(results)} frames into {self._folder} and loaded them as a Volume sequence"


def _quality_items():
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
        preview.apply_quality(context.scene, self.quality)
        return f"Quality '{self.quality}' applied"


class NUBIS_OT_benchmark(NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Time the viewport's redraw from the scene camera against the naive full march and EEVEE"""

    bl_idname = "nubis.benchmark"
    bl_label = "Benchmark"

    width: IntProperty(name="Width", default=480, min=16, max=7680)
    height: IntProperty(name="Height", default=270, min=16, max=4320)
    eevee: BoolProperty(name="Include EEVEE", default=True, description="Also bake and render the view with EEVEE")
    eevee_samples: IntProperty(
        name="EEVEE Samples", default=16, min=1, max=4096, description="EEVEE's samples when it renders the view"
    )

    def run(self, context):
        scene = context.scene
        out = runtime.cache_dir() / "benchmark"
        wm = context.window_manager
        wm.progress_begin(0, 1)
        try:
            result = preview.benchmark(
                scene,
                out,
                BenchmarkOptions(self.width, self.height, eevee=self.eevee, eevee_samples=self.eevee_samples),
            )
        finally:
            wm.progress_end()
        status.last_benchmark[:] = preview.sidebar_rows(result)
        eevee = f", EEVEE {result['eevee_over_redraw']:.0f}x" if "eevee_ms" in result else ""
        return (
            f"Redraw {result['redraw_ms']:.1f} ms, naive {result['naive_ms']:.0f} ms "
            f"({result['naive_over_redraw']:.1f}x){eevee}; details in {out}"
        )


# ---- the noise cache and user presets (the add-on's preferences; the preset menu of the main panel) --


class NUBIS_OT_clear_cache(NubisOperator, bpy.types.Operator):
    """Delete the cached noise volumes and sky captures; they are made again when needed"""

    bl_idname = "nubis.clear_cache"
    bl_label = "Clear Cache"

    def run(self, context):
        freed = noise.clear_cache(runtime.cache_dir())
        skies = skycapture.clear_stored()
        return f"Cleared {freed.sets} cached noise sets ({freed.nbytes / 2**20:.1f} MB) and {skies} sky captures"


class NUBIS_OT_preset_load(KeepOptions, NubisOperator, bpy.types.Operator):
    """Load a preset into this scene's cloudscape (or make one from it)"""

    bl_idname = "nubis.preset_load"
    bl_label = "Load Preset"
    bl_options = {"REGISTER", "UNDO"}

    filepath: StringProperty(subtype="FILE_PATH", options={"HIDDEN", "SKIP_SAVE"})

    @classmethod
    def description(cls, _context, properties):
        entry = next((e for e in preset_entries() if str(e.path) == properties.filepath), None)
        return entry.description if entry else cls.__doc__

    def invoke(self, context, event):
        # Where the scene holds the artist's own camera, World or Sun, ask what to keep, as New Cloudscape does.
        return NUBIS_OT_new_cloudscape.invoke(self, context, event)

    def run(self, context):
        if not self.filepath:
            raise NubisError("choose a preset from the menu")
        preset = presets.load_preset(self.filepath)
        keep = self.keep()
        with _field_progress(context) as progress:
            scenepresets.apply_preset(context.scene, preset, progress, keep)
        return f"Preset '{preset.name}' loaded"


class NUBIS_OT_preset_add(NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Save this scene's cloudscape as a preset of your own: every setting, the layers, the storms, and the
    sun, World, camera and render settings"""

    bl_idname = "nubis.preset_add"
    bl_label = "Add Preset"
    bl_options = {"REGISTER", "UNDO"}  # it names the scene's preset

    name: StringProperty(name="Name", description="The preset's name in the menu", maxlen=userpresets.MAX_NAME)
    preset_description: StringProperty(name="Description", description="One sentence on the preset: its tooltip")

    def invoke(self, context, _event):
        entry = active_preset(context)
        if not self.name and entry is not None and entry.user:
            self.name = entry.name
            self.preset_description = entry.description if entry.description != entry.name else ""
        return context.window_manager.invoke_props_dialog(self)

    def run(self, context):
        scene = context.scene
        preset = scenepresets.preset_from_scene(scene, self.name.strip(), self.preset_description.strip())
        path = userpresets.save_user_preset(runtime.user_preset_dir(), preset)
        scene.nubis.preset = path.stem
        transform = scene.view_settings.view_transform
        if transform != preset.extra["render"]["view_transform"]:
            self.report({"WARNING"}, f"the view transform '{transform}' is not one a preset holds: saved as AgX")
        return f"Preset '{preset.name}' saved to {path}"


class NUBIS_OT_preset_remove(NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Delete the active preset, if it is one you saved (the presets shipped with Nubis stay)"""

    bl_idname = "nubis.preset_remove"
    bl_label = "Remove Preset"

    name: StringProperty(name="Preset", description="File name of the preset to delete; empty: the active one")

    @classmethod
    def poll(cls, context):
        if not super().poll(context):
            return False
        try:
            entry = active_preset(context)
        except NubisError as err:
            cls.poll_message_set(str(err))
            return False
        if entry is None or not entry.user:
            cls.poll_message_set("Only presets you saved can be removed: load one of yours first")
            return False
        return True

    def invoke(self, context, event):
        return context.window_manager.invoke_confirm(self, event)

    def run(self, context):
        stem = self.name or context.scene.nubis.preset
        path = userpresets.remove_user_preset(runtime.user_preset_dir(), stem)
        return f"Preset '{stem}' removed ({path})"


CLASSES = (
    NUBIS_OT_new_cloudscape,
    NUBIS_OT_view_toggle,
    NUBIS_OT_generate_field,
    NUBIS_OT_layer_add,
    NUBIS_OT_layer_remove,
    NUBIS_OT_layer_move,
    NUBIS_OT_layer_duplicate,
    NUBIS_OT_apply_weather_rules,
    NUBIS_OT_render_image,
    NUBIS_OT_bake_vdb,
    NUBIS_OT_bake_frames,
)


CLASSES += (NUBIS_OT_viewport_quality, NUBIS_OT_benchmark)
CLASSES += (NUBIS_OT_clear_cache, NUBIS_OT_preset_load, NUBIS_OT_preset_add, NUBIS_OT_preset_remove)

register, unregister = bpy.utils.register_classes_factory(CLASSES)
