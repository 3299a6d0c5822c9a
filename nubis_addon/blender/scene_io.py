"""Translate between Blender data and the plain data core/ and render/ work on."""

from __future__ import annotations

import contextlib
import dataclasses
import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path

import bpy
import numpy as np
from mathutils import Euler, Matrix, Vector

from ..core import bundled, camera, cloudlayers, coverage, fieldstack, limits, paint, schema, userpresets
from ..core import fields as fieldgen
from ..core import sky as skymath
from ..core import storms as stormgen
from ..core.errors import NubisError
from ..core.fsutil import not_a_file
from ..core.presets import Preset
from ..core.state import MAX_STORMS, CloudState, StormLight, sun_vector, wind_vector
from . import sky, vdbclouds

FIELD_IMAGES = {
    "a": ("field_a", "Nubis Field A"),
    "b": ("field_b", "Nubis Field B"),
    "cirrus": ("field_cirrus", "Nubis Cirrus"),
}
SUN_NAME = "Nubis Sun"
STORM_TAG = "nubis_storm"
WORLD_NAME = "Nubis Sky"
CAMERA_NAME = "Nubis Camera"


# ---- settings ---------------------------------------------------------------------------------------


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
    return {s.key: _from_blender(s, getattr(settings, s.key)) for s in schema.PRESET_SCENE}


def _from_blender(s: schema.Setting, value):
    if s.kind == "image" or s.kind == "object":
        return value.name if value else ""
    if s.kind == "enum":
        return value.lower()
    if s.kind in ("vector", "color"):
        return list(value)
    return value


def table_to_dict(item, settings) -> dict:
    """A layer or storm property group as its preset table."""
    return {s.name: _from_blender(s, getattr(item, s.name)) for s in settings if s.in_preset and hasattr(item, s.name)}


def layer_to_dict(layer) -> dict:
    return table_to_dict(layer, schema.LAYER)


def layer_from_dict(layer, data: dict) -> None:
    """Set a layer from its preset table. A paint layer's channel is checked before anything is set, and the
    kind is set before the channel: a paint layer's channel menu offers only the channels a brush paints
    (blender/properties.py)."""
    if data.get("kind", layer.kind.lower()) == "paint" and "channel" in data:
        paint.check_paint_channel(data.get("name") or layer.name, data["channel"])
    if "kind" in data:
        data = {"kind": data["kind"], **data}
    for key, value in data.items():
        if key == "dabs":  # a paint layer's strokes (core/paint.py)
            layer.dabs.clear()
            add_dabs(layer, value)
            continue
        s = schema.LAYER_BY_NAME[key]
        if s.kind == "image":
            layer.image = bpy.data.images.get(value) if value else None
        elif s.kind == "enum":
            setattr(layer, key, value.upper())
        else:
            setattr(layer, key, value)


# ---- field images ----------------------------------------------------------------------------------

_field_generation = [0]


def field_generation() -> int:
    """Bumped whenever Nubis writes a field image, so cached copies of the pixels know to refresh."""
    return _field_generation[0]


def write_field_image(settings, which: str, data: np.ndarray, name: str = ""):
    """Store a field array in its image, creating or resizing it (named `name`, or as FIELD_IMAGES says).
    The image is packed into the .blend when the file is saved (blender/events.py), not on every
    composite: a slider drag re-composites many times a second."""
    attr, default_name = FIELD_IMAGES[which]
    name = name or default_name
    h, w = data.shape[:2]
    img = getattr(settings, attr)
    if img is None or tuple(img.size) != (w, h) or not img.is_float:
        img = bpy.data.images.new(name, w, h, alpha=True, float_buffer=True)
        setattr(settings, attr, img)
    # Data, not colour: no view transform, and alpha is a fourth channel, not coverage to premultiply.
    img.colorspace_settings.name = "Non-Color"
    img.alpha_mode = "CHANNEL_PACKED"
    img.pixels.foreach_set(np.ascontiguousarray(data, dtype=np.float32).ravel())
    img.update()
    _field_generation[0] += 1
    return img


def pack_fields(settings) -> None:
    """Pack the field images whose pixels changed since they were last packed, so they survive save and
    reload: the first cloud layer's and the cirrus, and each further layer's."""
    images = [getattr(settings, attr) for attr, _name in FIELD_IMAGES.values()]
    images += [getattr(c, attr) for c in settings.cloud_layers for attr in ("field_a", "field_b")]
    for img in images:
        if img is not None and (img.packed_file is None or img.is_dirty):
            img.pack()


# ---- a composite owed: the field's inputs changed since the last one ---------------------------------


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
_raster_key_counter = itertools.count(1)


def scene_state(scene) -> SceneState:
    """The scene's SceneState, made on first use."""
    return _scenes.setdefault(scene.as_pointer(), SceneState())


def _known_state(scene) -> SceneState:
    """The scene's SceneState, or a fresh one (not kept) when this session has none: reads make none."""
    return _scenes.get(scene.as_pointer()) or SceneState()


def mark_field_stale(scene) -> None:
    """The field's inputs changed: the next read of the field (or the debounced timer) composites."""
    scene_state(scene).stale = True


def field_stale(scene) -> bool:
    return _known_state(scene).stale


def stale_scenes() -> list:
    return [scene for scene in bpy.data.scenes if _known_state(scene).stale]


def forget_stale() -> None:
    """Forget every scene's SceneState and the paint rasters cached for them: the one place this session's
    per-scene memory ends (blender/events.py calls it on file loads, on unregister, and after a failed
    debounced composite)."""
    _scenes.clear()
    paint.forget()


def raster_key(layer) -> int:
    """The key core/paint.py caches this paint layer's raster under (core holds no Blender pointer)."""
    keys = scene_state(layer.id_data).raster_keys
    pointer = layer.as_pointer()
    if pointer not in keys:
        keys[pointer] = next(_raster_key_counter)
    return keys[pointer]


def coverage_multiplier(scene) -> float:
    """The multiplier on the coverage field that covers the fraction Coverage asks for: from the last
    composite's field before the storms, or, until this session composites, the one saved with the file."""
    state = _known_state(scene)
    s = scene.nubis
    if state.cover_hist is None:
        return s.density_coverage
    m = coverage.multiplier_for(s.density_cover, state.cover_hist)
    return max(m, paint.MULTIPLIER_FLOOR) if state.cover_painted else m


# Each dab column's name and the Python type Blender takes it as (core/paint.py: DABS).
_DAB_TYPES = tuple((column.name, {"float": float, "int": int, "bool": bool}[column.kind]) for column in paint.DABS)


def paint_dabs(layer) -> np.ndarray:
    """A paint layer's dabs as an (N, 7) array (core/paint.py: DAB_COLUMNS)."""
    n = len(layer.dabs)
    out = np.empty((n, len(paint.DABS)), np.float64)
    for k, (name, kind) in enumerate(_DAB_TYPES):
        buf = np.empty(n, np.float32 if kind is float else np.int32)
        if n:
            layer.dabs.foreach_get(name, buf)
        out[:, k] = buf
    return out


def add_dabs(layer, rows) -> None:
    """Append dabs (DAB_COLUMNS rows) to a paint layer's strokes."""
    # Python numbers, not numpy's: a million dabs (a full layer from a preset) are set one attribute at a time.
    for row in rows.tolist() if isinstance(rows, np.ndarray) else rows:
        d = layer.dabs.add()
        for (name, kind), v in zip(_DAB_TYPES, row, strict=True):
            setattr(d, name, kind(v))


def copy_dabs(src, dst) -> None:
    """A duplicated paint layer keeps its strokes."""
    add_dabs(dst, paint_dabs(src))


def paint_layers(settings, params=None) -> list[paint.PaintLayer]:
    """The enabled paint layers, top of the stack first, rasterized on the field's grid."""
    grid = paint.Grid.of(params or params_from_scene(settings))
    out = []
    for layer in settings.layers:
        if layer.kind != "PAINT" or not layer.enabled or not len(layer.dabs):
            continue
        channel = layer.channel.lower()
        paint.check_paint_channel(layer.name, channel)
        r = paint.raster(raster_key(layer), paint_dabs(layer), grid)
        out.append(paint.PaintLayer(channel, float(layer.opacity), r.values))
    return out


def pre_paint(scene):
    """(the paintable planes before the paint, the slider's multiplier) of the scene's last composite, or
    None: what a live stroke re-applies the paint to (blender/paint.py)."""
    return _known_state(scene).pre_paint


def read_field_image(img, which: str, resolution: int) -> np.ndarray:
    if img is None:
        return fieldgen.base_fields(resolution)[which]
    w, h = img.size
    if w == 0 or h == 0 or not img.has_data:
        raise NubisError(f"the field image '{img.name}' has no pixels: run Generate Field or reload the image")
    buf = np.empty(w * h * 4, np.float32)
    img.pixels.foreach_get(buf)
    arr = buf.reshape(h, w, 4)
    if not np.all(np.isfinite(arr)):
        raise NubisError(f"the field image '{img.name}' holds NaN or infinite pixels: regenerate or repaint it")
    return arr


def read_fields(settings, flush: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The field images' pixels; with `flush`, a composite owed is made first (renders and bakes must
    see the edits; the interactive viewport waits for the debounced one instead)."""
    if flush and field_stale(settings.id_data):
        generate_fields(settings.id_data)
    res = settings.field_resolution
    return tuple(read_field_image(getattr(settings, attr), which, res) for which, (attr, _n) in FIELD_IMAGES.items())


def image_arrays(settings) -> dict[str, np.ndarray]:
    """Pixels of every image referenced by an image layer, for the compositor."""
    out = {}
    for layer in settings.layers:
        img = layer.image
        if layer.kind == "IMAGE" and img is not None:
            w, h = img.size
            if not (w and h):
                where = f" ('{bpy.path.abspath(img.filepath)}')" if img.filepath else ""
                raise NubisError(
                    f"the image '{img.name}'{where} of field layer '{layer.name}' has no readable pixels "
                    "(damaged, or not an image format Blender reads): load a valid image or paint it"
                )
            buf = np.empty(w * h * img.channels, np.float32)
            img.pixels.foreach_get(buf)
            out[img.name] = buf.reshape(h, w, img.channels)
    return out


def _stack_inputs(scene, owner, params, storms=(), progress=None) -> fieldstack.StackInputs:
    """What `owner` (the scene's settings, or a further cloud layer) composites from."""
    return fieldstack.StackInputs(
        layers=[layer_to_dict(layer) for layer in owner.layers],
        params=params,
        images=image_arrays(owner),
        rain=owner.rule_cumulonimbus_top if owner.rule_rain else None,
        horizon=owner.rule_horizon_start if owner.rule_horizon else None,
        camera_xy=_camera_xy(scene),
        cover=owner.density_cover,
        painted=paint_layers(owner, params),
        has_paint=any(layer.kind == "PAINT" for layer in owner.layers),
        storms=storms,
        progress=progress,
    )


def _store_multiplier(owner, value: float) -> None:
    try:
        with batch_edit():
            owner.density_coverage = value
    except (AttributeError, RuntimeError):
        pass  # a composite made while Blender draws cannot write settings; renders read the session state


def generate_fields(scene, progress=None) -> None:
    """Composite the layer stack into the field images (the Data Field Generator, GDC22), with the weather
    rules, the coverage multiplier, the storms and the strokes (core/fieldstack.py), then every further
    cloud layer's. ``progress`` gets the fraction of layers done."""
    settings = scene.nubis
    params = params_from_scene(settings)
    inputs = _stack_inputs(scene, settings, params, storm_stencils(settings, params), progress)
    done = fieldstack.composite_stack(inputs)
    # Kept in the file, so a reopened file draws the same sky (coverage_multiplier).
    state = scene_state(scene)
    state.cover_hist = done.cover_hist
    state.cover_painted = any(p.channel == "coverage" for p in inputs.painted)
    state.pre_paint = done.pre_paint
    _store_multiplier(settings, done.stored_multiplier)
    for which, data in done.planes.items():
        write_field_image(settings, which, data)
    for cloud in settings.cloud_layers:
        composite_cloud_layer(scene, cloud)
    state.stale = False


# ---- a layered sky: the further cloud layers (core/cloudlayers.py, docs/layers.md) ---------------------


def cloud_layer_params(settings, cloud) -> dict:
    """A further cloud layer's full settings: the sky's, with the layer's own on top."""
    own = {s.key: _from_blender(s, getattr(cloud, s.key)) for s in schema.CLOUD_LAYER_SETTINGS}
    return cloudlayers.layer_params(params_from_scene(settings), own)


def composite_cloud_layer(scene, cloud) -> None:
    """Composite a further layer's stack into its own field images, as generate_fields does the first
    layer's (core/fieldstack.py). The superstorms are the first layer's: their stencils and lights act
    there (docs/layers.md)."""
    done = fieldstack.composite_stack(_stack_inputs(scene, cloud, cloud_layer_params(scene.nubis, cloud)))
    scene_state(scene).layer_coverage[cloud.name] = done.stored_multiplier
    _store_multiplier(cloud, done.stored_multiplier)
    for which in ("a", "b"):
        write_field_image(cloud, which, done.planes[which], f"{FIELD_IMAGES[which][1]} ({cloud.name})")


def drawn_cloud_layers(scene) -> tuple[tuple[cloudlayers.LayerField, ...], bool]:
    """The further layers drawn (enabled, and soloed while any layer is) with their fields, and whether
    the first layer is drawn. A stack the sky cannot draw (layers sharing altitudes) is refused here."""
    settings = scene.nubis
    soloing = settings.first_layer_solo or any(c.solo for c in settings.cloud_layers)

    def drawn(enabled: bool, solo: bool) -> bool:
        return enabled and (solo or not soloing)

    first = drawn(settings.first_layer_enabled, settings.first_layer_solo)
    ranges = [(settings.first_layer_name, settings.layer_bottom, settings.layer_top)] if first else []
    out = []
    res = settings.field_resolution
    known = _known_state(scene).layer_coverage
    for cloud in settings.cloud_layers:
        if not drawn(cloud.enabled, cloud.solo):
            continue
        params = cloud_layer_params(settings, cloud)
        params["density_coverage"] = known.get(cloud.name, cloud.density_coverage)
        a, b = _layer_field_arrays(scene, cloud, res)
        out.append(cloudlayers.LayerField(cloud.name, params, a, b))
        ranges.append((cloud.name, cloud.layer_bottom, cloud.layer_top))
    if out:
        cloudlayers.check_stack(ranges, "the scene's cloud layers")
    return tuple(out), first


def _layer_field_arrays(scene, cloud, res: int) -> tuple[np.ndarray, np.ndarray]:
    """A further layer's field pixels, read again only when Nubis wrote a field image since (every redraw
    reads the state; the pixels are megabytes)."""
    images = (cloud.field_a, cloud.field_b)
    key = (field_generation(), res, *(img.as_pointer() if img is not None else 0 for img in images))
    cache = scene_state(scene).layer_fields
    held = cache.get(cloud.name)
    if held is None or held[0] != key:
        arrays = tuple(read_field_image(img, w, res) for img, w in zip(images, ("a", "b"), strict=True))
        held = cache[cloud.name] = (key, *arrays)
    return held[1], held[2]


def add_cloud_layer(settings, data: cloudlayers.CloudLayer, preset_path: Path | None = None):
    """A further cloud layer made from its preset data (not composited: generate_fields does that)."""
    cloud = settings.cloud_layers.add()
    cloud.name, cloud.enabled = data.name, data.enabled
    for s in schema.CLOUD_LAYER_SETTINGS:
        value = data.params[s.key]
        setattr(cloud, s.key, value.upper() if s.kind == "enum" else value)
    for layer in data.field_layers:
        layer = dict(layer)
        if layer["kind"] == "image":
            layer["image"] = _load_layer_image(layer["image"], preset_path)
        layer_from_dict(cloud.layers.add(), layer)
    return cloud


def cloud_layers_of(settings) -> list[cloudlayers.CloudLayer]:
    """The further layers as preset data (what Save Preset writes), floats tidied as the rest."""
    tidy = userpresets.tidy_float32
    out = []
    for cloud in settings.cloud_layers:
        own = {s.key: _from_blender(s, getattr(cloud, s.key)) for s in schema.CLOUD_LAYER_SETTINGS}
        own = {k: tidy(v) if isinstance(v, float) else v for k, v in own.items()}
        stack = [_layer_table(layer) for layer in cloud.layers]
        out.append(cloudlayers.CloudLayer(cloud.name, own, stack, cloud.enabled))
    return out


# ---- superstorms ------------------------------------------------------------------------------------


def storm_centre(storm) -> tuple[float, float]:
    if storm.empty is None:
        return (0.0, 0.0)
    t = evaluated_matrix(storm.empty).translation
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
    curve = next((fc for fc in fcurves(scene) if fc.data_path == path), None)
    if curve is None:
        return None
    s = scene.nubis
    fps = scene_fps(scene)
    offset = s.wind_time_offset
    if time <= offset or s.wind_time_scale <= 0:
        return float(time * stormgen.vortex_fade(storm.blend))
    last = int(math.ceil(scene.frame_current + scene.frame_subframe)) + 1
    keys = tuple((k.co[0], k.co[1], k.interpolation) for k in curve.keyframe_points)
    key = (path, keys, fps, s.wind_time_scale, offset)
    vortex = scene_state(scene).vortex
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
    with batch_edit():
        storm = scene.nubis.storms.add()
        for key, value in data.items():
            if key not in ("x", "y"):
                setattr(storm, key, value)
        storm.empty = empty
    return storm


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
    for owner, curve in _fcurve_owners(anim.action):
        path = curve.data_path
        if not path.startswith(prefix):
            continue
        i = int(path[len(prefix) : path.index("]")])
        if i == index:
            owner.remove(curve)
        elif i > index:
            curve.data_path = f"{prefix}{i - 1}{path[path.index(']') :]}"


def _fcurve_owners(action) -> list:
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
    return [curve for _owner, curve in _fcurve_owners(anim.action)] if anim and anim.action else []


def _camera_xy(scene) -> tuple[float, float]:
    if scene.camera is None:
        return (0.0, 0.0)
    t = evaluated_matrix(scene.camera).translation
    return (float(t.x), float(t.y))


def layer_images(settings) -> set[str]:
    return {layer.image.name for layer in settings.layers if layer.kind == "IMAGE" and layer.image is not None}


# ---- presets ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Keep:
    """What New Cloudscape leaves as the artist had it. Everything not kept is set up from the preset."""

    camera: bool = False  # the scene camera: not moved, not re-lensed
    world: bool = False  # the scene's World: not replaced or recolored
    render: bool = False  # resolution, frame, view transform, Cycles samples and bounces
    sun: bool = False  # light the clouds with the scene's own Sun lamp rather than the preset's
    sky: bool | None = None  # build a physical sky World (blender/sky.py); None: the preset's [world] sky


def apply_preset(scene, preset: Preset, progress=None, keep: Keep = Keep()) -> None:
    """Make `scene` the preset's cloudscape: settings, layer stack, field images, and (unless `keep`
    says otherwise) its sun, world, camera and render settings; ``progress`` follows the field
    composite. The World is a physically based sky ('Nubis Sky', blender/sky.py) when the preset's
    `[world] sky` (or `keep.sky`) asks for one, else the preset's flat color; an artist's World stays in
    the file. Storm Empties an artist made stay in the scene; those Nubis made for the old storms go."""
    settings = scene.nubis
    own_sun = settings.sun if keep.sun and settings.sun is not None else (find_sun(scene) if keep.sun else None)
    with batch_edit():
        for key, value in preset.params.items():
            s = schema.BY_KEY[key]
            setattr(settings, key, value.upper() if s.kind == "enum" else value)
        settings.preset = preset.path.stem if preset.path else preset.name
        settings.layers.clear()
        for data in preset.layers:
            data = dict(data)
            if data["kind"] == "image":
                data["image"] = _load_layer_image(data["image"], preset.path)
            layer_from_dict(settings.layers.add(), data)
        settings.cloud_layers.clear()
        for data in preset.cloud_layers:
            add_cloud_layer(settings, data, preset.path)
        settings.active_further_layer = -1
        settings.first_layer_enabled, settings.first_layer_solo = True, False
        settings.sun = own_sun or _setup_sun(scene, preset.extra["sun"])
        if not keep.camera or scene.camera is None:
            _setup_camera(scene, preset.extra["camera"])
        for storm in list(settings.storms):
            if storm.empty is not None and storm.empty.get(STORM_TAG):
                bpy.data.objects.remove(storm.empty)
        settings.storms.clear()
        for data in preset.storms:
            add_storm(scene, data)
    generate_fields(scene, progress)  # after the camera and storms: the rules and stencils are placed by them
    if preset.legacy_coverage is not None:
        with batch_edit():
            settings.density_cover = coverage.covered_fraction(preset.legacy_coverage, scene_state(scene).cover_hist)
            settings.density_coverage = preset.legacy_coverage
    # The sky after the (possibly long) composite: its capture renders with Cycles for a second.
    if not keep.world or scene.world is None:
        build_sky = preset.extra["world"]["sky"] if keep.sky is None else keep.sky
        if build_sky:
            sky.build_world(scene, preset.extra["world"], settings.sun)
        else:
            _setup_world(scene, preset.extra["world"])
    if keep.render:
        return
    r = preset.extra["render"]
    scene.render.resolution_x, scene.render.resolution_y = r["width"], r["height"]
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = r["view_transform"]
    scene.frame_current = r["frame"]
    scene.cycles.samples = r["samples"]
    scene.cycles.volume_bounces = r["volume_bounces"]


def preset_from_scene(scene, name: str, description: str = "") -> Preset:
    """The scene's cloudscape as a preset (what Save Preset writes): every scene setting a preset
    holds, the layer stack, the storms (centred on their Empties), and the sun, world, camera and
    render sections read back from Blender's objects, the inverse of apply_preset. Floats are written
    as the shortest decimals of their float32 values (core/userpresets.py)."""
    settings = scene.nubis
    tidy = userpresets.tidy_float32
    params = {}
    for s in schema.PRESET_SCENE:
        value = _from_blender(s, getattr(settings, s.key))
        params[s.key] = tidy(value) if s.kind in ("float", "vector", "color") else value
    layers = [_layer_table(layer) for layer in settings.layers]
    storms = []
    for storm in list(settings.storms)[:MAX_STORMS]:
        data = {k: tidy(v) for k, v in table_to_dict(storm, schema.STORM).items()}
        data["x"], data["y"] = (tidy(v) for v in storm_centre(storm))
        storms.append(data)
    extra = {sec: schema.table_defaults(t.values()) for sec, t in schema.EXTRA_SECTIONS.items() if sec != "preset"}
    sun = find_sun(scene)
    if sun is not None:
        d = evaluated_matrix(sun).to_3x3() @ Vector((0.0, 0.0, 1.0))
        d.normalize()
        extra["sun"].update(
            elevation=math.degrees(math.asin(max(-1.0, min(1.0, d.z)))),
            azimuth=math.degrees(math.atan2(d.x, d.y)) % 360.0,
            color=list(sun.data.color),
            strength=sun.data.energy,
            angle=math.degrees(sun.data.angle),
        )
    world = scene.world
    if sky.is_nubis_sky(world):
        extra["world"].update(sky.atmosphere(world))
    elif world is not None:
        extra["world"].update(sky=False)
        bg = next((n for n in world.node_tree.nodes if n.type == "BACKGROUND"), None) if world.node_tree else None
        if bg is not None:
            extra["world"].update(color=list(bg.inputs["Color"].default_value)[:3])
            extra["world"].update(strength=bg.inputs["Strength"].default_value)
        else:
            extra["world"].update(color=list(world.color))
    cam = scene.camera
    if cam is not None:
        if cam.parent is None and cam.rotation_mode == "XYZ" and not cam.constraints:
            location, rotation = list(cam.location), list(cam.rotation_euler)
        else:
            m = evaluated_matrix(cam)
            location, rotation = list(m.translation), list(m.to_euler("XYZ"))
        extra["camera"].update(location=location, rotation=[math.degrees(a) for a in rotation])
        if cam.type == "CAMERA":
            extra["camera"].update(lens=cam.data.lens, clip_end=cam.data.clip_end)
    r = scene.render
    pct = r.resolution_percentage / 100.0
    extra["render"].update(
        width=max(4, round(r.resolution_x * pct)), height=max(4, round(r.resolution_y * pct)), frame=scene.frame_current
    )
    cycles = getattr(scene, "cycles", None)
    if cycles is not None:
        extra["render"].update(samples=cycles.samples, volume_bounces=cycles.volume_bounces)
    if scene.view_settings.view_transform in schema.EXTRA_SECTIONS["render"]["view_transform"].choices:
        extra["render"]["view_transform"] = scene.view_settings.view_transform
    for table in extra.values():
        for key, value in table.items():
            table[key] = tidy(value)
    return Preset(name, None, params, extra, layers, description, storms, cloud_layers=cloud_layers_of(settings))


def _layer_table(layer) -> dict:
    """A field layer as its preset table, a paint layer's strokes included, floats tidied."""
    tidy = userpresets.tidy_float32
    data = {k: tidy(v) for k, v in layer_to_dict(layer).items()}
    if layer.kind == "PAINT" and len(layer.dabs):
        data["dabs"] = [
            [tidy(float(v)) if kind is float else int(v) for (_name, kind), v in zip(_DAB_TYPES, row, strict=True)]
            for row in paint_dabs(layer)
        ]
    return data


def _load_layer_image(ref: str, preset_path: Path | None) -> str:
    if ref in bpy.data.images:
        return ref
    path = Path(ref)
    if not path.is_absolute() and preset_path is not None:
        path = preset_path.parent / path
    why = not_a_file(path)
    if why == "does not exist":
        raise NubisError(f"the image '{ref}' of a field layer was not found: put it beside the preset or fix the path")
    if why:
        raise NubisError(f"the image '{ref}' of a field layer {why}: point the layer at an image file")
    try:
        size = path.stat().st_size
    except OSError as err:
        raise NubisError(f"cannot read the image '{path}' ({err.strerror}): check its permissions") from None
    if size == 0:
        raise NubisError(f"the image '{path}' of a field layer is an empty file (0 bytes): export it again")
    header = _image_header_size(path)
    if header is not None and max(header) > limits.LAYER_IMAGE_MAX:
        w, h = header
        raise NubisError(
            f"the image '{path}' of a field layer is {w}x{h} pixels, which would take about "
            f"{w * h * 20 / 2**30:.1f} GB to read: scale it to at most {limits.LAYER_IMAGE_MAX} pixels a side "
            "(the finest field has 4096)"
        )
    try:
        img = bpy.data.images.load(str(path), check_existing=True)
    except RuntimeError as err:
        raise NubisError(f"cannot load the image '{path}' ({err}): check that it is a valid image") from None
    # Blender loads pixels lazily: a file it cannot decode shows as a 0 x 0 image only now.
    if not img.has_data:
        img.reload()
    w, h = img.size
    if w == 0 or h == 0:
        bpy.data.images.remove(img)
        raise NubisError(
            f"the image '{path}' of a field layer cannot be read as an image (damaged, or not an image format "
            "Blender reads): export it again as PNG or EXR"
        )
    img.colorspace_settings.name = "Non-Color"
    return img.name


def _image_header_size(path: Path) -> tuple[int, int] | None:
    """An image's width and height from its header alone (OpenImageIO reads no pixels), or None when
    OpenImageIO cannot open it (Blender's loader then says what is wrong)."""
    oiio = bundled.oiio()
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        oiio.geterror()  # retrieved, so OpenImageIO does not print it at exit
        return None
    try:
        spec = inp.spec()
        return int(spec.width), int(spec.height)
    finally:
        inp.close()


def _setup_sun(scene, sun: dict):
    obj = scene.objects.get(SUN_NAME)
    if obj is None or obj.type != "LIGHT":
        data = bpy.data.lights.new(SUN_NAME, type="SUN")
        obj = bpy.data.objects.new(SUN_NAME, data)
        scene.collection.objects.link(obj)
    d = Vector(sun_vector(sun["elevation"], sun["azimuth"]))
    # A sun lamp shines along its local -Z; point +Z at the sun.
    obj.rotation_euler = d.to_track_quat("Z", "Y").to_euler()
    obj.location = (0.0, 0.0, 10.0)
    obj.data.color = sun["color"]
    obj.data.energy = sun["strength"]
    obj.data.angle = math.radians(sun["angle"])
    return obj


def _setup_world(scene, world_cfg: dict) -> None:
    """The preset's sky as the World "Nubis Sky"; an artist's own World is kept in the file (fake user)."""
    world = bpy.data.worlds.get(WORLD_NAME) or bpy.data.worlds.new(WORLD_NAME)
    if scene.world is not None and scene.world != world:
        scene.world.use_fake_user = True
    scene.world = world
    world.color = world_cfg["color"]
    if world.node_tree is None:  # worlds made before 5.0 may lack a node tree
        world.use_nodes = True
    if sky.MARKER in world:
        del world[sky.MARKER]
    bg = next((n for n in world.node_tree.nodes if n.type == "BACKGROUND"), None)
    if bg is None:
        bg = world.node_tree.nodes.new("ShaderNodeBackground")
        out = next((n for n in world.node_tree.nodes if n.type == "OUTPUT_WORLD"), None)
        out = out or world.node_tree.nodes.new("ShaderNodeOutputWorld")
        world.node_tree.links.new(bg.outputs[0], out.inputs["Surface"])
    bg.inputs["Color"].default_value = (*world_cfg["color"], 1.0)
    bg.inputs["Strength"].default_value = world_cfg["strength"]


def _setup_camera(scene, cam: dict) -> None:
    """The preset's view from the camera "Nubis Camera", made the scene camera; an artist's own camera
    is left where it was."""
    obj = scene.objects.get(CAMERA_NAME)
    if obj is None or obj.type != "CAMERA":
        obj = bpy.data.objects.new(CAMERA_NAME, bpy.data.cameras.new(CAMERA_NAME))
        scene.collection.objects.link(obj)
    scene.camera = obj
    obj.location = cam["location"]
    obj.rotation_euler = Euler([math.radians(a) for a in cam["rotation"]], "XYZ")
    obj.data.lens = cam["lens"]
    obj.data.clip_end = cam["clip_end"]


# ---- scene to state --------------------------------------------------------------------------------


find_sun = sky.find_sun


def world_ambient(scene) -> tuple[float, float, float]:
    world = scene.world
    if world is None:
        return (0.0, 0.0, 0.0)
    if world.node_tree is not None:
        bg = next((n for n in world.node_tree.nodes if n.type == "BACKGROUND"), None)
        if bg is not None:
            c = bg.inputs["Color"].default_value
            s = bg.inputs["Strength"].default_value
            return (c[0] * s, c[1] * s, c[2] * s)
    return tuple(world.color)


def state_from_scene(scene, camera_location=None, fields: tuple | None = None, wait: bool = True) -> CloudState:
    """The frame's CloudState; `fields` passes already-read (field_a, field_b) arrays to skip reading pixels.
    The sky light comes from the World's radiance (blender/sky.py); `wait` False (the viewport's draw)
    takes the last capture of the World rather than rendering a new one there and then."""
    settings = scene.nubis
    if fields is None:
        fields = read_fields(settings)  # first: a composite owed also sets the coverage multiplier
    params = params_from_scene(settings)
    params["density_coverage"] = coverage_multiplier(scene)
    further, first_drawn = drawn_cloud_layers(scene)
    sun = find_sun(scene)
    if sun is not None:
        direction = tuple(evaluated_matrix(sun).to_3x3() @ Vector((0.0, 0.0, 1.0)))
        radiance = tuple(c * sun.data.energy for c in sun.data.color)
    else:
        direction, radiance = (0.0, 0.0, 1.0), (0.0, 0.0, 0.0)
    air = sky.sun_air(scene)
    if air is not None and sun is not None:  # the sun above the atmosphere; each sample takes its own air
        radiance = (sun.data.energy,) * 3
    if camera_location is None:
        camera_location = evaluated_matrix(scene.camera).translation if scene.camera else (0.0, 0.0, 0.0)
    fps = scene_fps(scene)
    time = (scene.frame_current + scene.frame_subframe) / fps * params["wind_time_scale"] + params["wind_time_offset"]
    env = sky.environment(scene, wait)
    above, below, flank = skymath.hemisphere_radiance_cached(env)
    return CloudState(
        params=params,
        field_a=fields[0],
        field_b=fields[1],
        field_c=fields[2],
        sun_direction=direction,
        sun_radiance=radiance,
        sun_air=air,
        ambient=above,
        ambient_below=below,
        ambient_flank=sky.flank_light(scene, above, flank),
        sky_env=env,
        draw_center=(float(camera_location[0]), float(camera_location[1])),
        time=time,
        storms=storm_lights(settings, scene, time),
        vdb_clouds=vdbclouds.placements(scene, strict=wait),
        vdb_gpu_budget=vdbclouds.gpu_budget(),
        cloud_layers=further,
        first_layer_drawn=first_drawn,
    )


def camera_matrices(scene, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """The scene camera's projection (its clipping planes included) at this resolution and its view matrix,
    float64."""
    cam = scene.camera
    if cam is None:
        raise NubisError("the scene has no camera: add one or use New Cloudscape")
    depsgraph = bpy.context.evaluated_depsgraph_get()
    proj = cam.evaluated_get(depsgraph).calc_matrix_camera(depsgraph, x=width, y=height, scale_x=1.0, scale_y=1.0)
    view = np.linalg.inv(np.array(evaluated_matrix(cam).normalized(), dtype=np.float64))
    return np.array(proj, dtype=np.float64), view


def camera_inv_view_proj(scene, width: int, height: int):
    """Inverse view-projection of the scene camera at this resolution, as a mathutils Matrix."""
    proj, view = camera_matrices(scene, width, height)
    return Matrix(camera.ray_inverse_view_projection(proj, view).tolist())


def camera_eye(scene) -> tuple[float, float, float, float]:
    """The scene camera's position (w = 1), or w = 0 for an orthographic camera (rays start on the
    near plane then)."""
    cam = scene.camera
    if cam is None or getattr(cam.data, "type", "PERSP") == "ORTHO":
        return (0.0, 0.0, 0.0, 0.0)
    t = evaluated_matrix(cam).translation
    return (float(t.x), float(t.y), float(t.z), 1.0)


def evaluated_matrix(obj):
    """An object's evaluated world matrix: right after a script moves it, `matrix_world` is stale
    until the depsgraph updates, and drivers and constraints only show in the evaluated copy."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    return obj.evaluated_get(depsgraph).matrix_world.copy()
