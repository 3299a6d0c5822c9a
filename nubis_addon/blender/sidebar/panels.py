"""The sidebar (N panel) of the 3D viewport, tab 'Nubis', generated from the settings schema
(core/schema.py): each sub-panel draws the settings the schema assigns to it, in the schema's order,
plus the lists and buttons that belong there."""

from __future__ import annotations

import bpy

from ...core import quality, schema
from ...core.errors import NubisError
from ..host import presetlist, runtime, status, ui
from ..jobs import pipeline
from ..live import viewport
from . import paint


def draw_settings(layout, owner, settings, layer_owner=None) -> None:
    """The schema's settings of one panel, in its order, as Blender's property-split columns; a cloud
    layer's own settings (schema.CLOUD_LAYER_KEYS) from `layer_owner` when given (ui.active_cloud_layer)."""
    layout.use_property_split = True
    layout.use_property_decorate = True
    col = layout.column()
    for s in settings:
        col.prop(layer_owner if layer_owner is not None and s.key in _LAYER_KEYS else owner, s.key)


_LAYER_KEYS = frozenset(schema.CLOUD_LAYER_KEYS)


def panel_settings(panel: str, group=schema.SCENE) -> tuple[schema.Setting, ...]:
    return tuple(s for s in group if s.panel == panel)


class NUBIS_MT_presets(bpy.types.Menu):
    """The presets shipped with Nubis, then the user's own (saved with the + beside the menu)"""

    bl_label = "Presets"

    def draw(self, _context):
        layout = self.layout
        try:
            entries = presetlist.preset_entries()
        except NubisError as err:
            layout.label(text=str(err), icon="ERROR")
            return
        shipped = [e for e in entries if not e.user]
        mine = [e for e in entries if e.user]
        for entry in shipped:
            layout.operator("nubis.preset_load", text=entry.name).filepath = str(entry.path)
        layout.separator()
        if not mine:
            layout.label(text="Save your own presets with +")
        for entry in mine:
            layout.operator("nubis.preset_load", text=entry.name, icon="USER").filepath = str(entry.path)


def draw_preset_row(layout, context) -> None:
    """Blender's preset row: the menu, showing the active preset, with Add (+) and Remove (-) beside it."""
    try:
        entry = presetlist.active_preset(context) if ui.has_cloudscape(context.scene) else None
    except NubisError as err:  # the user's preset folder cannot be made
        layout.label(text=str(err), icon="ERROR")
        return
    row = layout.row(align=True)
    row.menu("NUBIS_MT_presets", text=entry.name if entry else "Presets", icon="PRESET")
    row.operator("nubis.preset_add", text="", icon="ADD")
    row.operator("nubis.preset_remove", text="", icon="REMOVE")


class NUBIS_PT_main(bpy.types.Panel):
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Nubis"
    bl_label = "Nubis Clouds"

    def draw(self, context):
        layout = self.layout
        layout.operator_menu_enum("nubis.new_cloudscape", "preset", text="New Cloudscape", icon="OUTLINER_DATA_VOLUME")
        draw_preset_row(layout, context)
        if not ui.has_cloudscape(context.scene):
            layout.label(text="No cloudscape in this scene yet")
            return
        row = layout.row(align=True)
        row.prop(context.scene.nubis, "enabled")
        shown = viewport.view_toggle(context)
        row.operator("nubis.view_toggle", text="", icon="HIDE_OFF" if shown else "HIDE_ON", depress=shown)
        generating = runtime.noise_generating()
        if generating is not None:
            layout.label(text=f"Generating noise for seed {generating}...", icon="TIME")
        if status.last_error():
            layout.label(text=status.last_error(), icon="ERROR")
        layout.operator("nubis.render_image", icon="RENDER_STILL")


class NubisPanel(ui.SidebarPanel):
    """A sidebar panel drawing one panel of the settings schema (`panel`)."""

    panel = ""

    def draw(self, context):
        self.draw_before(context)
        shown = tuple(s for s in panel_settings(self.panel) if s.key != "enabled")
        if shown:
            draw_settings(self.layout, context.scene.nubis, shown, ui.active_cloud_layer(context.scene))
        self.draw_after(context)

    def draw_before(self, context) -> None:
        pass

    def draw_after(self, context) -> None:
        pass


_KIND_ICONS = {
    "PERLIN": "FORCE_TURBULENCE",
    "WORLEY": "MOD_OCEAN",
    "PERLIN_WORLEY": "OUTLINER_DATA_VOLUME",
    "GRADIENT": "IPO_LINEAR",
    "CONSTANT": "SNAP_FACE",
    "IMAGE": "IMAGE_DATA",
    "PAINT": "BRUSH_DATA",
}


class NUBIS_UL_layers(bpy.types.UIList):
    """The layer stack: an enable checkbox, the kind's icon, the name and the channel written."""

    def draw_item(self, _context, layout, _data, item, _icon, _active_data, _active_prop, _index=0):
        row = layout.row(align=True)
        row.prop(item, "enabled", text="")
        row.label(text="", icon=_KIND_ICONS.get(item.kind, "DOT"))
        row.prop(item, "name", text="", emboss=False)
        sub = row.row()
        sub.active = item.enabled
        sub.label(text=item.channel.replace("_", " ").title())


_LAYER_KEYS_BY_KIND = {
    "PERLIN": ("scale", "seed", "octaves"),
    "WORLEY": ("scale", "seed", "octaves"),
    "PERLIN_WORLEY": ("scale", "seed", "octaves"),
    "GRADIENT": ("gradient", "angle", "center", "radius"),
    "CONSTANT": ("value",),
    "IMAGE": (),
    "PAINT": (),
}
_LAYER_COMMON = ("kind", "channel", "blend", "enabled", "opacity")


def _list_with_buttons(layout, template: tuple, rows: int, item: str):
    """A UIList (template_list's arguments) with the add and remove buttons of `item` beside it; returns the
    buttons' column for more."""
    row = layout.row()
    row.template_list(*template, rows=rows)
    col = row.column(align=True)
    col.operator(f"nubis.{item}_add", icon="ADD", text="")
    col.operator(f"nubis.{item}_remove", icon="REMOVE", text="")
    return col


def _cloud_layer_row(row, owner, first: bool) -> None:
    """One cloud layer's enable box, name, altitudes and solo toggle."""
    prefix = "first_layer_" if first else ""
    row.prop(owner, f"{prefix}enabled", text="")
    row.prop(owner, f"{prefix}name", text="", emboss=False)
    sub = row.row()
    sub.active = getattr(owner, f"{prefix}enabled")
    sub.label(text=f"{owner.layer_bottom / 1000:.1f}-{owner.layer_top / 1000:.1f} km")
    solo = getattr(owner, f"{prefix}solo")
    row.prop(owner, f"{prefix}solo", text="", icon="SOLO_ON" if solo else "SOLO_OFF", emboss=False)


class NUBIS_UL_cloud_layers(bpy.types.UIList):
    """A layered sky's further layers (docs/layers.md): enable, name, altitudes, solo."""

    def draw_item(self, _context, layout, _data, item, _icon, _active_data, _active_prop, _index=0):
        _cloud_layer_row(layout.row(align=True), item, first=False)


class NUBIS_PT_cloud_layers(ui.SidebarPanel, bpy.types.Panel):
    """The sky's cloud layers: the panels below act on the one chosen here."""

    bl_label = "Cloud Layers"

    def draw(self, context):
        layout = self.layout
        s = context.scene.nubis
        # The first layer is the scene's own settings: its row stands above the list of further layers.
        box = layout.box().row(align=True)
        chosen = ui.first_layer_chosen(context.scene)
        box.operator("nubis.cloud_layer_first", text="", icon="RADIOBUT_ON" if chosen else "RADIOBUT_OFF")
        _cloud_layer_row(box, s, first=True)
        col = _list_with_buttons(
            layout, ("NUBIS_UL_cloud_layers", "", s, "cloud_layers", s, "active_further_layer"), 2, "cloud_layer"
        )
        col.operator("nubis.cloud_layer_move", icon="TRIA_UP", text="").direction = "UP"
        col.operator("nubis.cloud_layer_move", icon="TRIA_DOWN", text="").direction = "DOWN"


class _FieldDrawing:
    def draw_after(self, context):
        layout = self.layout
        layout.use_property_split = False
        s = ui.active_cloud_layer(context.scene)
        col = _list_with_buttons(layout, ("NUBIS_UL_layers", "", s, "layers", s, "active_layer"), 4, "layer")
        col.operator("nubis.layer_duplicate", icon="DUPLICATE", text="")
        col.operator("nubis.layer_move", icon="TRIA_UP", text="").direction = "UP"
        col.operator("nubis.layer_move", icon="TRIA_DOWN", text="").direction = "DOWN"
        if s.layers and 0 <= s.active_layer < len(s.layers):
            layer = s.layers[s.active_layer]
            box = layout.box()
            box.use_property_split = True
            if layer.kind == "PAINT":  # strokes on top of the field: no blend, mask or remap
                for key in ("kind", "channel", "enabled", "opacity"):
                    box.prop(layer, key)
                paint.draw_layer(box, layer)
                layout.operator("nubis.generate_field", icon="FILE_REFRESH")
                return
            for key in _LAYER_COMMON:
                box.prop(layer, key)
            # The mask is chosen from the layers above this one (the loader refuses any other).
            box.prop_search(layer, "mask", s, "layers", icon="MOD_MASK")
            sub = box.row()
            sub.active = bool(layer.mask)
            sub.prop(layer, "invert_mask")
            for key in _LAYER_KEYS_BY_KIND[layer.kind]:
                box.prop(layer, key)
            if layer.kind == "IMAGE":
                box.template_ID(layer, "image", open="image.open")
            box.prop(layer, "remap")
        layout.operator("nubis.generate_field", icon="FILE_REFRESH")


class _LightingDrawing:
    def draw(self, context):
        s = context.scene.nubis
        layout = self.layout
        layout.use_property_split = True
        col = layout.column()
        for setting in panel_settings("lighting"):
            row = col.row()
            if setting.key == "ambient_color":
                row.active = s.ambient_source == "COLOR"
            elif setting.key == "lighting_droplet_size":
                row.active = s.lighting_cycles_mie
            row.prop(s, setting.key)
        col.prop(context.scene.cycles, "volume_bounces", text="Bounces")  # Cycles' own tooltip


class _StormsDrawing:
    def draw_before(self, context):
        layout = self.layout
        s = context.scene.nubis
        _list_with_buttons(layout, ("UI_UL_list", "nubis_storms", s, "storms", s, "active_storm"), 2, "storm")
        if s.storms and 0 <= s.active_storm < len(s.storms):
            storm = s.storms[s.active_storm]
            box = layout.box()
            draw_settings(box, storm, panel_settings("storms", schema.STORM))
            row = layout.row(align=True)
            row.operator("nubis.storm_lifecycle", icon="KEYFRAME")
            row.operator("nubis.lightning_sequence", icon="LIGHT_SUN")


class _ViewportDrawing:
    """The temporal viewport (docs/viewport.md): quality, convergence and the benchmark."""

    def draw_before(self, context):
        s = context.scene.nubis
        params = {k: getattr(s, k) for k in quality.ROW_KEYS.values()}
        try:
            rows = quality.qualities()
        except Exception as err:  # a damaged quality file: say so in place of the menu
            self.layout.label(text=str(err), icon="ERROR")
            return
        current = next((q.label for q in rows.values() if q.matches(params)), "Custom")
        self.layout.operator_menu_enum("nubis.viewport_quality", "quality", text=f"Quality: {current}")

    def draw_after(self, context):
        layout = self.layout
        layout.use_property_split = False
        layout.operator("nubis.benchmark", icon="TIME")
        if status.last_benchmark:
            box = layout.box().column(align=True)
            for name, value in status.last_benchmark:
                row = box.split(factor=0.6)
                row.label(text=name)
                row.label(text=value)


class _BakeDrawing:
    def draw_after(self, context):
        layout = self.layout
        try:
            voxels, nbytes = pipeline.bake_estimate(context.scene)
            col = layout.column(align=True)
            # Short enough for the default sidebar width; the Bake VDB button's tooltip says the rest.
            col.label(text=f"{voxels / 1e6:.1f} M voxels, at most {nbytes / 2**20:.0f} MB", icon="INFO")
        except NubisError as err:  # the bake would be refused: say why before anyone presses the button
            layout.label(text=str(err), icon="ERROR")
        self.layout.operator("nubis.bake_vdb", icon="FILE_VOLUME")
        self.layout.operator("nubis.bake_frames", icon="SEQUENCE")


# Panels open on a new cloudscape; the others start closed.
_OPEN = frozenset({"field", "lighting", "viewport", "bake"})
# What a panel draws beyond its schema panel's settings (NubisPanel.draw calls draw_before and draw_after).
_DRAWINGS = {
    "field": _FieldDrawing,
    "lighting": _LightingDrawing,
    "storms": _StormsDrawing,
    "viewport": _ViewportDrawing,
    "bake": _BakeDrawing,
}


def _panel(panel: str) -> type:
    """The sidebar panel of the schema's panel `panel`: its label from the schema, its settings drawn by
    NubisPanel with the panel's own additions (_DRAWINGS)."""
    namespace = {"bl_label": dict(schema.PANELS)[panel], "panel": panel}
    if panel not in _OPEN:
        namespace["bl_options"] = {"DEFAULT_CLOSED"}
    bases = (_DRAWINGS[panel],) if panel in _DRAWINGS else ()
    return type(f"NUBIS_PT_{panel}", (*bases, NubisPanel, bpy.types.Panel), namespace)


# Sub-panels in the schema's order (the order an artist works in).
PANEL_CLASSES = {p: _panel(p) for p in schema.PANEL_IDS}
CLASSES = (
    NUBIS_UL_layers,
    NUBIS_UL_cloud_layers,
    NUBIS_MT_presets,
    NUBIS_PT_main,
    NUBIS_PT_cloud_layers,
    *PANEL_CLASSES.values(),
)


register, unregister = bpy.utils.register_classes_factory(CLASSES)
