"""The sidebar (N panel) of the 3D viewport, tab 'Nubis'."""

from __future__ import annotations

import bpy

from ..core.params import PARAMS
from . import viewport


class NubisPanel:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Nubis"

    @classmethod
    def poll(cls, context):
        return getattr(context.scene, "nubis", None) is not None and context.scene.nubis.field_a is not None


def _draw_section(layout, settings, section: str) -> None:
    col = layout.column(align=True)
    for p in PARAMS:
        if p.section == section:
            col.prop(settings, p.key)


class NUBIS_PT_main(bpy.types.Panel):
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Nubis"
    bl_label = "Nubis Clouds"

    def draw(self, context):
        layout = self.layout
        settings = getattr(context.scene, "nubis", None)
        layout.operator_menu_enum("nubis.new_cloudscape", "preset", text="New Cloudscape", icon="OUTLINER_DATA_VOLUME")
        if settings is None or settings.field_a is None:
            layout.label(text="No cloudscape in this scene yet")
            return
        layout.prop(settings, "enabled")
        if viewport.last_error():
            layout.label(text=viewport.last_error(), icon="ERROR")
        layout.operator("nubis.render_image", icon="RENDER_STILL")


class NUBIS_PT_field(NubisPanel, bpy.types.Panel):
    bl_label = "Data Field"
    bl_parent_id = "NUBIS_PT_main"

    def draw(self, context):
        layout = self.layout
        s = context.scene.nubis
        _draw_section(layout, s, "field")
        row = layout.row()
        row.template_list("UI_UL_list", "nubis_layers", s, "layers", s, "active_layer", rows=4)
        col = row.column(align=True)
        col.operator("nubis.layer_add", icon="ADD", text="")
        col.operator("nubis.layer_remove", icon="REMOVE", text="")
        col.operator("nubis.layer_duplicate", icon="DUPLICATE", text="")
        col.operator("nubis.layer_move", icon="TRIA_UP", text="").direction = "UP"
        col.operator("nubis.layer_move", icon="TRIA_DOWN", text="").direction = "DOWN"
        if s.layers and 0 <= s.active_layer < len(s.layers):
            layer = s.layers[s.active_layer]
            box = layout.box()
            for key in ("kind", "channel", "blend", "enabled", "opacity", "mask", "invert_mask"):
                box.prop(layer, key)
            if layer.kind in {"PERLIN", "WORLEY", "PERLIN_WORLEY"}:
                for key in ("scale", "seed", "octaves"):
                    box.prop(layer, key)
            elif layer.kind == "GRADIENT":
                for key in ("gradient", "angle", "center", "radius"):
                    box.prop(layer, key)
            elif layer.kind == "CONSTANT":
                box.prop(layer, "value")
            elif layer.kind == "IMAGE":
                box.template_ID(layer, "image", open="image.open")
            box.prop(layer, "remap")
        row = layout.row(align=True)
        row.prop(s, "rule_rain", toggle=True)
        row.prop(s, "rule_horizon", toggle=True)
        layout.operator("nubis.generate_field", icon="FILE_REFRESH")


def _section_panel(section: str, label: str):
    def draw(self, context):
        _draw_section(self.layout, context.scene.nubis, section)

    return type(
        f"NUBIS_PT_{section}",
        (NubisPanel, bpy.types.Panel),
        {"bl_label": label, "bl_parent_id": "NUBIS_PT_main", "bl_options": {"DEFAULT_CLOSED"}, "draw": draw},
    )


class NUBIS_PT_light(NubisPanel, bpy.types.Panel):
    bl_label = "Light"
    bl_parent_id = "NUBIS_PT_main"

    def draw(self, context):
        s = context.scene.nubis
        self.layout.label(text="The sun is the scene's first Sun lamp: rotate it to change the time of day")
        self.layout.prop(s, "ambient_source", expand=True)
        if s.ambient_source == "COLOR":
            self.layout.prop(s, "ambient_color")
        self.layout.prop(context.scene.cycles, "volume_bounces", text="Cycles Volume Bounces")


class NUBIS_PT_storms(NubisPanel, bpy.types.Panel):
    bl_label = "Superstorms"
    bl_parent_id = "NUBIS_PT_main"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        s = context.scene.nubis
        row = layout.row()
        row.template_list("UI_UL_list", "nubis_storms", s, "storms", s, "active_storm", rows=2)
        col = row.column(align=True)
        col.operator("nubis.storm_add", icon="ADD", text="")
        col.operator("nubis.storm_remove", icon="REMOVE", text="")
        if s.storms and 0 <= s.active_storm < len(s.storms):
            storm = s.storms[s.active_storm]
            box = layout.box()
            for key in (
                "empty",
                "radius",
                "coverage",
                "blend",
                "height",
                "base",
                "bottom_type",
                "seed",
                "spin",
                "darkening",
                "ambient_boost",
                "glow",
                "glow_color",
                "flash",
                "anvil_offset",
            ):
                box.prop(storm, key)
            layout.operator("nubis.storm_lifecycle", icon="KEYFRAME")
            layout.operator("nubis.lightning_sequence", icon="LIGHT_SUN")
        layout.prop(s, "storm_twist")
        layout.prop(s, "storm_jittered_rings")


class NUBIS_PT_viewport(NubisPanel, bpy.types.Panel):
    """The temporal viewport (docs/viewport.md): quality, convergence and the benchmark."""

    bl_label = "Viewport"
    bl_parent_id = "NUBIS_PT_main"

    def draw(self, context):
        from ..core import quality

        layout = self.layout
        s = context.scene.nubis
        params = {k: getattr(s, k) for k in quality.ROW_KEYS.values()}
        current = next((q.label for q in quality.qualities().values() if q.matches(params)), "Custom")
        layout.operator_menu_enum("nubis.viewport_quality", "quality", text=f"Quality: {current}")
        layout.use_property_split = True
        col = layout.column(align=True)
        col.prop(s, "viewport_samples", text="Samples")
        col.prop(s, "viewport_resolution", text="Resolution")
        col.prop(s, "viewport_blur", text="Upscale Blur")
        col = layout.column(align=True)
        col.prop(s, "march_light_samples", text="Light Samples")
        col.prop(s, "march_mip", text="Noise Mip")
        layout.use_property_split = False
        layout.operator("nubis.benchmark", icon="TIME")
        if viewport.last_benchmark:
            box = layout.box().column(align=True)
            for line in viewport.last_benchmark:
                box.label(text=line)


class NUBIS_PT_bake(NubisPanel, bpy.types.Panel):
    bl_label = "Bake"
    bl_parent_id = "NUBIS_PT_main"

    def draw(self, context):
        self.layout.prop(context.scene.nubis, "bake_voxel_size")
        col = self.layout.column(heading="Options")
        for key in ("bake_camera_only", "bake_half", "bake_velocity"):
            col.prop(context.scene.nubis, key)
        self.layout.operator("nubis.bake_vdb", icon="FILE_VOLUME")
        self.layout.operator("nubis.bake_frames", icon="SEQUENCE")


CLASSES = (
    NUBIS_PT_main,
    NUBIS_PT_field,
    _section_panel("layer", "Layer"),
    _section_panel("noise", "Noise"),
    _section_panel("density", "Density"),
    _section_panel("wind", "Wind"),
    NUBIS_PT_storms,
    NUBIS_PT_light,
    _section_panel("lighting", "Lighting"),
    _section_panel("march", "Ray March"),
    NUBIS_PT_viewport,
    NUBIS_PT_bake,
)


register, unregister = bpy.utils.register_classes_factory(CLASSES)
