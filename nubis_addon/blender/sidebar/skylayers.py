"""A layered sky in the sidebar (docs/layers.md): the Cloud Layers list's operators. The first layer is
the cloudscape's own settings; Add makes a further layer at free altitudes above the others, with a copy
of the chosen layer's settings and field stack; Remove and the arrows act on the further layers."""

from __future__ import annotations

import bpy
from bpy.props import EnumProperty

from ...core import cloudlayers
from ..host import ui
from ..scene import datafield, sceneparams
from .operators import NubisOperator


def _ranges(settings) -> list[tuple[float, float]]:
    first = [(settings.layer_bottom, settings.layer_top)]
    return first + [(c.layer_bottom, c.layer_top) for c in settings.cloud_layers]


def _no_further(settings, doing: str) -> str:
    """Why no further layer is chosen to `doing`, or ""."""
    if not settings.cloud_layers:
        return f"there is no further cloud layer to {doing}: add one with + first"
    if not 0 <= settings.active_further_layer < len(settings.cloud_layers):
        return f"the first cloud layer is the cloudscape's own and cannot {doing}: choose a further one"
    return ""


class ActsOnFurtherLayer(ui.NeedsCloudscape):
    """Grey, and says why, while no further cloud layer is chosen."""

    doing = "act"

    @classmethod
    def unavailable(cls, scene) -> str:
        return _no_further(scene.nubis, cls.doing)


class NUBIS_OT_cloud_layer_add(ui.NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Add a cloud layer above the others, a copy of the chosen layer's settings and field"""

    bl_idname = "nubis.cloud_layer_add"
    bl_label = "Add Cloud Layer"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def unavailable(cls, scene) -> str:
        if len(scene.nubis.cloud_layers) + 1 >= cloudlayers.MAX_CLOUD_LAYERS:
            return f"a sky holds at most {cloudlayers.MAX_CLOUD_LAYERS} cloud layers: remove one before adding another"
        return ""

    def run(self, context):
        self.refuse_if_unavailable(context.scene)
        scene = context.scene
        s = scene.nubis
        count = len(s.cloud_layers) + 1
        source = ui.active_cloud_layer(scene)
        first = ui.first_layer_chosen(scene)
        base = sceneparams.params_from_scene(s) if first else datafield.cloud_layer_params(s, source)
        own = cloudlayers.new_layer_params(base, _ranges(s))
        stack = [datafield.layer_to_dict(layer) for layer in source.layers]
        taken = {c.name for c in s.cloud_layers} | {s.first_layer_name}
        number = count + 1
        while f"Layer {number}" in taken:  # names key each layer's field images and state
            number += 1
        data = cloudlayers.CloudLayer(f"Layer {number}", own, stack)
        with sceneparams.batch_edit():
            cloud = datafield.add_cloud_layer(s, data)
            for copy, original in zip(cloud.layers, source.layers, strict=True):
                datafield.copy_dabs(original, copy)
        s.active_further_layer = len(s.cloud_layers) - 1
        datafield.generate_fields(scene)
        return f"added cloud layer '{cloud.name}' at {cloud.layer_bottom:.0f}-{cloud.layer_top:.0f} m"


class NUBIS_OT_cloud_layer_remove(ActsOnFurtherLayer, NubisOperator, bpy.types.Operator):
    """Remove the chosen cloud layer (the first is the cloudscape's own: switch it off instead)"""

    bl_idname = "nubis.cloud_layer_remove"
    bl_label = "Remove Cloud Layer"
    bl_options = {"REGISTER", "UNDO"}
    doing = "be removed"

    def run(self, context):
        self.refuse_if_unavailable(context.scene)
        s = context.scene.nubis
        index = s.active_further_layer
        s.cloud_layers.remove(index)
        s.active_further_layer = min(index, len(s.cloud_layers) - 1)
        return None


class NUBIS_OT_cloud_layer_move(ActsOnFurtherLayer, NubisOperator, bpy.types.Operator):
    """Move the chosen cloud layer up or down the list (the first stays first)"""

    bl_idname = "nubis.cloud_layer_move"
    bl_label = "Move Cloud Layer"
    bl_options = {"REGISTER", "UNDO"}
    doing = "move"

    direction: EnumProperty(items=(("UP", "Up", ""), ("DOWN", "Down", "")))

    def run(self, context):
        self.refuse_if_unavailable(context.scene)
        s = context.scene.nubis
        index = s.active_further_layer
        target = index + (-1 if self.direction == "UP" else 1)
        if 0 <= target < len(s.cloud_layers):
            s.cloud_layers.move(index, target)
            s.active_further_layer = target
        return None


class NUBIS_OT_cloud_layer_first(ui.NeedsCloudscape, NubisOperator, bpy.types.Operator):
    """Let the panels below act on the first cloud layer (the cloudscape's own settings)"""

    bl_idname = "nubis.cloud_layer_first"
    bl_label = "Choose the First Cloud Layer"
    bl_options = {"REGISTER", "UNDO"}

    def run(self, context):
        context.scene.nubis.active_further_layer = ui.FIRST_LAYER
        return None


CLASSES = (NUBIS_OT_cloud_layer_add, NUBIS_OT_cloud_layer_remove, NUBIS_OT_cloud_layer_move, NUBIS_OT_cloud_layer_first)

register, unregister = bpy.utils.register_classes_factory(CLASSES)
