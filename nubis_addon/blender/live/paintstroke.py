"""A stroke of the Paint Sky tool as it is painted: where it lands on the cloud layer, the paint layer it
goes into, the notice before a long composite, and its rectangle of the field patched into the drawn
texture while the drag goes on (render/fieldpatch.py); the tool's operator in blender/sidebar/paint.py
drives it."""

from __future__ import annotations

import math

import numpy as np
from bpy_extras import view3d_utils

from ...core import fieldstats, paint, paintraster
from ...core.errors import NubisError
from ..host import runtime, ui
from ..scene import datafield, sceneparams
from . import viewport

# While a drag goes on, the light volumes (the clouds' shadows) wait this long after the last sample:
# refilling them costs a whole-sky pass per sample (docs/measurements.md#painting).
LIGHT_HOLD_S = 0.4


def brush_altitude(settings) -> float:
    """The cloud layer's base: a stroke lands where the view ray meets it (the field itself is flat)."""
    return float(settings.layer_bottom)


def hit(context, mouse: tuple[float, float]):
    """The world point under the mouse on the cloud layer's base, or None when the ray misses it."""
    region, rv3d = context.region, context.region_data
    if region is None or rv3d is None:
        return None
    origin = view3d_utils.region_2d_to_origin_3d(region, rv3d, mouse)
    direction = view3d_utils.region_2d_to_vector_3d(region, rv3d, mouse)
    z = brush_altitude(ui.active_cloud_layer(context.scene))
    if abs(direction.z) < 1e-9:
        return None
    t = (z - origin.z) / direction.z
    if t < 0 and rv3d.is_perspective:
        return None
    return origin + direction * t


def paint_layer(settings, channel: str, name: str = ""):
    """The paint layer a stroke goes into: the named one (made if missing), else the active layer when it
    paints this channel, else the last paint layer of this channel, else a new one at the bottom."""
    channel = channel.upper()
    if name:
        layer = settings.layers.get(name)
        if layer is not None and layer.kind != "PAINT":
            raise NubisError(f"the layer '{name}' is a {layer.kind.lower()} layer, not a paint layer: name another")
        if layer is not None and layer.channel != channel:
            raise NubisError(
                f"the paint layer '{name}' paints {layer.channel.lower()}, not {channel.lower()}: "
                "choose its channel or another layer"
            )
    else:
        layer = None
        active = settings.layers[settings.active_layer] if 0 <= settings.active_layer < len(settings.layers) else None
        if active is not None and active.kind == "PAINT" and active.channel == channel:
            layer = active
        else:
            layer = next((x for x in reversed(settings.layers) if x.kind == "PAINT" and x.channel == channel), None)
    if layer is None:
        with sceneparams.batch_edit():
            layer = settings.layers.add()
            layer.name = name or f"Paint {channel.replace('_', ' ').title()}"
            layer.kind = "PAINT"
            layer.channel = channel
            layer.blend = "ADD"
        settings.active_layer = len(settings.layers) - 1
    return layer


def append_dabs(layer, dabs: np.ndarray) -> None:
    paint.check_room(len(layer.dabs), len(dabs), layer.name)
    datafield.add_dabs(layer, dabs)


def composite_notice(owner, layer, dabs: np.ndarray, grid: paint.Grid) -> str | None:
    """Before a stroke's dabs go into `layer` of `owner`'s stack (a cloud layer's: ui.active_cloud_layer):
    refuse a composite that would hold too much memory, and the line announcing a long one (core/paint.py:
    composite_cost), or None."""
    todo = []
    for other in owner.layers:
        if other.kind != "PAINT" or not other.enabled or (other != layer and not len(other.dabs)):
            continue
        held = datafield.paint_dabs(other)
        todo.append((datafield.raster_key(other), np.vstack([held, dabs]) if other == layer else held))
    cost = paintraster.composite_cost(todo, grid)
    paintraster.check_cost(cost)
    return paintraster.notice(cost)


def check_channel(scene, channel: str) -> None:
    if channel == "STORM" and not len(scene.nubis.storms):
        raise NubisError(
            "storm coverage is drawn only inside a superstorm and this scene has none: add one "
            "(Nubis > Superstorms > Add), then paint its coverage"
        )


def brush_mode(mode: str) -> paint.BrushMode:
    """The brush mode an operator's Mode ("ADD", "SUBTRACT", "SMOOTH") names."""
    return paint.BRUSH_MODE[mode.lower()]


def mode_of_event(event, mode: str) -> str:
    """The Mode a drag paints in: the first brush mode whose modifier key the event holds, else `mode`."""
    held = next((m for m in paint.BRUSH_MODES if m.key and getattr(event, m.key)), None)
    return held.name.upper() if held is not None else mode


class LiveStroke:
    """One drag: dabs are rasterized as they come, the field's rectangle under them re-composited and
    written into the viewport's field arrays and GPU texture in place. On a further cloud layer (`live`
    False) the dabs are laid as they come and the layer is composited when the drag ends: painting in
    place is the first layer's (docs/layers.md)."""

    def __init__(self, scene, layer, radius: float, strength: float, falloff: str, mode: str, live: bool = True):
        self.scene = scene
        self.live = live
        settings = scene.nubis
        brush = brush_mode(mode)
        self.grid = paint.Grid.of(sceneparams.params_from_scene(settings))
        self.spacer = paint.Spacer(radius, brush.sign * strength, falloff.lower(), brush.dab_mode, grid=self.grid)
        self.layer_name = layer.name
        self.held = len(layer.dabs)
        self.dabs: list[np.ndarray] = []
        self.laid = 0
        self.hold_light = True  # False refills the shadows at every sample (the benchmark's comparison)
        if live:
            self._start_live(layer)

    def _start_live(self, layer) -> None:
        """The rasters and planes a live drag re-composites its rectangles from."""
        scene, settings = self.scene, self.scene.nubis
        self.layer_key = datafield.raster_key(layer)
        if sceneparams.field_stale(scene) or datafield.pre_paint(scene) is None:
            datafield.generate_fields(scene)
        self.pre, self.multiplier = datafield.pre_paint(scene)
        self.channel = layer.channel.lower()
        self.image, self.plane = paint.PAINT_CHANNELS[self.channel]
        self.which = tuple(datafield.FIELD_IMAGES).index(self.image)  # the viewport's arrays are in this order
        # The layer's raster as it stands, copied: a cancelled drag leaves the cached one untouched.
        base = paintraster.raster(self.layer_key, datafield.paint_dabs(layer), self.grid)
        self.raster = paintraster.Raster(self.grid)
        self.raster.values = base.values.copy()
        self.raster.count = base.count
        self.layers = []
        for other in settings.layers:
            if other.kind != "PAINT" or not other.enabled or (other != layer and not len(other.dabs)):
                continue
            values = (
                self.raster.values
                if other == layer
                else paintraster.raster(datafield.raster_key(other), datafield.paint_dabs(other), self.grid).values
            )
            self.layers.append(paintraster.PaintLayer(other.channel.lower(), float(other.opacity), values))

    def add(self, x: float, y: float, pressure: float, start: bool) -> tuple | None:
        """Dab along the stroke to (x, y); returns the field rectangle changed. The stretch is clipped to the
        field and its dabs counted before they are laid: past the layer's MAX_DABS the stroke is refused."""
        if not all(math.isfinite(v) and abs(v) < paint.NUMBER_MAX for v in (x, y, pressure)):
            return None  # a view ray the float range cannot place: no sample
        run = self.spacer.advance(x, y, pressure, start)
        paint.check_room(self.held + self.laid, run[-1] if run is not None else 0, self.layer_name)
        rows = self.spacer.lay(run)
        if len(rows):
            self.dabs.append(rows)
            self.laid += len(rows)
        if not self.live:
            return None
        rect = None
        for row in rows:
            rect = paint.union(rect, self.raster.add(row))
        if rect is not None:
            self.show(rect)
        return rect

    def show(self, rect) -> None:
        """Re-composite `rect` into the viewport's field arrays and, when it has uploaded them, its texture
        (otherwise its next redraw uploads them whole, this rectangle included)."""
        arrays = viewport.field_arrays(self.scene)
        plane = paintraster.paint_plane(self.channel, self.pre[self.channel], self.layers, self.multiplier, rect)
        r0, r1, c0, c1 = rect
        arrays[self.which][r0:r1, c0:c1, self.plane] = plane
        fieldstats.edited(arrays[self.which])
        clouds = runtime.loaded_gpu(self.scene.nubis.noise_seed)
        if clouds is not None:
            clouds.patch_field(arrays, self.which, rect)
            if self.hold_light:
                clouds.hold_light(LIGHT_HOLD_S)
        ui.redraw_views()

    def commit(self, layer) -> int:
        """The stroke's dabs into the layer (the undo step's data); the raster is kept as the layer's."""
        dabs = np.concatenate(self.dabs) if self.dabs else paint.as_dabs([])
        append_dabs(layer, dabs)
        if self.live:
            paintraster.remember(datafield.raster_key(layer), datafield.paint_dabs(layer), self.raster)
        return len(dabs)


def begin_stroke(scene, channel: str, name: str, brush: tuple) -> tuple[int, str, LiveStroke]:
    """A drag's start on the cloud layer chosen in the Cloud Layers list: (that layer's index among the
    further layers, ui.FIRST_LAYER for the first; the paint layer's name; the stroke, live on the first layer only).
    `brush` is (radius, strength, falloff, mode)."""
    owner = ui.active_cloud_layer(scene)
    live = ui.first_layer_chosen(scene)
    layer = paint_layer(owner, channel, name)
    stroke = LiveStroke(scene, layer, *brush, live=live)
    return (ui.FIRST_LAYER if live else scene.nubis.active_further_layer), layer.name, stroke
