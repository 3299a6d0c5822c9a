"""The data field in the scene: its field layers, images and paint strokes, composited by core/fieldstack.py
for the first cloud layer and every further one alike, and the further cloud layers' fields."""

from __future__ import annotations

from pathlib import Path

import bpy
import numpy as np

from ...core import bundled, cloudlayers, coverage, fieldstack, limits, paint, paintraster, schema, userpresets
from ...core import fields as fieldgen
from ...core.errors import NubisError
from ...core.fsutil import not_a_file
from . import sceneparams, superstorms

FIELD_IMAGES = {
    "a": ("field_a", "Nubis Field A"),
    "b": ("field_b", "Nubis Field B"),
    "cirrus": ("field_cirrus", "Nubis Cirrus"),
}


def layer_to_dict(layer) -> dict:
    return sceneparams.table_to_dict(layer, schema.FIELD_LAYER)


def layer_from_dict(layer, data: dict) -> None:
    """Set a layer from its preset table. A paint layer's channel is checked before anything is set, and the
    kind is set before the channel: a paint layer's channel menu offers only the channels a brush paints
    (blender/sidebar/properties.py)."""
    if data.get("kind", layer.kind.lower()) == "paint" and "channel" in data:
        paint.check_paint_channel(data.get("name") or layer.name, data["channel"])
    if "kind" in data:
        data = {"kind": data["kind"], **data}
    for key, value in data.items():
        if key == "dabs":  # a paint layer's strokes (core/paint.py)
            layer.dabs.clear()
            add_dabs(layer, value)
            continue
        s = schema.FIELD_LAYER_BY_NAME[key]
        if s.kind == "image":
            layer.image = bpy.data.images.get(value) if value else None
        elif s.kind == "enum":
            setattr(layer, key, value.upper())
        else:
            setattr(layer, key, value)


_field_generation = [0]


def field_generation() -> int:
    """Bumped whenever Nubis writes a field image, so cached copies of the pixels know to refresh."""
    return _field_generation[0]


def write_field_image(settings, which: str, data: np.ndarray, name: str = ""):
    """Store a field array in its image, creating or resizing it (named `name`, or as FIELD_IMAGES says).
    The image is packed into the .blend when the file is saved (blender/live/events.py), not on every
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


def raster_key(layer) -> int:
    """The key core/paint.py caches this paint layer's raster under (core holds no Blender pointer)."""
    keys = sceneparams.scene_state(layer.id_data).raster_keys
    pointer = layer.as_pointer()
    if pointer not in keys:
        keys[pointer] = next(sceneparams.raster_key_counter)
    return keys[pointer]


def coverage_multiplier(scene) -> float:
    """The multiplier on the coverage field that covers the fraction Coverage asks for: from the last
    composite's field before the storms, or, until this session composites, the one saved with the file."""
    state = sceneparams.known_state(scene)
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


def paint_layers(settings, params=None) -> list[paintraster.PaintLayer]:
    """The enabled paint layers, top of the stack first, rasterized on the field's grid."""
    grid = paint.Grid.of(params or sceneparams.params_from_scene(settings))
    out = []
    for layer in settings.layers:
        if layer.kind != "PAINT" or not layer.enabled or not len(layer.dabs):
            continue
        channel = layer.channel.lower()
        paint.check_paint_channel(layer.name, channel)
        r = paintraster.raster(raster_key(layer), paint_dabs(layer), grid)
        out.append(paintraster.PaintLayer(channel, float(layer.opacity), r.values))
    return out


def pre_paint(scene):
    """(the paintable planes before the paint, the slider's multiplier) of the scene's last composite, or
    None: what a live stroke re-applies the paint to (blender/sidebar/paint.py)."""
    return sceneparams.known_state(scene).pre_paint


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
    if flush and sceneparams.field_stale(settings.id_data):
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
        with sceneparams.batch_edit():
            owner.density_coverage = value
    except (AttributeError, RuntimeError):
        pass  # a composite made while Blender draws cannot write settings; renders read the session state


def generate_fields(scene, progress=None) -> None:
    """Composite the layer stack into the field images (the Data Field Generator, GDC22), with the weather
    rules, the coverage multiplier, the storms and the strokes (core/fieldstack.py), then every further
    cloud layer's. ``progress`` gets the fraction of layers done."""
    settings = scene.nubis
    params = sceneparams.params_from_scene(settings)
    inputs = _stack_inputs(scene, settings, params, superstorms.storm_stencils(settings, params), progress)
    done = fieldstack.composite_stack(inputs)
    # Kept in the file, so a reopened file draws the same sky (coverage_multiplier).
    state = sceneparams.scene_state(scene)
    state.cover_hist = done.cover_hist
    state.cover_painted = any(p.channel == "coverage" for p in inputs.painted)
    state.pre_paint = done.pre_paint
    _store_multiplier(settings, done.stored_multiplier)
    for which, data in done.planes.items():
        write_field_image(settings, which, data)
    for cloud in settings.cloud_layers:
        composite_cloud_layer(scene, cloud)
    state.stale = False


def cloud_layer_params(settings, cloud) -> dict:
    """A further cloud layer's full settings: the sky's, with the layer's own on top."""
    own = {s.key: sceneparams.from_blender(s, getattr(cloud, s.key)) for s in schema.CLOUD_LAYER_SETTINGS}
    return cloudlayers.layer_params(sceneparams.params_from_scene(settings), own)


def composite_cloud_layer(scene, cloud) -> None:
    """Composite a further layer's stack into its own field images, as generate_fields does the first
    layer's (core/fieldstack.py). The superstorms are the first layer's: their stencils and lights act
    there (docs/layers.md)."""
    done = fieldstack.composite_stack(_stack_inputs(scene, cloud, cloud_layer_params(scene.nubis, cloud)))
    sceneparams.scene_state(scene).layer_coverage[cloud.name] = done.stored_multiplier
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
    known = sceneparams.known_state(scene).layer_coverage
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
    cache = sceneparams.scene_state(scene).layer_fields
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
            layer["image"] = load_layer_image(layer["image"], preset_path)
        layer_from_dict(cloud.layers.add(), layer)
    return cloud


def cloud_layers_of(settings) -> list[cloudlayers.CloudLayer]:
    """The further layers as preset data (what Save Preset writes), floats tidied as the rest."""
    tidy = userpresets.tidy_float32
    out = []
    for cloud in settings.cloud_layers:
        own = {s.key: sceneparams.from_blender(s, getattr(cloud, s.key)) for s in schema.CLOUD_LAYER_SETTINGS}
        own = {k: tidy(v) if isinstance(v, float) else v for k, v in own.items()}
        stack = [layer_table(layer) for layer in cloud.layers]
        out.append(cloudlayers.CloudLayer(cloud.name, own, stack, cloud.enabled))
    return out


def _camera_xy(scene) -> tuple[float, float]:
    if scene.camera is None:
        return (0.0, 0.0)
    t = sceneparams.evaluated_matrix(scene.camera).translation
    return (float(t.x), float(t.y))


def layer_images(settings) -> set[str]:
    return {layer.image.name for layer in settings.layers if layer.kind == "IMAGE" and layer.image is not None}


def layer_table(layer) -> dict:
    """A field layer as its preset table, a paint layer's strokes included, floats tidied."""
    tidy = userpresets.tidy_float32
    data = {k: tidy(v) for k, v in layer_to_dict(layer).items()}
    if layer.kind == "PAINT" and len(layer.dabs):
        data["dabs"] = [
            [tidy(float(v)) if kind is float else int(v) for (_name, kind), v in zip(_DAB_TYPES, row, strict=True)]
            for row in paint_dabs(layer)
        ]
    return data


def load_layer_image(ref: str, preset_path: Path | None) -> str:
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
    header = image_header_size(path)
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


def image_header_size(path: Path) -> tuple[int, int] | None:
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
