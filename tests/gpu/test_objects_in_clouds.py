"""F12 with the scene's objects in the clouds (blender/f12/composition.py, docs/sky.md#objects-in-the-clouds): the
clouds between the camera and an object veil it in EEVEE and Cycles as Cycles veils it when it renders the
camera's bake of the same clouds; objects that rise into the layer receive the shadows of the clouds above
each point; the veil blurs with the camera over the shutter. Judged on display-referred PNGs (Rec. 709
luminance, 0-1), at a small size."""

from __future__ import annotations

import math

import numpy as np
import pytest

W, H = 96, 54
REC709 = np.array([0.2126, 0.7152, 0.0722])
# A pixel counts as veiled when the clouds change its luminance by more than this (the measure).
VEILED = 0.05


def _material(blender, name: str, colour, emission: bool):
    """An emission-only material (the clouds' shadows leave it alone), or a diffuse one."""
    mat = blender.data.materials.new(name)
    if mat.node_tree is None:
        mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    if emission:
        shader = nt.nodes.new("ShaderNodeEmission")
        shader.inputs["Strength"].default_value = 1.0
    else:
        shader = nt.nodes.new("ShaderNodeBsdfDiffuse")
    shader.inputs["Color"].default_value = (*colour, 1.0)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(shader.outputs[0], out.inputs["Surface"])
    return mat


def _scene(blender, case: str, emission: bool = True):
    """The default cloudscape with one object and the camera placed for `case`:
    below: a 5 km cone 16 km ahead of a camera 1 km up, piercing the layer;
    above: a camera 6 km up looking down on a ground plane through the layer;
    inside: a 6 km long wall crossing the layer 3 km ahead of a camera inside it, through a cloud."""
    from nubis_addon.blender import ensure_registered

    blender.ops.wm.read_factory_settings(use_empty=True)
    ensure_registered()
    assert blender.ops.nubis.new_cloudscape(preset="default") == {"FINISHED"}
    scene = blender.context.scene
    cam = scene.camera
    if case == "below":
        blender.ops.mesh.primitive_cone_add(vertices=64, radius1=6000.0, depth=5000.0, location=(0, 16000, 2500))
        cam.location, rotation = (0.0, 0.0, 1000.0), 92.0
    elif case == "above":
        blender.ops.mesh.primitive_plane_add(size=60000.0, location=(0.0, 15000.0, 0.0))
        cam.location, rotation = (0.0, 0.0, 6000.0), 55.0
    else:
        blender.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 3000.0, 2000.0), scale=(6000.0, 60.0, 150.0))
        cam.location, rotation = (0.0, 0.0, 2000.0), 90.0
    obj = blender.context.object
    obj.data.materials.append(_material(blender, f"{case} surface", (0.3, 0.15, 0.08), emission))
    cam.rotation_euler = (math.radians(rotation), 0.0, 0.0)
    cam.data.lens, cam.data.clip_end = 30.0, 100000.0
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = W, H, 100
    r.image_settings.file_format = "PNG"
    r.image_settings.color_mode = "RGBA"
    scene.cycles.device, scene.cycles.use_denoising = "CPU", False
    scene.eevee.taa_render_samples = 4
    # EEVEE's virtual shadow maps at a quarter of their resolution: the frames are tiny, and at full
    # resolution the shadows took two thirds of each EEVEE frame on llvmpipe.
    scene.eevee.shadow_resolution_scale = 0.25
    scene.nubis.sky_environment_width = 128
    scene.nubis.sky_shadow_resolution = 256
    return scene, obj


def _engine(blender, engine: str) -> str:
    from nubis_addon.blender.f12 import scene_render

    if engine == "CYCLES":
        return engine
    engines = {e.identifier for e in blender.types.RenderSettings.bl_rna.properties["engine"].enum_items}
    return next(e for e in ("BLENDER_EEVEE_NEXT", "BLENDER_EEVEE") if e in scene_render.ENGINES and e in engines)


def _render(blender, scene, engine: str, path, samples: int = 16) -> np.ndarray:
    """F12 to a display-referred PNG; RGBA 0-1, top row first. The World and the Cycles settings the veil
    borrows are the artist's again afterwards."""
    from nubis_addon.core import imageio

    scene.render.engine = _engine(blender, engine)
    scene.cycles.samples = samples
    scene.render.filepath = str(path)
    world, bounces = scene.world, scene.cycles.transparent_max_bounces
    blender.ops.render.render(write_still=True)
    assert scene.world == world and scene.cycles.transparent_max_bounces == bounces
    return imageio.read_image(path)


def _luminance(rgba: np.ndarray) -> np.ndarray:
    return rgba[..., :3] @ REC709


def _without_clouds(blender, scene, path) -> tuple[np.ndarray, np.ndarray]:
    """The object's own pixels (a transparent film, clouds off) and their luminance."""
    scene.nubis.sky_render_clouds = False
    scene.render.film_transparent = True
    try:
        rgba = _render(blender, scene, "CYCLES", path, samples=2)
    finally:
        scene.nubis.sky_render_clouds = True
        scene.render.film_transparent = False
    return rgba[..., 3] > 0.99, _luminance(rgba)


def _bake_reference(blender, scene, tmp) -> np.ndarray:
    """Cycles rendering the camera's bake of the same clouds (the World's sky, no Nubis background); 64
    samples: at 32 its own noise inside a cloud was most of the difference measured against it."""
    from nubis_addon.blender.jobs import pipeline
    from nubis_addon.blender.scene import cycles_setup
    from nubis_addon.core.jobs import BakeOptions

    vdb = tmp / "camera.vdb"
    pipeline.bake(scene, vdb, BakeOptions(camera_only=True, voxel_size=80.0, size=(W, H)))
    cycles_setup.import_volume(scene, str(vdb))
    scene.cycles.volume_bounces = 16
    scene.cycles.max_bounces = max(scene.cycles.max_bounces, 16)
    try:
        return _luminance(_render(blender, scene, "CYCLES", tmp / "reference.png", samples=64))
    finally:
        cycles_setup.remove_volume(scene)


@pytest.fixture(scope="module", params=["below", "above", "inside"])
def veiled(request, blender, tmp_path_factory):
    """Per case: the object's mask and unclouded luminance, the bake's reference and F12's renders."""
    case = request.param
    tmp = tmp_path_factory.mktemp(f"veil_{case}")
    scene, _obj = _scene(blender, case)
    mask, clear = _without_clouds(blender, scene, tmp / "clear.png")
    reference = _bake_reference(blender, scene, tmp)
    # EEVEE on the mountain only: its shader compiles cost a software rasterizer most of a minute per scene.
    engines = ("CYCLES", "EEVEE") if case == "below" else ("CYCLES",)
    from nubis_addon.blender.f12 import composition

    renders = {}
    for engine in engines:
        renders[engine] = _luminance(_render(blender, scene, engine, tmp / f"{engine}.png"))
        assert composition.last_frame["veil"] == 1.0, (case, engine, composition.last_frame)
    return case, mask, clear, reference, renders


def test_the_clouds_veil_an_object_as_cycles_veils_it_in_the_bake(veiled):
    case, mask, clear, reference, renders = veiled
    assert mask.sum() > 100, (case, mask.sum())
    share_ref = float((np.abs(reference - clear)[mask] > VEILED).mean())
    assert share_ref > 0.05, (case, share_ref)  # the scene has clouds in front of the object
    for engine, lum in renders.items():
        share = float((np.abs(lum - clear)[mask] > VEILED).mean())
        mean_diff = float(np.abs(lum - reference)[mask].mean())
        # Measured at 96x54 (docs/measurements.md#objects-in-the-clouds): within 10 % and 0.015.
        print(f"{case} {engine}: veiled share {share:.3f} (bake {share_ref:.3f}), mean difference {mean_diff:.4f}")
        assert abs(share - share_ref) <= 0.3 * share_ref, (case, engine, share, share_ref)
        assert mean_diff <= 0.025, (case, engine, mean_diff)


def test_without_an_object_in_the_clouds_the_render_keeps_its_background(blender, tmp_path):
    """No surface behind a cloud and no motion blur: no veil, the World's image holds all the clouds."""
    from nubis_addon.blender.f12 import composition

    scene, obj = _scene(blender, "below")
    obj.location.y = -16000.0  # behind the camera
    _render(blender, scene, "CYCLES", tmp_path / "sky.png", samples=2)
    assert composition.last_frame["veil"] == 0.0, composition.last_frame
    veil = blender.data.objects.get(composition.VEIL_NAME)
    assert veil is None or (veil.hide_render and composition.collapsed(veil))


def _box_blur_length(sharp: np.ndarray, blurred: np.ndarray, rows: np.ndarray) -> float:
    """The width (pixels) of the horizontal box that best turns `sharp` into `blurred` on these rows."""
    best, best_err = 0.0, np.inf
    for width in np.arange(1.0, 40.0, 0.5):
        n = int(np.ceil(width)) | 1
        kernel = np.ones(n)
        kernel[[0, -1]] = (width - (n - 2)) / 2 if n > 1 else 1.0
        kernel /= kernel.sum()
        smooth = np.array([np.convolve(row, kernel, mode="same") for row in sharp])
        inner = slice(20, sharp.shape[1] - 20)  # away from the frame's edges
        err = float(np.mean((smooth[rows, inner] - blurred[rows, inner]) ** 2))
        if err < best_err:
            best, best_err = width, err
    return best


def test_a_fast_pan_blurs_the_clouds_as_far_as_the_ground(blender, tmp_path):
    """Camera motion blur: the veil is world geometry the shutter's cameras see, so the clouds' edges are
    spread along a pan as far as the ground's texture edges. Measured apart: the clouds over a plain ground,
    then the checkered ground without clouds; each the box along the pan that turns the still frame into
    the blurred one."""
    from nubis_addon.blender.f12 import composition
    from nubis_addon.core.composition import FILTER_MARGIN

    scene, ground = _scene(blender, "above")
    emission = next(n for n in ground.data.materials[0].node_tree.nodes if n.type == "EMISSION")
    cam = scene.camera
    for frame, turn in ((1, 0.0), (2, math.radians(6.0))):
        cam.rotation_euler.z = turn
        cam.keyframe_insert("rotation_euler", index=2, frame=frame)
    for curve in _fcurves(cam):
        curve.extrapolation = "LINEAR"
        for key in curve.keyframe_points:
            key.interpolation = "LINEAR"
    scene.frame_set(1)
    scene.render.motion_blur_shutter = 1.0

    def still_and_blurred(tag: str) -> tuple[np.ndarray, np.ndarray]:
        scene.render.use_motion_blur = False
        still = _luminance(_render(blender, scene, "CYCLES", tmp_path / f"{tag}_still.png", samples=32))
        scene.render.use_motion_blur = True
        blurred = _luminance(_render(blender, scene, "CYCLES", tmp_path / f"{tag}_blurred.png", samples=32))
        return still, blurred

    along_clouds = _box_blur_length(*still_and_blurred("clouds"), np.arange(H))
    assert composition.last_frame["veil"] == 1.0 and composition.last_frame["margin"] > FILTER_MARGIN
    checker = ground.data.materials[0].node_tree.nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 40.0  # 1.5 km squares: several pixels each
    ground.data.materials[0].node_tree.links.new(checker.outputs["Color"], emission.inputs["Color"])
    scene.nubis.sky_render_clouds = False
    along_ground = _box_blur_length(*still_and_blurred("ground"), np.arange(H))
    print(f"blur along the pan: the clouds {along_clouds:.1f} px, the ground {along_ground:.1f} px")
    assert along_ground > 3.0, along_ground
    assert abs(along_clouds - along_ground) <= 0.3 * along_ground, (along_clouds, along_ground)


def _fcurves(obj):
    """The object's F-curves: an action's own, or its channelbag's (Blender 5's layered actions)."""
    action = obj.animation_data.action
    if getattr(action, "fcurves", None) is not None and len(action.fcurves):
        return list(action.fcurves)
    return [c for layer in action.layers for strip in layer.strips for bag in strip.channelbags for c in bag.fcurves]


def _stack_transmittance(blender, scene, points: np.ndarray) -> np.ndarray:
    """The product of the casters' maps a shadow ray from each point crosses on its way to the sun."""
    from nubis_addon.blender.f12 import shadows

    sun = np.array(scene.objects["Nubis Sun"].matrix_world.to_3x3().col[2])
    total = np.ones(len(points))
    index = 0
    for caster in shadows.in_use(scene):
        m = np.array(caster.matrix_world)
        origin, u, v = m[:3, 3], m[:3, 0], m[:3, 1]
        above = points[:, 2] < origin[2]
        s = (origin[2] - points[:, 2]) / sun[2]
        q = points + s[:, None] * sun - origin
        img = blender.data.images[caster.name]
        res = img.size[0]
        tmap = np.array(img.pixels[:], np.float32).reshape(res, res, 4)[..., 0]
        x = np.clip((((q @ u) / (u @ u) + 0.5) * res).astype(int), 0, res - 1)
        y = np.clip((((q @ v) / (v @ v) + 0.5) * res).astype(int), 0, res - 1)
        total = np.where(above, total * tmap[y, x], total)
        index += 1
    assert index > 3, index  # a stack through the layer, not one caster above the peak
    return total


@pytest.mark.parametrize("engine", ["CYCLES", "EEVEE"])
def test_a_peak_in_the_layer_is_shaded_where_clouds_stand_between_it_and_the_sun(blender, engine, tmp_path):
    """The shadow a point of the flank receives is the clouds' transmittance from that point towards the
    sun: a stack of casters through the layer, not one above the peak (which left the flank unshaded)."""
    from mathutils import Vector

    from nubis_addon.blender.scene import cloudstate

    scene, mountain = _scene(blender, "below", emission=False)
    # The sun from the side: the flank the camera sees is in sun, and the clouds' shadows fall beside them.
    sun = scene.objects["Nubis Sun"]
    sun.rotation_euler = (0.0, 0.0, 0.0)
    sun.rotation_euler = Vector((0.8, -0.2, 0.55)).to_track_quat("Z", "Y").to_euler()
    lit = _render(blender, scene, engine, tmp_path / "shadows.png")
    floor = cloudstate.state_from_scene(scene).shell()[0]
    points = _visible_points(blender, scene, mountain)
    inside = ~np.isnan(points[..., 0]) & (points[..., 2] > floor) & (_veil_alpha(blender) < 0.1)
    transmittance = np.full(inside.shape, np.nan)
    transmittance[inside] = _stack_transmittance(blender, scene, points[inside])
    scene.nubis.sky_shadows = False
    try:
        unshaded = _render(blender, scene, engine, tmp_path / "no_shadows.png")
    finally:
        scene.nubis.sky_shadows = True
    ratio = _luminance(lit) / np.maximum(_luminance(unshaded), 1e-3)
    shaded, sunny = inside & (transmittance < 0.5), inside & (transmittance > 0.9)
    assert shaded.sum() >= 8 and sunny.sum() >= 8, (shaded.sum(), sunny.sum())
    # Measured at 96x54: 0.86 against 1.00 in Cycles, 0.94 against 1.00 in EEVEE (a display-referred ratio:
    # the sky's light stays in the shade, and the view transform compresses).
    assert ratio[shaded].mean() < 0.97 * ratio[sunny].mean(), (engine, ratio[shaded].mean(), ratio[sunny].mean())


def _veil_alpha(blender) -> np.ndarray:
    """The last frame's veil opacity per pixel (top row first): the shadow on a pixel behind a cloud hides
    behind the cloud's own light."""
    from nubis_addon.blender.f12 import composition

    img = blender.data.images[composition.VEIL_IMAGE]
    m = int(composition.last_frame["margin"])
    alpha = np.array(img.pixels[:], np.float32).reshape(img.size[1], img.size[0], 4)[..., 3]
    return alpha[m : m + H, m : m + W][::-1]


def _visible_points(blender, scene, obj) -> np.ndarray:
    """The point of `obj` each pixel's centre sees (top row first), NaN where the pixel sees anything else."""
    from mathutils import Vector

    from nubis_addon.blender.scene import cloudstate
    from nubis_addon.core import sky as skymath

    inv = cloudstate.camera_inv_view_proj(scene, W, H)
    eye = cloudstate.camera_eye(scene)
    dirs = skymath.camera_directions(inv, eye, W, H)
    depsgraph = blender.context.evaluated_depsgraph_get()
    points = np.full((H, W, 3), np.nan)
    for y in range(H):
        for x in range(W):
            hit, where, _n, _i, what, _m = scene.ray_cast(depsgraph, Vector(eye[:3]), Vector(dirs[y, x]))
            if hit and what.original == obj:
                points[y, x] = where
    return points


@pytest.mark.parametrize("kind", ["ORTHO", "PANO", "zero shutter"])
def test_other_cameras_render_with_the_clouds_and_the_world_back(blender, kind, tmp_path):
    """An orthographic camera is composed like a perspective one; a panoramic camera keeps the clouds as a
    background (a documented fallback, said once on the console); motion blur with a zero shutter renders
    as a still. No traceback, the World and the Cycles settings as they were (_render checks those)."""
    from nubis_addon.blender.f12 import composition, scene_render

    scene, _obj = _scene(blender, "below")
    cam = scene.camera
    if kind == "ORTHO":
        cam.data.type, cam.data.ortho_scale = "ORTHO", 20000.0
        cam.location.y = -20000.0
    elif kind == "PANO":
        cam.data.type = "PANO"
        if hasattr(cam.data, "panorama_type"):
            cam.data.panorama_type = "EQUIRECTANGULAR"
        else:
            cam.data.cycles.panorama_type = "EQUIRECTANGULAR"
    else:
        scene.render.use_motion_blur, scene.render.motion_blur_shutter = True, 0.0
    scene.render.resolution_x, scene.render.resolution_y = 48, 27
    composition.last_frame.clear()
    scene_render.last_error.clear()
    rgba = _render(blender, scene, "CYCLES", tmp_path / "render.png", samples=2)
    assert rgba.shape == (27, 48, 4) and np.isfinite(rgba).all()
    assert not scene_render.last_error, scene_render.last_error
    if kind == "PANO":
        assert not composition.last_frame  # the background path: no composition ran
    else:
        assert composition.last_frame["veil"] == 1.0 and composition.last_frame["margin"] == 4.0


def _display(rgb: np.ndarray) -> np.ndarray:
    """Scene-linear to display-referred luminance (the sRGB curve; the scenes here use the Standard view)."""
    lum = np.clip(rgb[..., :3] @ REC709, 0.0, None)
    return np.where(lum <= 0.0031308, 12.92 * lum, 1.055 * np.power(lum, 1 / 2.4) - 0.055)


def test_the_viewport_veils_the_peak_as_f12_does(blender, tmp_path):
    """The 3D viewport's draw path (as `preview` replays it) with the scene's depth: the clouds in front of
    the peak's flanks are laid over it as EEVEE's F12 lays them
    (docs/viewport.md#clouds-in-front-of-the-scene): the share of the peak's pixels the clouds change by
    more than 0.05 within 0.8-1.25x of F12's, and the peak's pixels within 0.03 of F12's on average
    (display-referred)."""
    from nubis_addon.blender.host import runtime
    from nubis_addon.blender.jobs import preview
    from nubis_addon.blender.scene import cloudstate
    from nubis_addon.render import temporal

    scene, _obj = _scene(blender, "below")
    mask, _lum = _without_clouds(blender, scene, tmp_path / "mask.png")
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "OPEN_EXR"
    f12 = _render(blender, scene, "EEVEE", tmp_path / "f12.exr")
    scene.nubis.sky_render_clouds = False
    try:
        clear = _render(blender, scene, "EEVEE", tmp_path / "clear.exr")
    finally:
        scene.nubis.sky_render_clouds = True
    view = preview.camera_view(scene, W, H)
    clouds = runtime.cloud_gpu(scene.nubis.noise_seed)
    state = cloudstate.state_from_scene(scene)
    tv = temporal.TemporalViewport()
    with preview.scene_depth(scene, view) as (deep, depth):
        for _ in range(16 * 8):
            tv.redraw(clouds, state, deep, 1.0, 8, depth=depth, depth_key=1)
        assert tv.converged
        shown = temporal.render_view(tv, clouds, deep)
    tv.free()
    over = shown[..., :3] + (1.0 - shown[..., 3:4]) * clear[..., :3]
    base, view_lum, f12_lum = _display(clear), _display(over), _display(f12)
    share_f12 = float((np.abs(f12_lum - base)[mask] > VEILED).mean())
    share_view = float((np.abs(view_lum - base)[mask] > VEILED).mean())
    mean_diff = float(np.abs(view_lum - f12_lum)[mask].mean())
    print(f"veiled share: viewport {share_view:.3f}, F12 {share_f12:.3f}; mean difference {mean_diff:.4f}")
    assert share_f12 > 0.05, share_f12  # clouds stand in front of the peak
    assert 0.8 * share_f12 <= share_view <= 1.25 * share_f12, (share_view, share_f12)
    assert mean_diff <= 0.03, mean_diff


def _silhouette_band(covered: np.ndarray, reach: int = 2) -> np.ndarray:
    """The pixels within `reach` pixels of where covered meets uncovered."""
    band = np.zeros_like(covered)
    for dy in range(-reach, reach + 1):
        for dx in range(-reach, reach + 1):
            band |= np.roll(np.roll(covered, dy, 0), dx, 1) != covered
    return band


def _orbit(blender, scene, degrees: float, centre=(0.0, 16000.0)) -> None:
    """Move the camera about the vertical through `centre` (x, y), turning it with its path."""
    from mathutils import Matrix

    c = Matrix.Translation((*centre, 0.0))
    turn = c @ Matrix.Rotation(math.radians(degrees), 4, "Z") @ c.inverted()
    scene.camera.matrix_world = turn @ scene.camera.matrix_world
    blender.context.view_layer.update()


def test_an_orbit_around_the_peak_leaves_no_veil_behind_at_its_silhouette(blender):
    """The viewport's history while the camera orbits the peak (24 frames half a degree of arc apart, 140 m
    each, 4 redraws a frame, as a moving view redraws): on the peak's pixels at its silhouette the clouds
    are no more opaque than the frame's own march says on average (the history of the sky beside it is not
    reprojected onto it), and at most 6 % of them are off by 0.1. Measured at 96x54: a bias of -0.003 and
    4.6 % off (7.6 % of the peak's inner pixels, 12 % of the sky's); reprojecting across the silhouette as
    before read +0.004 and 4.5 % (docs/viewport.md#clouds-in-front-of-the-scene)."""
    from nubis_addon.blender.host import runtime
    from nubis_addon.blender.jobs import preview
    from nubis_addon.blender.scene import cloudstate
    from nubis_addon.render import temporal

    scene, _obj = _scene(blender, "below")
    clouds = runtime.cloud_gpu(scene.nubis.noise_seed)
    moving = temporal.TemporalViewport()
    _orbit(blender, scene, -6.0)
    sums = np.zeros(5)
    for frame in range(24):
        if frame:
            _orbit(blender, scene, 0.5)
        view = preview.camera_view(scene, W, H)
        state = cloudstate.state_from_scene(scene)
        with preview.scene_depth(scene, view) as (deep, depth):
            for _ in range(4):
                moving.redraw(clouds, state, deep, 1.0, 1, depth=depth, depth_key=frame)
            shown = moving.read_history()[..., 3]
            still = temporal.TemporalViewport()
            for _ in range(16):  # every pixel marched once: the frame's own march
                still.redraw(clouds, state, deep, 1.0, 1, depth=depth, depth_key=frame)
            march = still.read_history()[..., 3]
            still.free()
            # Through a list: the buffer's own strides differ between Blender's lines.
            covered = np.array(depth.read().to_list(), np.float32).reshape(H, W)[::-1] < 1.0
        band = _silhouette_band(covered)
        edge, inner = band & covered, covered & ~band
        diff = shown - march
        sums += (diff[edge].sum(), edge.sum(), (diff[edge] > 0.1).sum(), (diff[inner] > 0.1).sum(), inner.sum())
    moving.free()
    bias, off, off_inside = sums[0] / sums[1], sums[2] / sums[1], sums[3] / sums[4]
    print(f"silhouette: bias {bias:+.4f}, {off:.1%} off by 0.1 (inside {off_inside:.1%})")
    assert sums[1] > 1000 and sums[4] > 1000, sums
    assert bias <= 0.0, bias
    assert off <= 0.06, (off, off_inside)
