"""The comparison: the viewport's march against Cycles rendering the bake of the same shot, with its
side-by-side, difference image and metrics (compare, docs/cli.md); Cycles' noise and its reuse are reference.py's."""

from __future__ import annotations

import dataclasses
import json
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...core import bakeplan, imageio, march, metrics, staging
from ...core.bakeplan import BakePlan, camera_fitting_voxel, camera_footprint_voxel
from ...core.errors import NubisError
from ...core.fsutil import check_output_dir
from ...core.jobs import BakeOptions, CompareOptions
from ..scene import cloudstate, superstorms
from . import pipeline
from . import reference as cycles_reference

# Cycles' volume bounces for a full comparison: enough that doubling them changes the picture by less
# than Cycles' own noise on every preset (docs/convergence.md). The scene's own setting (8 by default,
# what an artist renders with) is not a reference: a thick deck is far darker at 8 (docs/convergence.md).
REFERENCE_BOUNCES = 256


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
    if options.mode not in pipeline.COMPARE_MODES:
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
    state = cloudstate.state_from_scene(scene)
    inv = np.array(cloudstate.camera_inv_view_proj(scene, o.width, o.height))
    wanted = max(camera_footprint_voxel(state, inv, o.width, o.height, scene.nubis.bake_voxel_size), o.voxel_floor)
    voxel = max(camera_fitting_voxel(state, inv, wanted), o.voxel_floor)
    if wanted >= voxel:
        return voxel, 1.0, None
    # The memory bound (every evaluated voxel active) holds the bake coarser than the camera asks: what the
    # clouds really fill, counted at the size that fits, may allow finer voxels. A coarse reference is not
    # converged in its voxels (docs/bake.md#memory).
    run.say(1, f"counting what the clouds fill of a {voxel:.3g} m bake")
    probe = pipeline.probe_share(scene, voxel, (o.width, o.height), THIN_CIRRUS)
    finer = max(camera_fitting_voxel(state, inv, wanted, active_share=probe), o.voxel_floor)
    return (finer, probe, voxel) if finer < voxel else (voxel, 1.0, None)


def _compare_bake(run: _CompareRun) -> pipeline.BakeResult:
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
        baked = pipeline.bake(run.scene, run.stage(run.out / "clouds.vdb"), options)
    except bakeplan.BakeTooLarge:
        if safe is None:
            raise
        # The clouds filled more than the probe measured (its bake stopped before its trees outgrew the
        # memory): the size the bound allows instead.
        run.say(1, f"the clouds fill more than measured: baking at {safe:.3g} m voxels")
        baked = pipeline.bake(
            run.scene, run.stage(run.out / "clouds.vdb"), options.but(voxel_size=safe, active_share=1.0)
        )
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
    shot = dataclasses.replace(pipeline.viewport_shot(run.scene, w, h, 0, o.mode, clip), pixel_area=True)
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
        return pipeline.downsample(pipeline.render_shot(shot, passes, first), ss)

    image, noise, passes = cycles_reference.sample_to_target(render, start, goal, lambda text: run.step(f"   {text}"))
    run.timings["viewport_s"] = time.perf_counter() - t
    return image, noise, ss, passes


def _compare_cycles(run: _CompareRun, baked: pipeline.BakeResult, viewport: np.ndarray) -> tuple[np.ndarray, dict]:
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
    cost); with a target, seed pairs are added until the noise is under it (blender/jobs/reference.py)."""
    scene, o = run.scene, run.options

    def render(n: int, seed_offset: int) -> np.ndarray:
        scene.cycles.seed += seed_offset
        try:
            return pipeline.render_cycles(scene, o.width, o.height, n, str(vdb), bounces=bounces, exact_samples=True)
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
    shot = dataclasses.replace(
        pipeline.viewport_shot(run.scene, o.width * ss, o.height * ss, 1, o.mode, clip), pixel_area=True
    )
    march_ref = pipeline.render_shot(shot, passes)
    cone = metrics.compare(viewport, pipeline.downsample(march_ref, ss))
    run.timings["reference_s"] = time.perf_counter() - t
    return {k: cone[k] for k in ("alpha_rmse", "luminance_rel_error", "luminance_bias")}


def _describe(run: _CompareRun, result: dict, baked: pipeline.BakeResult, clip, ss: int) -> None:
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
    pipeline.save_render(scene, stage(out / "viewport.exr"), viewport)
    pipeline.save_render(scene, stage(out / "cycles.exr"), cycles)
    view_png, cyc_png = pipeline.display_image(scene, viewport), pipeline.display_image(scene, cycles)
    imageio.write_image(stage(out / "viewport.png"), view_png)
    imageio.write_image(stage(out / "cycles.png"), cyc_png)
    diff = metrics.difference_image(viewport, cycles)
    imageio.write_image(stage(out / "difference.png"), diff)
    imageio.write_image(stage(out / "side_by_side.png"), metrics.side_by_side(view_png, cyc_png, diff))
    stage(out / "metrics.json").write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")  # moved last
