"""The scene's settings as plain values, its animation, and what this session remembers of each scene
(SceneState): the lowest floor of the scene's data."""

from __future__ import annotations

import contextlib
import itertools
from dataclasses import dataclass, field

import bpy

from ...core import paintraster, schema


def scene_fps(scene) -> float:
    return scene.render.fps / scene.render.fps_base


_batch = [0]


@contextlib.contextmanager
def batch_edit():
    """Many settings written at once (a preset, a quality level): their update callbacks wait, and the
    writer composites or redraws once at the end."""
    _batch[0] += 1
    try:
        yield
    finally:
        _batch[0] -= 1


def in_batch_edit() -> bool:
    return _batch[0] > 0


def params_from_scene(settings) -> dict:
    """The scene settings a preset holds, as plain values by key."""
    return {s.key: from_blender(s, getattr(settings, s.key)) for s in schema.PRESET_SCENE}


def from_blender(s: schema.Setting, value):
    if s.kind == "image" or s.kind == "object":
        return value.name if value else ""
    if s.kind == "enum":
        return value.lower()
    if s.kind in ("vector", "color"):
        return list(value)
    return value


def table_to_dict(item, settings) -> dict:
    """A layer or storm property group as its preset table."""
    return {s.name: from_blender(s, getattr(item, s.name)) for s in settings if s.in_preset and hasattr(item, s.name)}


@dataclass
class SceneState:
    """What this session remembers of one scene between composites: nothing of it is saved. Kept by the
    scene's pointer, so all of it goes at once on a file load (pointers are reused) and on unregister."""

    stale: bool = False  # the field's inputs changed since its last composite: one is owed
    cover_hist: tuple | None = None  # the last composite's coverage histogram, before the storms
    cover_painted: bool = False  # whether the last composite painted coverage (core/paint.py)
    pre_paint: tuple | None = None  # (the paintable planes before the paint, the slider's multiplier)
    raster_keys: dict = field(default_factory=dict)  # a paint layer's pointer -> its key in core/paint.py
    vortex: dict = field(default_factory=dict)  # an animated storm's vortex times, by F-curve (_vortex_time)
    layer_coverage: dict = field(default_factory=dict)  # a further cloud layer's coverage multiplier, by name
    layer_fields: dict = field(default_factory=dict)  # a further layer's field arrays and what they were read from


_scenes: dict[int, SceneState] = {}


# The keys core/paint.py caches paint layers' rasters under: counted here, never reused, never a pointer.
raster_key_counter = itertools.count(1)


def scene_state(scene) -> SceneState:
    """The scene's SceneState, made on first use."""
    return _scenes.setdefault(scene.as_pointer(), SceneState())


def known_state(scene) -> SceneState:
    """The scene's SceneState, or a fresh one (not kept) when this session has none: reads make none."""
    return _scenes.get(scene.as_pointer()) or SceneState()


def mark_field_stale(scene) -> None:
    """The field's inputs changed: the next read of the field (or the debounced timer) composites."""
    scene_state(scene).stale = True


def field_stale(scene) -> bool:
    return known_state(scene).stale


def stale_scenes() -> list:
    return [scene for scene in bpy.data.scenes if known_state(scene).stale]


def forget_stale() -> None:
    """Forget every scene's SceneState and the paint rasters cached for them: the one place this session's
    per-scene memory ends (blender/live/events.py calls it on file loads, on unregister, and after a failed
    debounced composite)."""
    _scenes.clear()
    paintraster.forget()


# F-curve paths on the scene whose values feed the field: the layers, the storms and the scene settings
# whose change re-composites (schema trigger "field").
_FIELD_PATHS = ("nubis.layers[", "nubis.storms[") + tuple(
    f"nubis.{s.key}" for s in schema.SCENE if s.trigger == "field"
)


def field_animated(settings) -> bool:
    """Whether the field changes from frame to frame: keyed layers, rules, storms or field settings, or
    a storm Empty with an animation of its own."""
    for s in settings.storms:
        if s.empty is not None and s.empty.animation_data and s.empty.animation_data.action:
            return True
    return any(fc.data_path.startswith(_FIELD_PATHS) for fc in fcurves(settings.id_data))


def fcurve_owners(action) -> list:
    """(collection, curve) pairs, for legacy and Blender 5.0 layered actions alike."""
    curves = getattr(action, "fcurves", None)
    if curves is not None:
        return [(curves, c) for c in list(curves)]
    out = []
    for layer in getattr(action, "layers", ()):
        for strip in layer.strips:
            for bag in getattr(strip, "channelbags", ()):
                out.extend((bag.fcurves, c) for c in list(bag.fcurves))
    return out


def fcurves(scene) -> list:
    anim = scene.animation_data
    return [curve for _owner, curve in fcurve_owners(anim.action)] if anim and anim.action else []


def evaluated_matrix(obj):
    """An object's evaluated world matrix: right after a script moves it, `matrix_world` is stale
    until the depsgraph updates, and drivers and constraints only show in the evaluated copy."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    return obj.evaluated_get(depsgraph).matrix_world.copy()
