"""What the interface's pieces share, stated once, low enough that every Blender-side module can use it:
whether a scene holds a cloudscape, the poll that needs one, the sidebar panel's placement, and asking
the views to redraw."""

from __future__ import annotations

import bpy

from ...core.errors import NubisError


def has_cloudscape(scene) -> bool:
    """Whether `scene` holds a Nubis cloudscape (New Cloudscape has made its field images)."""
    settings = getattr(scene, "nubis", None) if scene is not None else None
    return settings is not None and getattr(settings, "field_a", None) is not None


# `scene.nubis.active_further_layer` is the row chosen in the Cloud Layers list of further layers (the
# list Blender's UIList draws needs an index property); FIRST_LAYER there, no row of it: the panels act on
# the first cloud layer, the scene's own settings.
FIRST_LAYER = -1


def active_cloud_layer(scene):
    """What the sidebar's per-layer panels act on (docs/layers.md): the scene's own settings for the first
    cloud layer, or the further layer chosen in the Cloud Layers list. Both hold the layer's settings under
    the same keys (core/schema.py: CLOUD_LAYER_KEYS), its field stack (`layers`) and `active_layer`."""
    settings = scene.nubis
    return settings if first_layer_chosen(scene) else settings.cloud_layers[settings.active_further_layer]


def first_layer_chosen(scene) -> bool:
    """Whether the sidebar's per-layer panels act on the first cloud layer (not a further one). Asked by
    index: each `scene.nubis` is a new Python object, so `is` cannot tell."""
    settings = scene.nubis
    return not 0 <= settings.active_further_layer < len(settings.cloud_layers)


def redraw_views(area_types: tuple[str, ...] = ("VIEW_3D",)) -> None:
    """Ask every area of these types (the 3D views by default) of every window to redraw."""
    wm = getattr(bpy.context, "window_manager", None)
    for window in wm.windows if wm else ():
        for area in window.screen.areas:
            if area.type in area_types:
                area.tag_redraw()


def property_group_registration(classes: tuple, id_type, attr: str, group):
    """register() and unregister() for `classes` and a pointer to the property group `group` as `attr` of
    every `id_type` (bpy.types.Scene, bpy.types.Volume, ...)."""

    def register() -> None:
        for cls in classes:
            bpy.utils.register_class(cls)
        setattr(id_type, attr, bpy.props.PointerProperty(type=group))

    def unregister() -> None:
        delattr(id_type, attr)
        for cls in reversed(classes):
            bpy.utils.unregister_class(cls)

    return register, unregister


class NeedsCloudscape:
    """An operator's poll: available once the scene has a cloudscape, and says how to make one; an operator
    that also needs something of the scene (a layer to remove, room for one more) says why it is grey
    through `unavailable`, the sentence its run refuses with (`refuse_if_unavailable`), stated once."""

    @classmethod
    def poll(cls, context):
        if not has_cloudscape(context.scene):
            cls.poll_message_set("Create a cloudscape first (Nubis > New Cloudscape)")
            return False
        why = cls.unavailable(context.scene)
        if why:
            cls.poll_message_set(why[:1].upper() + why[1:])
            return False
        return True

    @classmethod
    def unavailable(cls, scene) -> str:
        """Why the operator cannot act on `scene` now ("" when it can): cheap, as every redraw asks."""
        return ""

    def refuse_if_unavailable(self, scene) -> None:
        why = self.unavailable(scene)
        if why:
            raise NubisError(why)


class SidebarPanel:
    """A panel in the 3D view's sidebar, under the Nubis tab's main panel, shown once there is a cloudscape."""

    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Nubis"
    bl_parent_id = "NUBIS_PT_main"

    @classmethod
    def poll(cls, context):
        return has_cloudscape(context.scene)
