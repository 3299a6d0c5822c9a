"""The headless pipeline shared by the operators and the command line: render, bake, Cycles, compare."""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import bpy
import numpy as np
from mathutils import Matrix

from ...core import bakeplan, camera, imageio, interrupt, limits, staging, vdbwrite
from ...core import sky as skymath
from ...core.bakeplan import BakePlan, measured_share
from ...core.errors import NubisError
from ...core.fsutil import check_output_path
from ...core.jobs import BakeOptions, RenderOptions
from ...core.state import MAX_STORMS, CloudState
from ...render import bake as gpu_bake
from ...render import engine, offscreens
from ..host import runtime
from ..scene import cloudstate, cycles_setup, datafield, sceneparams, skycapture, vdbclouds
from . import snapshot, sun_air
from .snapshot import BakeSnapshot

Progress = Callable[[float], None]


def ocio_config() -> str:
    return os.path.join(bpy.utils.resource_path("LOCAL"), "datafiles", "colormanagement", "config.ocio")


def sky_background(scene, width: int, height: int) -> np.ndarray:
    """The World as the scene camera sees it behind the clouds (H, W, 3), top row first: the World's
    capture (blender/scene/sky.py) looked up along each pixel's view ray."""
    if scene.camera is None:
        return np.broadcast_to(np.asarray(cloudstate.world_ambient(scene), np.float32), (height, width, 3))
    env = skycapture.environment(scene)
    if env.shape[0] > 4 or env.shape[1] > 8:  # not one colour: a sharper capture for pictures
        env = skycapture.capture_world(scene, skycapture.BACKGROUND_WIDTH, samples=4)
    inv = cloudstate.camera_inv_view_proj(scene, width, height)
    dirs = skymath.camera_directions(inv, cloudstate.camera_eye(scene), width, height)
    return skymath.sample(env, dirs).astype(np.float32)


def display_image(scene, rgba: np.ndarray) -> np.ndarray:
    """What the artist sees: the clouds over the World's sky, through the scene's view transform."""
    background = sky_background(scene, rgba.shape[1], rgba.shape[0])
    return imageio.to_display(
        imageio.composite_over(rgba, background), scene.view_settings.view_transform, ocio_config()
    )


def save_render(scene, path: str | os.PathLike, rgba: np.ndarray) -> Path:
    """EXR keeps scene-linear premultiplied RGBA; PNG is display-referred over the sky."""
    path = Path(path)
    if path.suffix.lower() == ".exr":
        return imageio.write_image(path, rgba)
    return imageio.write_image(path, display_image(scene, rgba))


def check_scene(scene) -> None:
    """What a saved scene may hold beyond what the renderer serves (presets are checked on load):
    the camera and the storms within reach, at most four storms, at most 128 field layers, VDB clouds that
    can be drawn."""
    settings = scene.nubis
    limits.check_count(
        "superstorms", len(settings.storms), MAX_STORMS, f"remove {len(settings.storms) - MAX_STORMS} of them"
    )
    limits.check_count("field layers", len(settings.layers), limits.MAX_FIELD_LAYERS, "merge or remove layers")
    if scene.camera is not None:
        limits.check_position(
            f"the camera '{scene.camera.name}'",
            sceneparams.evaluated_matrix(scene.camera).translation,
            "move it closer to the clouds",
        )
    for storm in settings.storms:
        if storm.empty is not None:
            limits.check_position(
                f"the storm '{storm.empty.name}'",
                sceneparams.evaluated_matrix(storm.empty).translation,
                "move it closer",
            )
    # The marked VDB clouds read (and cached) now: a damaged or oversized file is refused before any work.
    vdbclouds.placements(scene, strict=True)


def resolution(scene, width: int | None, height: int | None) -> tuple[int, int]:
    w = width or scene.render.resolution_x * scene.render.resolution_percentage // 100
    h = height or scene.render.resolution_y * scene.render.resolution_percentage // 100
    if not (4 <= w <= 16384 and 4 <= h <= 16384):
        raise NubisError(f"a {w}x{h} image is out of range: use a width and height between 4 and 16384")
    return w, h


# The two comparison modes of `compare`.
# single: one scattering event on both sides, the viewport's reference light march, no powder and no
#         multiple-scattering octaves, against Cycles with one volume bounce.
# full:   every viewport term against Cycles with REFERENCE_BOUNCES volume bounces (or the caller's).
COMPARE_MODES = ("single", "full")


@dataclass
class ViewportShot:
    """Everything a viewport render of the scene camera needs, detached from the scene: a script
    can change `state.params` and render again without touching Blender data."""

    state: CloudState
    inv_view_proj: object
    eye: tuple[float, float, float, float]
    noise_seed: int
    width: int
    height: int
    # Each pass's rays cross their pixels at a place of their own (camera.subpixel_offset), so passes
    # integrate the pixels' areas as Cycles' box filter does; off, every pass samples the centres.
    pixel_area: bool = False

    def pass_inverse(self, index: int):
        """The inverse view-projection of pass `index`."""
        if not self.pixel_area:
            return self.inv_view_proj
        dx, dy = camera.subpixel_offset(index)
        return Matrix(camera.shifted_inverse(self.inv_view_proj, dx, dy, self.width, self.height).tolist())


def viewport_shot(
    scene, width: int, height: int, light_mode: int = 0, mode: str = "", clip_box: tuple | None = None
) -> ViewportShot:
    """`mode` "single" or "full" prepares the shot for a comparison with Cycles; `clip_box` (x0, y0,
    x1, y1) keeps only the clouds inside a bake's box, so both renderers light the same clouds."""
    state = cloudstate.state_from_scene(scene)
    state.clip_box = clip_box
    # A full comparison's reference march measures the real-time light model's own optical depths.
    state.light_mode = 2 if light_mode == 1 and mode == "full" else light_mode
    if mode == "single":
        state.light_mode = 1
        # Physical single scattering: the sky is the world's radiance, not the real-time ambient's
        # tuned strength.
        state.params.update(lighting_ms_octaves=1, lighting_powder=0.0, lighting_ambient=1.0)
    if mode in COMPARE_MODES:
        # The atmosphere fade has no counterpart in the Cycles scene.
        state.params["lighting_fade_distance"] = 0.0
    inv = cloudstate.camera_inv_view_proj(scene, width, height)
    # The noise mip levels follow the pixel's footprint, as in the 3D viewport.
    state.pixel_angle, state.pixel_size = camera.pixel_footprint(np.array(inv), width, height)
    return ViewportShot(state, inv, cloudstate.camera_eye(scene), scene.nubis.noise_seed, width, height)


def render_shot(
    shot: ViewportShot, passes: int = 1, first_pass: int = 0, progress: Progress | None = None
) -> np.ndarray:
    """Premultiplied scene-linear RGBA, top row first. Offline, several passes with shifted jitter
    replace the viewport's grain with a converged image; `first_pass` starts later in the jitter
    sequence, so renders of disjoint passes are independent estimates of the same image. `progress`
    gets the fraction done after each tile."""
    # Run to its end here, between two looks at the interface: the shared GPU inputs (and the light
    # volumes they already hold) serve it; a stepped render gets its own (render_shot_steps).
    return run_steps(_render_run(shot, runtime.cloud_gpu(shot.noise_seed), max(1, passes), first_pass), progress)


def render_shot_steps(shot: ViewportShot, passes: int = 1, first_pass: int = 0):
    """render_shot as a generator yielding the fraction done after each tile, for the interface's modal
    Render Clouds; it returns the image. The shot is the snapshot (viewport_shot reads the scene once), and
    its GPU inputs are the render's own, made now (CloudGPU.fork): the 3D viewport's redraws meanwhile do
    not reach them. Closing it early frees the GPU's image and returns nothing."""
    clouds = runtime.cloud_gpu(shot.noise_seed).fork()
    return _render_run(shot, clouds, max(1, passes), first_pass)


def _render_run(shot: ViewportShot, clouds, passes: int, first_pass: int):
    total = None
    for k, i in enumerate(range(first_pass, first_pass + passes)):
        shot.state.jitter_pass = i
        clouds.update(shot.state)
        tiles = engine.render_offscreen_steps(clouds, shot.pass_inverse(i), shot.eye, shot.width, shot.height)
        try:
            while True:
                try:
                    fraction = next(tiles)
                except StopIteration as done:
                    frame = done.value
                    break
                yield (k + fraction) / passes
        finally:
            tiles.close()
        total = frame if total is None else total + frame
    return total / passes


def render_viewport(
    scene,
    width: int,
    height: int,
    light_mode: int = 0,
    mode: str = "",
    passes: int = 1,
    progress: Progress | None = None,
) -> np.ndarray:
    """The viewport's clouds from the scene camera: premultiplied scene-linear RGBA, top row first (a
    clipped or partial render: render_shot of a viewport_shot)."""
    return render_shot(viewport_shot(scene, width, height, light_mode, mode), passes, progress=progress)


def downsample(rgba: np.ndarray, factor: int) -> np.ndarray:
    """Box-filter an image by an integer factor (premultiplied values average correctly)."""
    if factor == 1:
        return rgba
    h, w, c = rgba.shape
    return rgba.reshape(h // factor, factor, w // factor, factor, c).mean(axis=(1, 3))


def render_files(scene, out: str | os.PathLike, options: RenderOptions, progress: Progress | None = None) -> np.ndarray:
    """The viewport's clouds to `out` (and their motion vectors to `options.motion`), the files together
    or not at all; returns the image (premultiplied scene-linear RGBA)."""
    with staging.output_set() as outputs:
        rgba = render_viewport(scene, options.width, options.height, passes=options.passes, progress=progress)
        save_render(scene, outputs.stage(out), rgba)
        if options.motion:
            imageio.write_image(outputs.stage(options.motion), render_motion(scene, options.width, options.height))
    return rgba


def render_motion(scene, width: int, height: int) -> np.ndarray:
    """Motion vectors of the scene camera's view for one frame step: dx, dy (pixels), cloud distance, alpha."""
    state = cloudstate.state_from_scene(scene)
    fps = sceneparams.scene_fps(scene)
    state.motion_dt = scene.nubis.wind_time_scale / fps
    clouds = runtime.cloud_gpu(scene.nubis.noise_seed)
    clouds.update(state)
    inv = cloudstate.camera_inv_view_proj(scene, width, height)
    return engine.render_motion(clouds, inv, cloudstate.camera_eye(scene), inv.inverted(), width, height)


@dataclass
class BakeResult:
    path: Path
    plan: BakePlan
    active_voxels: int
    seconds: float
    grids: tuple[str, ...] = ()
    frame: int = 0


def bake_grids(snap: BakeSnapshot, tiles=None, progress: Progress | None = None):
    """Evaluate the snapshot's tiles (or `tiles`) on the GPU into sparse grids: density, and where the
    sky has them absorption and glow; with the plan's `velocity` a Vec3 `velocity` grid in metres per
    second of animation, from the motion vectors' own model (the wind's scroll and the storms' turn
    over one frame, times the frame rate)."""
    grids, evaluate = _bake_evaluator(snap)
    evaluate(snap.plan.tiles if tiles is None else tiles, progress)
    return grids


def _bake_evaluator(snap: BakeSnapshot):
    """The grids a bake fills and the function that evaluates a group of its tiles into them, on GPU
    inputs of the bake's own (uploaded from the snapshot once: the viewport's redraws cannot reach them)."""
    plan = snap.plan
    clouds = snap.gpu_inputs()
    grids = vdbwrite.SparseGrids(plan.voxel_size, plan.origin)
    grids.grid("density")
    # Skies whose field can hold no glow or absorption read back the density alone.
    packed = plan.extra_grids == 0 and not plan.velocity
    sink = _grid_sink(grids, plan.velocity, snap.fps, packed)
    if plan.active_share < 1.0:
        sink = _guarded_sink(sink, plan, packed)

    def evaluate(tiles, progress=None):
        gpu_bake.bake_tiles(clouds, plan, tiles, sink, progress, plan.velocity, packed)

    return grids, evaluate


# Tiles evaluated between two looks at the interface (a cancel, a progress update) in a modal bake.
TILES_PER_STEP = 8


def bake_steps(scene, path: str | os.PathLike, options: BakeOptions, tiles_per_step: int = TILES_PER_STEP):
    """The bake in steps, for the interface: the scene is read now, into a snapshot (blender/jobs/snapshot.py),
    and the generator returned yields the fraction done after each group of tiles, evaluated from that
    snapshot whatever the scene, the timeline or the viewport do meanwhile; the file is written
    (atomically) after the last, and the generator returns the BakeResult. Closing it early cancels:
    nothing is written, an earlier file at `path` stays as it was."""
    path = check_output_path(path, (".vdb",))
    snap = snapshot.take(scene, options)
    return snapshot_steps(snap, path, options.half, tiles_per_step)


def snapshot_steps(
    snap: BakeSnapshot, path: str | os.PathLike, half: bool = False, tiles_per_step: int = TILES_PER_STEP
):
    """A snapshot's bake in steps (bake_steps; Bake Sequence runs one per frame): reads no Blender data."""
    path = check_output_path(path, (".vdb",))
    start = time.perf_counter()
    grids, evaluate = _bake_evaluator(snap)
    return _bake_run(snap, grids, evaluate, path, half, max(1, int(tiles_per_step)), start)


# What a bake says when its output folder goes while it runs (core/staging.py, FolderGone).
BAKE_GONE = ("the bake ran", "bake again")


def _bake_run(snap: BakeSnapshot, grids, evaluate, path: Path, half: bool, step: int, start: float):
    tiles = snap.plan.tiles
    try:
        for i in range(0, len(tiles), step):
            evaluate(tiles[i : i + step])
            # A folder removed (or replaced by a file) meanwhile stops the bake here, not after its last tile.
            staging.check_folder(path.parent)
            yield min(1.0, (i + step) / len(tiles))
        names = tuple(
            n
            for n in ("density", "glow", "absorption", "velocity")
            if n in grids.grids and (n == "density" or grids.active_voxels(n) > 0)
        )
        grids.write(path, snap.metadata(names), half=half)
    except staging.FolderGone as gone:
        raise gone.said(*BAKE_GONE) from None
    active = grids.active_voxels("density")
    return BakeResult(path, snap.plan, active, time.perf_counter() - start, names, snap.frame)


run_steps = offscreens.run_steps  # a stepped bake or render to its end: its BakeResult or image


_estimates: dict = {}


def bake_estimate(scene, voxel_size: float | None = None) -> tuple[int, int]:
    """(voxels the GPU would evaluate, bytes the bake would hold at its peak) with the scene's bake
    settings, for the Bake panel: planned once per change of the field, the settings or the camera."""
    s = scene.nubis
    cam = scene.camera
    key = (
        scene.as_pointer(),
        datafield.field_generation(),
        voxel_size or s.bake_voxel_size,
        s.bake_camera_only,
        s.bake_velocity,
        tuple(map(tuple, cam.matrix_world)) if cam else None,
        tuple((k, tuple(v) if isinstance(v, list) else v) for k, v in sceneparams.params_from_scene(s).items()),
    )
    if key not in _estimates:
        _estimates.clear()
        _state, plan = snapshot.bake_plan(scene, snapshot.scene_options(scene, voxel_size), wait=False)
        _estimates[key] = (plan.evaluated_voxels, plan.bytes_estimate)
    return _estimates[key]


def _active_voxels(block: np.ndarray, packed: bool) -> int:
    """Cloudy voxels of a block bake_tiles hands over (the density: the block itself when packed)."""
    return int(np.count_nonzero((block if packed else block[..., 0]) > vdbwrite.DEFAULT_TOLERANCE))


def _guarded_sink(sink, plan: BakePlan, packed: bool):
    """`sink`, stopping the bake once its trees would outgrow the memory limit: a plan that counted on a
    measured active share (BakePlan.active_share) keeps the promise of the estimate this way. Nothing is
    written then (the bake writes its file after the last tile)."""
    active = 0

    def guarded(ijk, block):
        nonlocal active
        active += _active_voxels(block, packed)
        need = bakeplan.BASE_BYTES + active * plan.bytes_per_active_voxel / bakeplan.LEAF_FILL
        if need > bakeplan.DEFAULT_MEMORY_LIMIT:
            raise bakeplan.BakeTooLarge(
                f"the clouds fill more of the {plan.voxel_size:g} m bake than its probe measured (over "
                f"{need / 1024**3:.1f} GB): give a larger voxel size (--voxel-size)",
                plan.voxel_size * 1.25,
            )
        sink(ijk, block)

    return guarded


def probe_share(scene, voxel_size: float, size: tuple[int, int], thin_cirrus: bool = False) -> float:
    """The BakePlan.active_share measured_share allows, from a camera-only bake at `voxel_size` that only
    counts its cloudy voxels: a fine bake the bound refuses may fit by what the clouds really fill
    (core/bakeplan.py, SHARE_MARGIN)."""
    snap = snapshot.take(scene, BakeOptions(voxel_size, camera_only=True, size=size, thin_cirrus=thin_cirrus))
    plan = snap.plan
    clouds = snap.gpu_inputs()
    packed = plan.extra_grids == 0
    active = 0

    def count(_ijk, block):
        nonlocal active
        active += _active_voxels(block, packed)

    gpu_bake.bake_tiles(clouds, plan, plan.tiles, count, packed=packed)
    return measured_share(active, plan.evaluated_voxels)


def _grid_sink(grids, velocity: bool, fps: float, packed: bool = False):
    tol = vdbwrite.DEFAULT_TOLERANCE

    def sink(ijk, block):
        if packed:
            grids.add("density", block, ijk)
            return
        grids.add("density", block[..., 0], ijk)
        for name, channel in (("glow", 1), ("absorption", 2)):
            if float(block[..., channel].max()) > tol:
                grids.add(name, block[..., channel], ijk)
        if velocity:
            active = (block[..., 0] > tol)[..., None]
            grids.add("velocity", np.where(active, block[..., 4:7] * fps, 0.0).astype(np.float32), ijk)

    return sink


def bake(
    scene, path: str | os.PathLike, options: BakeOptions | None = None, progress: Progress | None = None
) -> BakeResult:
    """Bake the viewport's density to an OpenVDB `density` grid in world space (atomic write): sparse
    and tiled, so memory follows the clouds rather than the box (docs/bake.md; the options: core/jobs.py)."""
    return run_steps(bake_steps(scene, path, options or BakeOptions()), progress)


def render_cycles(
    scene,
    width: int,
    height: int,
    samples: int | None = None,
    vdb_path: str | None = None,
    voxel_size: float | None = None,
    bounces: int | None = None,
    exact_samples: bool = False,
) -> np.ndarray:
    """Bake (unless given a VDB), import it with the matched material, render with Cycles; premultiplied RGBA."""
    with interrupt.temporary_dir("nubis-cycles-") as tmp:
        if vdb_path is None:
            vdb_path = str(Path(tmp) / "clouds.vdb")
            # The VDB clouds render from their own files (vdbclouds.native).
            bake(scene, vdb_path, BakeOptions(voxel_size=voxel_size, vdb=False))
        cycles_setup.import_volume(scene, vdb_path)
        exr = Path(tmp) / "cycles.exr"
        cycles_setup.configure_render(scene, width, height, samples, bounces, exact_samples)
        scene.render.filepath = str(exr)
        with runtime.own_render(), vdbclouds.native(scene), sun_air.above_the_air(scene):
            bpy.ops.render.render(write_still=True, scene=scene.name)
        if not exr.is_file():
            raise NubisError("Cycles wrote no image: check the console for Cycles errors")
        rgba = imageio.read_image(exr)
        cycles_setup.remove_volume(scene)
    return rgba
