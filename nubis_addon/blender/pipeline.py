"""The headless pipeline shared by the operators and the command line: render, bake, Cycles, compare."""

from __future__ import annotations

import dataclasses
import json
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import bpy
import numpy as np
from mathutils import Matrix

from ..core import bakeplan, camera, imageio, interrupt, limits, march, metrics, staging, vdbio
from ..core import sky as skymath
from ..core.bakeplan import (
    BakePlan,
    camera_fitting_voxel,
    camera_footprint_voxel,
    measured_share,
)
from ..core.errors import NubisError
from ..core.fsutil import check_output_dir, check_output_path
from ..core.jobs import BakeOptions, CompareOptions, RenderOptions
from ..core.state import MAX_STORMS, CloudState
from ..render import bake as gpu_bake
from ..render import engine
from . import cycles_setup, datafield, runtime, scene_io, sceneparams, sky, snapshot, sun_air, superstorms, vdbclouds
from . import reference as cycles_reference
from .snapshot import BakeSnapshot

Progress = Callable[[float], None]


def ocio_config() -> str:
    return os.path.join(bpy.utils.resource_path("LOCAL"), "datafiles", "colormanagement", "config.ocio")


def sky_background(scene, width: int, height: int) -> np.ndarray:
    """The World as the scene camera sees it behind the clouds (H, W, 3), top row first: the World's
    capture (blender/sky.py) looked up along each pixel's view ray."""
    if scene.camera is None:
        return np.broadcast_to(np.asarray(scene_io.world_ambient(scene), np.float32), (height, width, 3))
    env = sky.environment(scene)
    if env.shape[0] > 4 or env.shape[1] > 8:  # not one colour: a sharper capture for pictures
        env = sky.capture_world(scene, sky.BACKGROUND_WIDTH, samples=4)
    inv = scene_io.camera_inv_view_proj(scene, width, height)
    dirs = skymath.camera_directions(inv, scene_io.camera_eye(scene), width, height)
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
    limits.check_count("field layers", len(settings.layers), limits.MAX_LAYERS, "merge or remove layers")
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

# Cycles' volume bounces for a full comparison: enough that doubling them changes the picture by less
# than Cycles' own noise on every preset (docs/convergence.md). The scene's own setting (8 by default,
# what an artist renders with) is not a reference: a thick deck is far darker at 8 (docs/convergence.md).
REFERENCE_BOUNCES = 256


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
    state = scene_io.state_from_scene(scene)
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
    inv = scene_io.camera_inv_view_proj(scene, width, height)
    # The noise mip levels follow the pixel's footprint, as in the 3D viewport.
    state.pixel_angle, state.pixel_size = camera.pixel_footprint(np.array(inv), width, height)
    return ViewportShot(state, inv, scene_io.camera_eye(scene), scene.nubis.noise_seed, width, height)


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
    state = scene_io.state_from_scene(scene)
    fps = sceneparams.scene_fps(scene)
    state.motion_dt = scene.nubis.wind_time_scale / fps
    clouds = runtime.cloud_gpu(scene.nubis.noise_seed)
    clouds.update(state)
    inv = scene_io.camera_inv_view_proj(scene, width, height)
    return engine.render_motion(clouds, inv, scene_io.camera_eye(scene), inv.inverted(), width, height)


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
    grids = vdbio.SparseGrids(plan.voxel_size, plan.origin)
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
    """The bake in steps, for the interface: the scene is read now, into a snapshot (blender/snapshot.py),
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


run_steps = engine.run_steps  # a stepped bake or render to its end: its BakeResult or image


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
    return int(np.count_nonzero((block if packed else block[..., 0]) > vdbio.DEFAULT_TOLERANCE))


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
    tol = vdbio.DEFAULT_TOLERANCE

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


def bake_clip_box(plan: BakePlan) -> tuple[float, float, float, float]:
    """The XY box (x0, y0, x1, y1) a bake covers: voxel centres sit half a voxel inside it."""
    half = plan.voxel_size / 2
    x0, y0 = plan.origin[0] - half, plan.origin[1] - half
    return (x0, y0, x0 + plan.dims[0] * plan.voxel_size, y0 + plan.dims[1] * plan.voxel_size)


def compare(
    scene, out_dir: str | os.PathLike, options: CompareOptions, step: Callable[[str], None] | None = None
) -> dict:
    """Viewport and Cycles renders of the same shot, their side-by-side, a difference image and
    metrics.json (computed on the scene-linear EXR values); the bake Cycles rendered is kept as
    clouds.vdb. Only the part of the sky the camera sees is baked, with voxels of one pixel's footprint
    at the nearest cloud (down to 20 m) unless `options.voxel_size` is given, and the cirrus as a slab two
    voxels thin. The eight files replace an earlier comparison together or not at all. `options.reference`
    adds the real-time light march against the reference march (the slowest part after Cycles); `step` is
    told what each stage is about to do (core/jobs.py has the options)."""
    if options.mode not in COMPARE_MODES:
        raise NubisError(f"unknown comparison mode '{options.mode}': use single or full")
    out = check_output_dir(out_dir)
    try:
        with staging.output_set() as outputs:
            stages = 4 if options.mode == "full" and options.reference else 3
            run = _CompareRun(scene, out, outputs.stage, options, step or _silent, stages)
            return _compare(run)
    except staging.FolderGone as gone:
        raise gone.said("the comparison ran", "compare again") from None


# The comparison bakes the cirrus as a slab two voxels thin: the viewport samples the 2D layer at one
# point, and a ray crossing a thick slab at a grazing angle averages kilometres of it
# (docs/sources.md#comparison-set-up).
THIN_CIRRUS = True

# Jittered passes the comparison's viewport accumulates (in two halves): most of the way to converged for
# half the time of 8 (docs/sources.md#comparison-set-up).
COMPARE_PASSES = 4
# With a noise target the viewport adds passes until its own grain is at most this share of the target in
# the luminance and this much in the alpha, or it has taken the most passes (docs/sources.md#comparison-set-up).
VIEW_NOISE = {"luminance_share": 0.2, "alpha": 0.002, "most_passes": 32}


def _silent(_text: str) -> None:
    pass


@dataclass
class _CompareRun:
    """One comparison: where it writes (`stage` names a file's staged path), its options and what it has
    found so far."""

    scene: object
    out: Path
    stage: Callable[[Path], Path]
    options: CompareOptions
    step: Callable[[str], None]
    stages: int
    timings: dict = dataclasses.field(default_factory=dict)

    def say(self, n: int, text: str) -> None:
        self.step(f"{n}/{self.stages} {text}")


def _compare(run: _CompareRun) -> dict:
    baked = _compare_bake(run)
    clip = bake_clip_box(baked.plan)  # the viewport keeps only the baked clouds (Cycles sees no others)
    viewport, grain, ss, passes = _compare_viewport(run, clip)
    cycles, result = _compare_cycles(run, baked, viewport)
    result["viewport_noise"] = grain
    result["viewport_passes"] = passes
    if run.stages == 4:
        result["cone_march_vs_reference"] = _compare_reference(run, viewport, clip, ss, passes)
    _describe(run, result, baked, clip, ss)
    _write_comparison(run, viewport, cycles, result)
    return result


def _compare_voxels(run: _CompareRun) -> tuple[float, float, float | None]:
    """The bake's voxel size, the active share its memory bound may count on, and the size to fall back to
    if the clouds fill more than that share (None: no fallback needed)."""
    o, scene = run.options, run.scene
    if o.voxel_size is not None:
        return o.voxel_size, 1.0, None
    # The sparse bake's memory follows the clouds, so the voxels can be as fine as the camera needs.
    state = scene_io.state_from_scene(scene)
    inv = np.array(scene_io.camera_inv_view_proj(scene, o.width, o.height))
    wanted = max(camera_footprint_voxel(state, inv, o.width, o.height, scene.nubis.bake_voxel_size), o.voxel_floor)
    voxel = max(camera_fitting_voxel(state, inv, wanted), o.voxel_floor)
    if wanted >= voxel:
        return voxel, 1.0, None
    # The memory bound (every evaluated voxel active) holds the bake coarser than the camera asks: what the
    # clouds really fill, counted at the size that fits, may allow finer voxels. A coarse reference is not
    # converged in its voxels (docs/bake.md#memory).
    run.say(1, f"counting what the clouds fill of a {voxel:.3g} m bake")
    probe = probe_share(scene, voxel, (o.width, o.height), THIN_CIRRUS)
    finer = max(camera_fitting_voxel(state, inv, wanted, active_share=probe), o.voxel_floor)
    return (finer, probe, voxel) if finer < voxel else (voxel, 1.0, None)


def _compare_bake(run: _CompareRun) -> BakeResult:
    t = time.perf_counter()
    voxel, share, safe = _compare_voxels(run)
    run.say(1, f"baking what the camera sees, {voxel:.3g} m voxels")
    options = BakeOptions(
        voxel_size=voxel,
        camera_only=True,
        size=(run.options.width, run.options.height),
        thin_cirrus=THIN_CIRRUS,
        active_share=share,
        vdb=False,  # Cycles renders the VDB clouds' own files (vdbclouds.native)
    )
    try:
        baked = bake(run.scene, run.stage(run.out / "clouds.vdb"), options)
    except bakeplan.BakeTooLarge:
        if safe is None:
            raise
        # The clouds filled more than the probe measured (its bake stopped before its trees outgrew the
        # memory): the size the bound allows instead.
        run.say(1, f"the clouds fill more than measured: baking at {safe:.3g} m voxels")
        baked = bake(run.scene, run.stage(run.out / "clouds.vdb"), options.but(voxel_size=safe, active_share=1.0))
    run.timings["bake_s"] = time.perf_counter() - t
    return baked


def _supersampling(options: CompareOptions) -> int:
    """Cycles integrates each pixel's area (a box filter); the viewport samples the pixel centre:
    supersampled, both estimate the same pixel value."""
    return max(1, min(4, 1024 // max(options.width, options.height)))


def _compare_viewport(run: _CompareRun, clip) -> tuple[np.ndarray, dict, int, int]:
    """The viewport converged as its accumulation converges when the view stands still, each pass's rays
    crossing their pixels at places of their own as Cycles' do: two halves of the options' viewport passes
    (COMPARE_PASSES unless given), or with a noise target and none given as many as VIEW_NOISE asks.
    Returns the image, its grain (the halves' difference), the supersampling and the passes."""
    o = run.options
    ss = _supersampling(o)
    t = time.perf_counter()
    w, h = o.width * ss, o.height * ss
    shot = dataclasses.replace(viewport_shot(run.scene, w, h, 0, o.mode, clip), pixel_area=True)
    goal = None
    if o.noise_target is not None and o.viewport_passes is None:
        goal = cycles_reference.NoiseGoal(
            o.noise_target / 100 * VIEW_NOISE["luminance_share"],
            VIEW_NOISE["alpha"],
            VIEW_NOISE["most_passes"],
            "the viewport's",
            "passes",
        )
    more = "" if goal is None else f", more until its noise is at most {goal.describe()}"
    start = o.viewport_passes or COMPARE_PASSES
    run.say(2, f"the viewport's march, {w}x{h} pixels, {start} passes{more}")
    done = [0]

    def render(passes: int, _half: int) -> np.ndarray:
        first, done[0] = done[0], done[0] + passes
        return downsample(render_shot(shot, passes, first), ss)

    image, noise, passes = cycles_reference.sample_to_target(render, start, goal, lambda text: run.step(f"   {text}"))
    run.timings["viewport_s"] = time.perf_counter() - t
    return image, noise, ss, passes


def _compare_cycles(run: _CompareRun, baked: BakeResult, viewport: np.ndarray) -> tuple[np.ndarray, dict]:
    """Cycles' image of the bake (or an earlier run's of the same view) and the metrics against it."""
    o, scene = run.options, run.scene
    # Cycles counts bounces after the first scattering: 0 volume bounces is single scattering.
    bounces = 0 if o.mode == "single" else (REFERENCE_BOUNCES if o.bounces is None else o.bounces)
    t = time.perf_counter()
    total = o.samples or scene.cycles.samples
    target = o.noise_target / 100 if o.noise_target is not None else None
    ref_key = cycles_reference.key(scene, baked.path, o.width, o.height, bounces)
    earlier = cycles_reference.reusable(run.out, ref_key, total, target) if o.reuse_reference else None
    if earlier is not None:
        cycles, info = earlier
        taken, noise = info["samples"], info["cycles_noise"]
        run.say(3, f"Cycles: the earlier reference in {run.out} ({taken} samples, same bake and scene)")
    else:
        run.say(3, f"Cycles, {o.width}x{o.height} pixels, {total} samples, {bounces} volume bounces")
        split = o.noise_estimate or target is not None
        cycles, noise, taken = _cycles_samples(run, total, bounces, baked.path, split, target)
    run.timings["cycles_s"] = time.perf_counter() - t
    result = metrics.compare(viewport, cycles)
    if noise is not None:
        result["cycles_noise"] = noise
    result["cycles_reference"] = {
        "key": ref_key,
        "samples": taken,
        "reused": earlier is not None,
        "cycles_s": earlier[1]["cycles_s"] if earlier is not None else run.timings["cycles_s"],
    }
    result["volume_bounces"] = bounces
    scene.cycles.samples = taken
    return cycles, result


def _cycles_samples(run: _CompareRun, total: int, bounces: int, vdb, split: bool, target: float | None):
    """Cycles' image of the bake, its noise (None unless `split`) and the samples taken. Split, the
    samples go to two seeds (their mean is the reference, half their difference its noise, at no extra
    cost); with a target, seed pairs are added until the noise is under it (blender/reference.py)."""
    scene, o = run.scene, run.options

    def render(n: int, seed_offset: int) -> np.ndarray:
        scene.cycles.seed += seed_offset
        try:
            return render_cycles(scene, o.width, o.height, n, str(vdb), bounces=bounces, exact_samples=True)
        finally:
            scene.cycles.seed -= seed_offset

    if not split:
        return render(total, 0), None, total
    goal = None if target is None else cycles_reference.NoiseGoal(target)
    return cycles_reference.sample_to_target(render, total, goal, lambda text: run.step(f"   {text}"))


def _compare_reference(run: _CompareRun, viewport: np.ndarray, clip, ss: int, passes: int) -> dict:
    """The real-time cone march against the reference march, everything else equal (the same passes, so
    the same rays)."""
    o = run.options
    run.say(4, f"the reference light march, {o.width * ss}x{o.height * ss} pixels")
    t = time.perf_counter()
    shot = dataclasses.replace(viewport_shot(run.scene, o.width * ss, o.height * ss, 1, o.mode, clip), pixel_area=True)
    march_ref = render_shot(shot, passes)
    cone = metrics.compare(viewport, downsample(march_ref, ss))
    run.timings["reference_s"] = time.perf_counter() - t
    return {k: cone[k] for k in ("alpha_rmse", "luminance_rel_error", "luminance_bias")}


def _describe(run: _CompareRun, result: dict, baked: BakeResult, clip, ss: int) -> None:
    """What was compared, into the metrics."""
    scene, o = run.scene, run.options
    # The reference march keeps within the shader loop limit by taking longer steps (core/march.py).
    steps_max = scene.nubis.march_steps_max
    storms = len(superstorms.storm_lights(scene.nubis))
    result["reference_view_steps"] = min(
        steps_max, march.max_steps(scene.nubis.march_light_samples, storms, 2 if o.mode == "full" else 1)
    )
    result["reference_steps_capped"] = result["reference_view_steps"] < steps_max
    result.update(
        mode=o.mode,
        viewport_supersampling=ss,
        width=o.width,
        height=o.height,
        samples=scene.cycles.samples,
        preset=scene.nubis.preset,
        voxel_size=baked.plan.voxel_size,
        bake_dims=list(baked.plan.dims),
        # 1: the bake fitted the memory bound; below: it counted on this share, measured by a probe.
        bake_active_share=baked.plan.active_share,
        clip_box=list(clip),
        seconds=run.timings,
    )


def _write_comparison(run: _CompareRun, viewport: np.ndarray, cycles: np.ndarray, result: dict) -> None:
    scene, out, stage = run.scene, run.out, run.stage
    save_render(scene, stage(out / "viewport.exr"), viewport)
    save_render(scene, stage(out / "cycles.exr"), cycles)
    view_png, cyc_png = display_image(scene, viewport), display_image(scene, cycles)
    imageio.write_image(stage(out / "viewport.png"), view_png)
    imageio.write_image(stage(out / "cycles.png"), cyc_png)
    diff = metrics.difference_image(viewport, cycles)
    imageio.write_image(stage(out / "difference.png"), diff)
    imageio.write_image(stage(out / "side_by_side.png"), metrics.side_by_side(view_png, cyc_png, diff))
    stage(out / "metrics.json").write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")  # moved last
