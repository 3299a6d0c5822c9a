"""The Superstorms panel's buttons (docs/sources.md, GDC 2022): add and remove a storm, key its lifecycle and its
lightning."""

from __future__ import annotations

import bpy
from bpy.props import FloatProperty, IntProperty

from ...core import storms
from ...core.errors import NubisError
from ...core.state import MAX_STORMS
from ..host.ui import NeedsCloudscape
from ..scene import datafield, sceneparams, superstorms
from .operators import NubisOperator


class NUBIS_OT_storm_add(NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Add a superstorm stencil at the 3D cursor, positioned by a new Empty"""

    bl_idname = "nubis.storm_add"
    bl_label = "Add Superstorm"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def unavailable(cls, scene) -> str:
        if len(scene.nubis.storms) >= MAX_STORMS:
            return f"a scene holds at most {MAX_STORMS} superstorms: remove one first"
        return ""

    def run(self, context):
        self.refuse_if_unavailable(context.scene)
        s = context.scene.nubis
        cursor = context.scene.cursor.location
        superstorms.add_storm(context.scene, {"name": "Superstorm", "x": cursor.x, "y": cursor.y})
        s.active_storm = len(s.storms) - 1
        datafield.generate_fields(context.scene)
        return "Superstorm added: move its Empty to place it"


class NUBIS_OT_storm_remove(NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Remove the active superstorm and its Empty"""

    bl_idname = "nubis.storm_remove"
    bl_label = "Remove Superstorm"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def unavailable(cls, scene) -> str:
        return "" if scene.nubis.storms else "there is no superstorm to remove: add one with Add Superstorm"

    def run(self, context):
        self.refuse_if_unavailable(context.scene)
        s = context.scene.nubis
        storm = s.storms[min(s.active_storm, len(s.storms) - 1)]
        if storm.empty is not None:
            bpy.data.objects.remove(storm.empty)
        superstorms.remove_storm_animation(context.scene, s.active_storm)
        s.storms.remove(s.active_storm)
        s.active_storm = max(0, min(s.active_storm, len(s.storms) - 1))
        datafield.generate_fields(context.scene)
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
    curve = next(fc for fc in sceneparams.fcurves(scene) if fc.data_path == path)
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
        scene = context.scene
        storm = _active_storm(context)
        fps = sceneparams.scene_fps(scene)
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
        scene = context.scene
        storm = _active_storm(context)
        fps = sceneparams.scene_fps(scene)
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


CLASSES = (NUBIS_OT_storm_add, NUBIS_OT_storm_remove, NUBIS_OT_storm_lifecycle, NUBIS_OT_lightning_sequence)

register, unregister = bpy.utils.register_classes_factory(CLASSES)
