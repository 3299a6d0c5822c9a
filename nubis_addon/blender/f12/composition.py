"""F12 with the scene's objects in the clouds (docs/sky.md#objects-in-the-clouds): before each frame the
scene's surfaces are drawn from the render camera into a depth pre-pass (render/depthpass.py), each
camera ray's clouds are split where it meets the first of them (shaders/nubis_split_frag.glsl), and:

- the clouds in front of the surfaces go on a veil, a quad the engine renders just in front of the
  nearest surface, seen by camera rays only: emission for their light and transparency for the rest, so
  EEVEE and Cycles lay them over the objects sample by sample, with their own anti-aliasing, pixel
  filter and camera motion blur (the veil is widened by what the shutter's cameras see);
- the clouds behind the surfaces stay in the World's camera image, seen where an edge lets the sky through.

Frames where no surface stands behind a cloud and nothing blurs keep the background alone, as before.
"""

from __future__ import annotations

import time

import bpy
import numpy as np
from mathutils import Matrix

from ...core import composition
from ...render import depthpass, engine
from ..scene import cloudstate, sceneparams, surfaces

VEIL_NAME = "Nubis Cloud Veil"
VEIL_IMAGE = "Nubis Veil Clouds"
VEIL_MATERIAL = "Nubis Cloud Veil"
# A veil pixel this opaque or more over a surface makes the frame need the veil.
VISIBLE_ALPHA = 1.0 / 255.0
# The widest band the shutter may add on each side, as a share of the frame's larger side.
MAX_BLUR_SHARE = 0.5

UNIT_SQUARE = ((-0.5, -0.5, 0.0), (0.5, -0.5, 0.0), (0.5, 0.5, 0.0), (-0.5, 0.5, 0.0))  # a render quad's corners
# What the last frame's composition did, for the benchmark and the tests: whether it needed the veil, the
# margin it widened the frame by (pixels) and the veil's distance (metres).
last_frame: dict[str, float] = {}
_changed: dict[str, dict[str, int]] = {}  # scene name -> the render settings changed for the veil, as they were


def fallback(scene) -> str:
    """Why this scene's render keeps the clouds as a background only, or "" when they are composed."""
    cam = scene.camera
    if cam is None or cam.type != "CAMERA":
        return "the scene camera is not a camera"
    if getattr(cam.data, "type", "PERSP") == "PANO":
        return "a panoramic camera sees the clouds as a background only (docs/limits.md)"
    return ""


def write_image(name: str, pixels: np.ndarray) -> bpy.types.Image:
    """Float RGBA pixels (bottom row first) into a generated image, made or resized as needed. Scene
    linear, not packed: renders make them again."""
    h, w = pixels.shape[:2]
    img = bpy.data.images.get(name)
    if img is None or tuple(img.size) != (w, h) or not img.is_float:
        if img is not None:
            bpy.data.images.remove(img)
        img = bpy.data.images.new(name, w, h, alpha=True, float_buffer=True)
    # Data as stored: the premultiplied light and the alpha as two channels, no conversion on reading.
    img.colorspace_settings.name = "Non-Color"
    img.alpha_mode = "CHANNEL_PACKED"
    img.pixels.foreach_set(np.ascontiguousarray(pixels, dtype=np.float32).ravel())
    img.update()
    return img


def _forward_matrix(scene, frame: composition.Frame) -> np.ndarray:
    """The camera's own view-projection (its clipping planes included) for the widened frame."""
    cam = scene.camera
    depsgraph = bpy.context.evaluated_depsgraph_get()
    proj = cam.evaluated_get(depsgraph).calc_matrix_camera(
        depsgraph, x=frame.width, y=frame.height, scale_x=1.0, scale_y=1.0
    )
    view = np.linalg.inv(np.array(sceneparams.evaluated_matrix(cam).normalized(), np.float64))
    w, h = frame.size
    widen = np.diag([frame.width / w, frame.height / h, 1.0, 1.0])
    return widen @ np.array(proj, np.float64) @ view


def shutter_margin(scene, inv_view_proj, width: int, height: int) -> int:
    """Pixels the veil is widened by for camera motion blur: what the cameras at the shutter's opening and
    closing see beyond the frame. 0 without motion blur or with a zero shutter."""
    r = scene.render
    if not r.use_motion_blur or r.motion_blur_shutter <= 0.0:
        return 0
    position = getattr(r, "motion_blur_position", "CENTER")
    half = r.motion_blur_shutter
    offsets = {"START": (0.0, half), "END": (-half, 0.0)}.get(position, (-half / 2, half / 2))
    frame, sub = scene.frame_current, scene.frame_subframe
    invs = []
    try:
        for offset in offsets:
            t = frame + sub + offset
            scene.frame_set(int(np.floor(t)), subframe=float(t - np.floor(t)))
            invs.append(np.array(cloudstate.camera_inv_view_proj(scene, width, height)))
    finally:
        scene.frame_set(frame, subframe=sub)
    limit = int(MAX_BLUR_SHARE * max(width, height))
    return composition.blur_margin(inv_view_proj, invs, width, height, limit)


def split_clouds(scene, shot, clouds) -> np.ndarray:
    """The frame's clouds for the render World's camera image (top row first); when the frame needs the
    veil (a surface behind a cloud, or camera motion blur) it is placed with the clouds in front of the
    surfaces, else hidden."""
    w, h = shot.width, shot.height
    margin = composition.FILTER_MARGIN + shutter_margin(scene, shot.inv_view_proj, w, h)
    frame = composition.widened(np.array(shot.inv_view_proj), w, h, margin)
    ww, hh = frame.size
    inv = Matrix(frame.inv_view_proj.tolist())
    start = time.perf_counter()
    with depthpass.scene_hits(surfaces.camera_meshes(scene), _forward_matrix(scene, frame), ww, hh) as (
        hit_texture,
        hits,
    ):
        drawn = time.perf_counter()
        clouds.update(shot.state)
        near, far = engine.render_split(clouds, inv, shot.eye, hit_texture, ww, hh)
    marched = time.perf_counter()
    inside = (slice(margin, margin + h), slice(margin, margin + w))  # bottom row first
    surface = hits[..., 3] > 0.5
    veiled = bool((near[..., 3][surface] > VISIBLE_ALPHA).any())
    last_frame.clear()
    last_frame.update(veil=float(veiled or margin > composition.FILTER_MARGIN), margin=float(margin))
    if not last_frame["veil"]:
        stow_veil(scene)
        whole = near + (1.0 - near[..., 3:4]) * far
        clouds_image = whole[inside][::-1].copy()
    else:
        place(scene, frame, hits, near)
        clouds_image = far[inside][::-1].copy()
    last_frame.update(depth_s=drawn - start, march_s=marched - drawn, veil_s=time.perf_counter() - marched)
    return clouds_image


def place(scene, frame: composition.Frame, hits: np.ndarray, near: np.ndarray) -> bpy.types.Object:
    """The veil in front of the nearest surface the widened frame shows, carrying `near`."""
    cam = scene.camera
    m = sceneparams.evaluated_matrix(cam).normalized()
    eye = np.array(m.translation, np.float64)
    forward = -np.array(m.to_3x3().col[2], np.float64)
    distance = composition.veil_distance(hits, eye, forward, cam.data.clip_start, cam.data.clip_end)
    corners = composition.veil_corners(frame, eye, forward, distance)
    last_frame["distance"] = distance
    image = write_image(VEIL_IMAGE, near)
    obj = _veil_object(scene, image)
    set_corners(obj, corners)
    obj.matrix_world = Matrix.Identity(4)
    show(obj)
    return obj


def _veil_object(scene, image=None) -> bpy.types.Object:
    """The veil, carrying `image` (None: no material yet, as ready() makes it)."""
    obj = render_quad(scene, VEIL_NAME, _veil_material(image) if image is not None else None)
    for ray in ("diffuse", "glossy", "transmission", "volume_scatter", "shadow"):
        setattr(obj, f"visible_{ray}", False)
    obj.visible_camera = True
    for probe in ("hide_probe_volume", "hide_probe_sphere", "hide_probe_plane"):
        if hasattr(obj, probe):
            setattr(obj, probe, True)
    return obj


def render_quad(scene, name: str, material) -> bpy.types.Object:
    """A square (UVs 0-1 over its corners) of Nubis's own that only renders see, with `material` (None:
    as it is): the veil, a shadow caster. Made once, then kept."""
    obj = bpy.data.objects.get(name)
    if obj is None or obj.type != "MESH":
        mesh = bpy.data.meshes.new(name)
        mesh.from_pydata(list(UNIT_SQUARE), [], [(0, 1, 2, 3)])
        uv = mesh.uv_layers.new(name="UVMap")
        for loop, co in zip(uv.data, ((0, 0), (1, 0), (1, 1), (0, 1)), strict=True):
            loop.uv = co
        obj = bpy.data.objects.new(name, mesh)
    obj[surfaces.OWN_KEY] = True
    if obj.name not in scene.collection.objects:
        scene.collection.objects.link(obj)
    # Each only when it differs: a visibility set during a render, even to its own value, syncs the
    # view layer's bases under the render's dependency graph (docs/sky.md#render-animation).
    for key, value in (("hide_select", True), ("display_type", "WIRE"), ("hide_viewport", True)):
        if getattr(obj, key) != value:
            setattr(obj, key, value)  # hide_viewport: the viewport draws the clouds itself
    if material is None:
        return obj
    if not obj.data.materials:
        obj.data.materials.append(material)
    elif obj.data.materials[0] != material:
        obj.data.materials[0] = material
    return obj


# ---- a render object's visibility over a render -------------------------------------------------------
#
# Render Animation builds one dependency graph for all its frames before the first. An object whose render
# visibility changed between two frames (shown for one frame, hidden after it) made the next frame's
# update fail inside Blender (a segfault in deg_check_base_in_depsgraph). So Nubis's render objects are
# shown once when a render starts (ready), stowed when a frame does not need them (collapsed to a point:
# no ray meets them) and hidden when the render has ended (put_away).


def set_corners(obj, corners) -> None:
    """The quad's four corners (4, 3), object space."""
    obj.data.vertices.foreach_set("co", np.asarray(corners, np.float32).ravel())
    obj.data.update()


def collapsed(obj) -> bool:
    """Whether the quad's corners are at one point."""
    co = np.empty(len(obj.data.vertices) * 3, np.float32)
    obj.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    return bool((co == co[0]).all())


def stowed(obj) -> bool:
    """Whether no ray of a render meets the quad: collapsed, or out of renders, or not there."""
    return obj is None or obj.hide_render or collapsed(obj)


def stow(obj) -> None:
    """Out of this frame without a change of visibility: its corners at one point, and no material, so a
    render that never needs it compiles no shader for it (EEVEE: seconds a material on llvmpipe). A frame
    that places it gives the material back (render_quad)."""
    if obj is None:
        return
    if not collapsed(obj):
        set_corners(obj, np.zeros((4, 3)))
    if obj.data.materials:
        obj.data.materials.clear()


def show(obj) -> None:
    """Into the render. Already so for the whole render once ready() has run; a render that started
    without it (no render_init) changes the visibility here, once."""
    if obj.hide_render:
        obj.hide_render = False


def put_away(obj) -> None:
    """Out of renders and of the saved file's renders, once the render has ended."""
    if obj is not None and not obj.hide_render:
        obj.hide_render = True


def image_material(name: str, image, interpolation: str):
    """The material `name`, emptied, with one Image Texture node reading `image` (data as stored, edges
    extended); returns the material, its node tree and that node."""
    mat = bpy.data.materials.get(name) or bpy.data.materials.new(name)
    if mat.node_tree is None:
        mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = image
    tex.extension = "EXTEND"
    tex.interpolation = interpolation
    return mat, nt, tex


RECIPE_KEY = "nubis_recipe"  # a render material's ID property: which of Nubis's materials it was built as


def built(name: str, recipe: str, image) -> bpy.types.Material | None:
    """The material `name` when it was built as `recipe` and reads `image`: kept as it is, so a frame of an
    animation rebuilds no node tree (EEVEE would compile its shader again) when only the pixels changed."""
    mat = bpy.data.materials.get(name)
    if mat is None or mat.get(RECIPE_KEY) != recipe or mat.node_tree is None:
        return None
    texs = [n for n in mat.node_tree.nodes if n.type == "TEX_IMAGE"]
    return mat if len(texs) == 1 and texs[0].image == image else None


def _veil_material(image) -> bpy.types.Material:
    """The clouds' light as emission and what they let through as transparency: premultiplied `over`,
    exact in both engines. Closest texels, so an edge's samples each take their own pixel's clouds."""
    if (kept := built(VEIL_MATERIAL, "veil", image)) is not None:
        return kept
    mat, nt, tex = image_material(VEIL_MATERIAL, image, "Closest")
    mat[RECIPE_KEY] = "veil"
    light = nt.nodes.new("ShaderNodeEmission")
    light.inputs["Strength"].default_value = 1.0
    nt.links.new(tex.outputs["Color"], light.inputs["Color"])
    through = nt.nodes.new("ShaderNodeMath")
    through.operation = "SUBTRACT"
    through.inputs[0].default_value = 1.0
    nt.links.new(tex.outputs["Alpha"], through.inputs[1])
    clear = nt.nodes.new("ShaderNodeBsdfTransparent")
    nt.links.new(through.outputs[0], clear.inputs["Color"])
    add = nt.nodes.new("ShaderNodeAddShader")
    nt.links.new(light.outputs[0], add.inputs[0])
    nt.links.new(clear.outputs[0], add.inputs[1])
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(add.outputs[0], out.inputs["Surface"])
    mat.use_backface_culling = False
    if hasattr(mat, "cycles") and hasattr(mat.cycles, "emission_sampling"):
        mat.cycles.emission_sampling = "NONE"  # its light is for the camera's rays, not a lamp for the scene
    return finished(mat, "BLENDED")


def finished(mat, method: str) -> bpy.types.Material:
    """`mat` with EEVEE's render method (BLENDED, DITHERED) and its nodes laid out in a row."""
    mat.surface_render_method = method
    for i, node in enumerate(mat.node_tree.nodes):
        node.location = (i * 220, 0)
    return mat


def ready(scene) -> None:
    """When a render with the clouds starts: the veil made (empty) if need be, shown and stowed, so no
    frame changes its visibility."""
    obj = scene.objects.get(VEIL_NAME) or _veil_object(scene)
    stow(obj)
    show(obj)


def stow_veil(scene) -> None:
    """This frame has no veil."""
    stow(scene.objects.get(VEIL_NAME))


def put_away_veil(scene) -> None:
    put_away(bpy.data.objects.get(VEIL_NAME))


def lend_bounces(scene, casters: int = 0) -> None:
    """Cycles counts the veil as one transparent bounce of every camera ray, and each shadow caster one of
    every shadow ray: as many more for this render (the veil's one and `casters`, those of a stack beyond
    its first), so the artist's own transparent surfaces keep theirs. Given back by give_back."""
    extra = casters + (0 if stowed(scene.objects.get(VEIL_NAME)) else 1)
    if scene.render.engine != "CYCLES" or extra == 0 or scene.name in _changed:
        return
    _changed[scene.name] = {"transparent_max_bounces": scene.cycles.transparent_max_bounces}
    scene.cycles.transparent_max_bounces += extra


def give_back(scene) -> None:
    """The settings lend_bounces changed, as the artist had them."""
    for key, value in _changed.pop(scene.name, {}).items():
        setattr(scene.cycles, key, value)
