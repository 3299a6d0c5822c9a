"""The scene's superstorms: their Empties, stencils and lights for core/storms.py, their animation."""

from __future__ import annotations

import dataclasses
import math

import bpy
import numpy as np

from ...core import storms as stormgen
from ...core.state import MAX_STORMS, StormLight, wind_vector
from . import sceneparams

STORM_TAG = "nubis_storm"


def storm_centre(storm) -> tuple[float, float]:
    if storm.empty is None:
        return (0.0, 0.0)
    t = sceneparams.evaluated_matrix(storm.empty).translation
    return (float(t.x), float(t.y))


def storm_stencils(settings, params) -> list:
    wx, wy = wind_vector(params["wind_direction"])
    # The renderer filters the field bilinearly; keeping the stencil 1.5 texels inside the radius means
    # no filtered sample outside the radius ever sees a storm-modified texel.
    margin = 1.5 * params["field_size"] / params["field_resolution"]
    out = []
    for s in list(settings.storms)[:MAX_STORMS]:
        x, y = storm_centre(s)
        radius = max(s.radius - margin, 0.5 * s.radius)
        out.append(_from_settings(stormgen.Storm, s, x=x, y=y, radius=radius, wind_x=wx, wind_y=wy))
    return out


def _from_settings(cls, source, **given):
    """A `cls` dataclass: the fields in `given`, and every other field the property group `source` holds
    under the same name (a storm's settings carry the names of core's storm fields); the rest defaults."""
    read = {}
    for f in dataclasses.fields(cls):
        if f.name not in given and f.name in source.bl_rna.properties:
            value = getattr(source, f.name)
            read[f.name] = tuple(value) if hasattr(value, "__len__") and not isinstance(value, str) else value
    return cls(**read, **given)


def _vortex_time(scene, index: int, storm, time: float) -> float | None:
    """The vortex time of storm `index` when its blend is animated: the lifecycle fade integrated over
    the frames from 0 to now (core/storms.py), sampled once per frame and cached per F-curve."""
    if scene is None:
        return None
    path = f"nubis.storms[{index}].blend"
    curve = next((fc for fc in sceneparams.fcurves(scene) if fc.data_path == path), None)
    if curve is None:
        return None
    s = scene.nubis
    fps = sceneparams.scene_fps(scene)
    offset = s.wind_time_offset
    if time <= offset or s.wind_time_scale <= 0:
        return float(time * stormgen.vortex_fade(storm.blend))
    last = int(math.ceil(scene.frame_current + scene.frame_subframe)) + 1
    keys = tuple((k.co[0], k.co[1], k.interpolation) for k in curve.keyframe_points)
    key = (path, keys, fps, s.wind_time_scale, offset)
    vortex = sceneparams.scene_state(scene).vortex
    cached = vortex.get(key)
    if cached is None or len(cached[0]) < last + 1:
        frames = np.arange(0, max(last, 2 * len(cached[0]) if cached else 0) + 1, dtype=np.float64)
        if len(vortex) > 64:
            vortex.clear()
        blends = np.array([curve.evaluate(f) for f in frames])
        vortex[key] = cached = (frames / fps * s.wind_time_scale + offset, blends)
    return float(stormgen.vortex_time(cached[0], cached[1], time))


def storm_lights(settings, scene=None, time: float = 0.0) -> tuple[StormLight, ...]:
    """The storms as the renderer needs them; given the scene, animated lifecycles get their vortex time."""
    lights = []
    for i, s in enumerate(list(settings.storms)[:MAX_STORMS]):
        x, y = storm_centre(s)
        lights.append(_from_settings(StormLight, s, x=x, y=y, vortex_time=_vortex_time(scene, i, s, time)))
    return tuple(lights)


def add_storm(scene, data: dict):
    """A storm entry and the Empty that positions it."""
    empty = bpy.data.objects.new(data.get("name", "Superstorm"), None)
    empty[STORM_TAG] = True  # made by Nubis: removed with its storm, unlike an Empty the artist assigns
    empty.empty_display_type = "CIRCLE"
    empty.empty_display_size = data.get("radius", 12000.0)
    empty.location = (data.get("x", 0.0), data.get("y", 0.0), scene.nubis.layer_bottom)
    scene.collection.objects.link(empty)
    with sceneparams.batch_edit():
        storm = scene.nubis.storms.add()
        for key, value in data.items():
            if key not in ("x", "y"):
                setattr(storm, key, value)
        storm.empty = empty
    return storm


def storm_of_object(settings, obj):
    """The storm whose Empty `obj` is (or its evaluated copy), or None."""
    original = getattr(obj, "original", obj)
    return next((s for s in settings.storms if s.empty is not None and s.empty == original), None)


def remove_storm_animation(scene, index: int) -> None:
    """Storm F-curves are addressed by collection index: drop the removed storm's curves and move the
    later storms' curves down one, so no storm inherits another's lifecycle or lightning."""
    anim = scene.animation_data
    if not anim or not anim.action:
        return
    prefix = "nubis.storms["
    for owner, curve in sceneparams.fcurve_owners(anim.action):
        path = curve.data_path
        if not path.startswith(prefix):
            continue
        i = int(path[len(prefix) : path.index("]")])
        if i == index:
            owner.remove(curve)
        elif i > index:
            curve.data_path = f"{prefix}{i - 1}{path[path.index(']') :]}"
