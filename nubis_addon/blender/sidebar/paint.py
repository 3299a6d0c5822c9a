"""Painting the sky from above, live in the 3D view: the Paint Sky tool and `nubis.paint_field`.

A stroke's dabs go into a paint layer of the field's layer stack (core/paint.py): plain data, saved with
the .blend and undone stroke by stroke (the operator is one undo step). During a drag only the stroke's
rectangle of the field is re-composited and written into the GPU texture in place
(render/fieldpatch.py); when the stroke ends the whole field is composited again after the usual pause,
for renders, bakes and the file. docs/painting.md says how painted coverage meets the Coverage slider.
"""

from __future__ import annotations

import math
import time

import bpy
import gpu
from bpy.props import CollectionProperty, EnumProperty, FloatProperty, StringProperty
from bpy_extras import view3d_utils
from gpu_extras.batch import batch_for_shader

from ...core import paint
from ...core.errors import NubisError
from ..host import ui
from ..host.ui import NeedsCloudscape, SidebarPanel
from ..live import events, paintstroke, viewport
from ..scene import datafield, sceneparams

TOOL_ID = "nubis.paint_sky"
PAINT_OPERATOR = "nubis.paint_field"
BRUSH_KEYS = ("channel", "radius", "strength", "falloff")  # the brush settings the tool and the sidebar show


def _drag(mode: paint.BrushMode, plain: str = "drag") -> str:
    """How a drag picks `mode`: "Ctrl-drag", or `plain` for the drag without a modifier key."""
    return f"{mode.key.title()}-drag" if mode.key else plain


# The menus, in core/paint.py's order: Blender keeps an operator's choice by its position in the menu.
_CHANNELS = tuple((c.name.upper(), c.label, c.description) for c in paint.BRUSH_CHANNELS)
_PLAIN_DRAG = "the tool's plain drag"
_MODES = tuple((m.name.upper(), m.label, f"{m.description} ({_drag(m, _PLAIN_DRAG)})") for m in paint.BRUSH_MODES)
_FALLOFFS = tuple((f.upper(), f.title(), f"{f.title()} falloff from the centre to the radius") for f in paint.FALLOFFS)
# The drags as the tool's tooltip, the sidebar's hint and the operator's tooltip say them.
DRAGS = ", ".join(f"{_drag(m)} to {m.name}" for m in paint.BRUSH_MODES)
DRAG_HINT = " · ".join(f"{m.key.title() or 'Drag'}: {m.name}" for m in paint.BRUSH_MODES)
MODIFIER_DRAGS = ", ".join(f"{m.key.title()} {m.name}s" for m in paint.BRUSH_MODES if m.key)
_cursor: dict = {}  # what the brush circle draws: world centre, radius; empty when it is off the layer
# ---- where a stroke lands -------------------------------------------------------------------------------
# ---- the paint layer --------------------------------------------------------------------------------------
# ---- live: a stroke's rectangle into the drawn field ------------------------------------------------


# ---- operators ---------------------------------------------------------------------------------------------


class NUBIS_OT_paint_field(NeedsCloudscape, bpy.types.Operator):
    """Paint the data field from above, from a drag or a script's stroke (bl_description says how)."""

    bl_idname = PAINT_OPERATOR
    bl_label = "Paint Sky"
    bl_description = (
        f"Paint the data field from above: drag over the clouds ({MODIFIER_DRAGS}). From a script, give "
        "`stroke` as Blender's paint operators take it (world locations, pressure, is_start)"
    )
    bl_options = {"REGISTER", "UNDO"}

    channel: EnumProperty(name="Channel", items=_CHANNELS, default="COVERAGE")
    radius: FloatProperty(
        name="Radius",
        description="The brush's radius on the cloud layer",
        default=2500.0,
        min=0.0,
        soft_min=100.0,
        soft_max=50000.0,
        subtype="DISTANCE",
        unit="LENGTH",
    )
    strength: FloatProperty(
        name="Strength",
        description="How far one stroke moves the channel (1: all the way)",
        default=1.0,
        min=0.0,
        max=1.0,
    )
    falloff: EnumProperty(name="Falloff", items=_FALLOFFS, default="SMOOTH")
    mode: EnumProperty(name="Mode", items=_MODES, default="ADD")
    layer: StringProperty(name="Layer", description="The paint layer to paint into (empty: the channel's own)")
    stroke: CollectionProperty(type=bpy.types.OperatorStrokeElement, options={"SKIP_SAVE"})

    def _checked(self, context):
        settings = context.scene.nubis
        paintstroke.check_channel(context.scene, self.channel)
        grid = paint.Grid.of(sceneparams.params_from_scene(settings))
        paint.check_brush(grid, self.radius, self.strength)
        return grid

    def execute(self, context):
        scene = context.scene
        try:
            paint.check_stroke_length(len(self.stroke))
            grid = self._checked(context)
            points = []
            for n, el in enumerate(self.stroke):
                x, y = float(el.location[0]), float(el.location[1])
                points.append((x, y, float(el.pressure), bool(el.is_start) or n == 0))
            paint.check_points(grid, points)
            brush = paintstroke.brush_mode(self.mode)
            strength = brush.sign * self.strength
            dabs = paint.stroke_dabs(points, self.radius, strength, self.falloff.lower(), brush.dab_mode, grid=grid)
            owner = ui.active_cloud_layer(scene)
            layer = paintstroke.paint_layer(owner, self.channel, self.layer)
            line = paintstroke.composite_notice(owner, layer, dabs, grid)
            paintstroke.append_dabs(layer, dabs)
            if line:  # the console has it now, from core/paint.py's raster; the Info log gets it here
                self.report({"INFO"}, line)
            datafield.generate_fields(scene)
        except NubisError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        viewport.invalidate()
        ui.redraw_views()
        return {"FINISHED"}

    def invoke(self, context, event):
        if len(self.stroke) or context.area is None or context.area.type != "VIEW_3D":
            return self.execute(context)
        scene = context.scene
        mode = paintstroke.mode_of_event(event, self.mode)
        self.mode = mode
        try:
            self._checked(context)
            brush = (self.radius, self.strength, self.falloff, mode)
            self._owner, self._layer_name, self._live = paintstroke.begin_stroke(scene, self.channel, self.layer, brush)
            self._first = True
            self._sample(context, event)
        except NubisError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        context.window_manager.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def _sample(self, context, event) -> None:
        mouse = (event.mouse_region_x, event.mouse_region_y)
        point = paintstroke.hit(context, mouse)
        _cursor.clear()
        if point is None:
            return
        _cursor.update(centre=tuple(point), radius=self.radius)
        pressure = event.pressure if getattr(event, "is_tablet", False) else 1.0
        self._live.add(point.x, point.y, pressure, self._first)
        el = self.stroke.add()
        el.location = point
        el.mouse = mouse
        el.pressure = pressure
        el.is_start = self._first
        el.time = time.monotonic()
        self._first = False

    def modal(self, context, event):
        if event.type in {"MOUSEMOVE", "INBETWEEN_MOUSEMOVE"}:
            try:
                self._sample(context, event)
            except NubisError as err:  # the layer is full (core/paint.py: check_room): the stroke is dropped
                self.report({"ERROR"}, str(err))
                return self._cancel(context)
            return {"RUNNING_MODAL"}
        if event.type == "LEFTMOUSE" and event.value == "RELEASE":
            return self._finish(context)
        if event.type in {"ESC", "RIGHTMOUSE"}:
            return self._cancel(context)
        return {"RUNNING_MODAL"}

    def _cancel(self, context):
        """Drop the drag: the field is composited again without it."""
        self._live = None
        viewport.invalidate()
        events.request_composite(context.scene)
        ui.redraw_views()
        return {"CANCELLED"}

    def _finish(self, context):
        scene = context.scene
        s = scene.nubis
        owner = s.cloud_layers[self._owner] if 0 <= self._owner < len(s.cloud_layers) else s
        layer = owner.layers.get(self._layer_name)
        if layer is None or not self._live.dabs:
            self._live = None
            if not len(self.stroke):
                self.report({"WARNING"}, "the stroke missed the cloud layer: paint over the clouds (a top view helps)")
            return {"CANCELLED"}
        try:
            self._live.commit(layer)
        except NubisError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        self._live = None
        # The whole field after the usual pause (renders, saves and bakes composite first if it is owed).
        events.request_composite(scene)
        return {"FINISHED"}


class NUBIS_OT_paint_cursor(bpy.types.Operator):
    """Follow the mouse with the brush circle (the Paint Sky tool's mouse move)"""

    bl_idname = "nubis.paint_cursor"
    bl_label = "Paint Sky Cursor"
    bl_options = {"INTERNAL"}

    def invoke(self, context, event):
        _cursor.clear()
        if ui.has_cloudscape(context.scene):
            point = paintstroke.hit(context, (event.mouse_region_x, event.mouse_region_y))
            props = tool_settings(context)
            if point is not None and props is not None:
                _cursor.update(centre=tuple(point), radius=props.radius)
        if context.area is not None:
            context.area.tag_redraw()
        return {"PASS_THROUGH"}


class NUBIS_OT_view_field_top(NeedsCloudscape, bpy.types.Operator):
    """Look straight down on the data field, all of it in view (orthographic): the best view to paint from"""

    bl_idname = "nubis.view_field_top"
    bl_label = "Top View of the Clouds"

    @classmethod
    def poll(cls, context):
        return super().poll(context) and context.area is not None and context.area.type == "VIEW_3D"

    def execute(self, context):
        s = context.scene.nubis
        space, rv3d = context.space_data, context.region_data
        prefs = context.preferences.view
        smooth, prefs.smooth_view = prefs.smooth_view, 0  # no transition that would undo what follows
        try:
            bpy.ops.view3d.view_axis(type="TOP")  # Blender's own Top view: the header says so
        finally:
            prefs.smooth_view = smooth
        rv3d.view_perspective = "ORTHO"
        rv3d.view_location = (s.field_origin_x, s.field_origin_y, paintstroke.brush_altitude(s))
        rv3d.view_distance = s.field_size * 0.75
        # The orthographic view clips around its location: keep the whole sky and the ground inside.
        space.clip_end = max(space.clip_end, 4.0 * (s.layer_top + s.field_size))
        return {"FINISHED"}


class NUBIS_OT_paint_layer_clear(NeedsCloudscape, bpy.types.Operator):
    """Remove every stroke of the active paint layer"""

    bl_idname = "nubis.paint_layer_clear"
    bl_label = "Clear Strokes"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        s = ui.active_cloud_layer(context.scene)
        if not (0 <= s.active_layer < len(s.layers)) or s.layers[s.active_layer].kind != "PAINT":
            self.report({"ERROR"}, "the active layer is not a paint layer: select one in the Data Field's stack")
            return {"CANCELLED"}
        s.layers[s.active_layer].dabs.clear()
        try:
            datafield.generate_fields(context.scene)
        except NubisError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        viewport.invalidate()
        ui.redraw_views()
        return {"FINISHED"}


# ---- the tool, its circle and its panel ---------------------------------------------------------------


def tool_settings(context):
    """The Paint Sky tool's operator settings (radius, strength, ...), or None without a workspace."""
    workspace = getattr(context, "workspace", None)
    if workspace is None:
        return None
    try:
        tool = workspace.tools.from_space_view3d_mode("OBJECT", create=False)  # no ID writes while drawing
        if tool.idname != TOOL_ID:
            tool = None
        return tool.operator_properties(PAINT_OPERATOR) if tool is not None else None
    except (AttributeError, RuntimeError, TypeError):
        return None


class NubisPaintSkyTool(bpy.types.WorkSpaceTool):
    bl_space_type = "VIEW_3D"
    bl_context_mode = "OBJECT"
    bl_idname = TOOL_ID
    bl_label = "Paint Sky"
    bl_description = f"Paint where the clouds are, from above: {DRAGS}"
    bl_icon = "ops.generic.select_circle"
    bl_keymap = (
        (PAINT_OPERATOR, {"type": "LEFTMOUSE", "value": "PRESS", "any": True}, None),
        ("nubis.paint_cursor", {"type": "MOUSEMOVE", "value": "ANY", "any": True}, None),
    )

    def draw_settings(context, layout, tool):
        props = tool.operator_properties(PAINT_OPERATOR)
        for key in BRUSH_KEYS:
            layout.prop(props, key)


def _circle_points(centre, radius: float, n: int = 64):
    cx, cy, cz = centre
    return [
        (cx + radius * math.cos(2 * math.pi * k / n), cy + radius * math.sin(2 * math.pi * k / n), cz)
        for k in range(n + 1)
    ]


def _draw_cursor() -> None:
    """The brush circle on the cloud layer, drawn over the clouds (after the view's own drawing: the clouds
    and the sky in Solid shading cover anything drawn in the view before them)."""
    if not _cursor:
        return
    context = bpy.context
    region, rv3d = context.region, context.region_data
    if region is None or rv3d is None or tool_settings(context) is None:
        return
    points = []
    for p in _circle_points(_cursor["centre"], _cursor["radius"]):
        q = view3d_utils.location_3d_to_region_2d(region, rv3d, p)
        if q is None:
            return
        points.append((q.x, q.y))
    shader = gpu.shader.from_builtin("UNIFORM_COLOR")
    batch = batch_for_shader(shader, "LINE_STRIP", {"pos": points})
    gpu.state.blend_set("ALPHA")
    shader.bind()
    shader.uniform_float("color", (1.0, 0.55, 0.1, 0.9))
    batch.draw(shader)
    gpu.state.blend_set("NONE")


class NUBIS_PT_paint(SidebarPanel, bpy.types.Panel):
    """The sidebar's painting tools: the Paint Sky tool, its brush and the top view."""

    bl_label = "Paint Sky"

    def draw(self, context):
        layout = self.layout
        row = layout.row(align=True)
        row.operator("wm.tool_set_by_id", text="Paint Sky", icon="BRUSH_DATA").name = TOOL_ID
        row.operator("nubis.view_field_top", text="Top View", icon="VIEW_ORTHO")
        props = tool_settings(context)
        if props is not None:
            col = layout.column()
            col.use_property_split = True
            for key in BRUSH_KEYS:
                col.prop(props, key)
            layout.label(text=DRAG_HINT, icon="INFO")
        s = context.scene.nubis
        owner = ui.active_cloud_layer(context.scene)
        if s.cloud_layers:  # a layered sky: strokes go into the layer chosen in the Cloud Layers list
            name = s.first_layer_name if ui.first_layer_chosen(context.scene) else owner.name
            layout.label(text=f"Paints '{name}'", icon="OUTLINER_DATA_VOLUME")
        painted = [x for x in owner.layers if x.kind == "PAINT"]
        for x in painted:
            layout.label(text=f"{x.name}: {len(x.dabs)} dabs", icon="BRUSH_DATA" if x.enabled else "HIDE_ON")


def draw_layer(layout, layer) -> None:
    """A paint layer's own rows in the Data Field panel."""
    layout.label(text=f"{len(layer.dabs)} dabs (strokes are kept in the file)", icon="BRUSH_DATA")
    layout.operator("nubis.paint_layer_clear", icon="TRASH")


_CLASSES = (
    NUBIS_OT_paint_field,
    NUBIS_OT_paint_cursor,
    NUBIS_OT_view_field_top,
    NUBIS_OT_paint_layer_clear,
    NUBIS_PT_paint,
)
_handle: list = []
_tool: list = []


def register() -> None:
    for cls in _CLASSES:
        bpy.utils.register_class(cls)
    _handle.append(bpy.types.SpaceView3D.draw_handler_add(_draw_cursor, (), "WINDOW", "POST_PIXEL"))
    try:
        bpy.utils.register_tool(NubisPaintSkyTool, separator=True)
        _tool.append(NubisPaintSkyTool)
    except (ValueError, RuntimeError, KeyError) as err:  # a toolbar Blender cannot extend here
        print(f"Nubis: the Paint Sky tool is not in the toolbar ({err}); nubis.paint_field still paints")


def unregister() -> None:
    while _tool:
        bpy.utils.unregister_tool(_tool.pop())
    while _handle:
        bpy.types.SpaceView3D.draw_handler_remove(_handle.pop(), "WINDOW")
    for cls in reversed(_CLASSES):
        bpy.utils.unregister_class(cls)
    _cursor.clear()
