"""The command line's commands (render, bake, cycles, compare, preview, benchmark): what each one does
once cli.py has parsed and checked its arguments. Each returns its one-line summary."""

from __future__ import annotations

import contextlib
import os
import time
from dataclasses import dataclass
from pathlib import Path

import bpy

from ...core import console, distributed, fields, interrupt, limits, sequence, staging
from ...core.errors import NubisError
from ...core.fsutil import check_output_dir, not_a_file
from ...core.jobs import BakeOptions, BenchmarkOptions, CompareOptions, PreviewOptions, RenderOptions
from ...core.presets import load_preset
from ...render.gpu_context import ensure_gpu_context
from .. import registration
from ..f12 import scene_render
from ..host import ui
from ..jobs import comparison, farm, pipeline, preview, snapshot
from ..scene import datafield, scenepresets, vdbclouds

PROG = "nubis"
# compare --draft bakes voxels no finer than this (metres): at half the scene's size the camera-footprint
# size is about 15 m for the default cloudscape, a 35 s bake; 30 m takes a few seconds and Cycles renders
# it faster too, with the alpha RMSE within 0.01 of the finer bake's (docs/measurements.md#draft-comparison).
DRAFT_VOXEL = 30.0
# A field composite slower than this gets an estimate first, then a progress bar.
SLOW_COMPOSITE_S = 5.0


def _composite_progress(preset):
    seconds = fields.composite_seconds(preset.layers, preset.params["field_resolution"])
    if seconds < SLOW_COMPOSITE_S:
        return None
    res = preset.params["field_resolution"]
    console.current().line(
        f"{PROG}: compositing {len(preset.layers)} field layers at {res}x{res} pixels, about {seconds:.0f} s"
    )
    return console.progress("field")


def load_scene(args, in_blender: bool):
    """The scene to work on: a saved .blend, a preset, or (inside Blender) the open file's cloudscape."""
    if args.blend:
        path = Path(args.blend).expanduser()
        why = not_a_file(path)
        if why:
            raise NubisError(f"the .blend file '{path}' {why}: give the path of a saved .blend file")
        try:
            bpy.ops.wm.open_mainfile(filepath=str(path), load_ui=False)
        except RuntimeError as err:
            first = str(err).strip().splitlines()[-1] if str(err).strip() else "unreadable"
            raise NubisError(f"cannot open '{path}' ({first}): check that it is a Blender file") from None
        interrupt.track_blender_tempdir()
        registration.ensure_registered()
        scene = bpy.context.scene
        if not ui.has_cloudscape(scene):
            raise NubisError(f"'{path}' holds no Nubis cloudscape: add one with New Cloudscape and save the file")
        return scene
    if in_blender and not args.preset and bpy.data.filepath and ui.has_cloudscape(bpy.context.scene):
        return bpy.context.scene
    preset = load_preset(args.preset or "default")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    interrupt.track_blender_tempdir()  # factory settings start a new session folder
    registration.ensure_registered()
    scene = bpy.context.scene
    scenepresets.apply_preset(scene, preset, progress=_composite_progress(preset))
    return scene


def _add_vdb_clouds(scene, paths, with_cloudscape: bool) -> None:
    """--vdb: the files as Nubis clouds; the preset's procedural clouds off unless --with-cloudscape (its
    sky, sun and camera stay)."""
    vdbclouds.add_files(scene, paths)
    if not with_cloudscape:
        s = scene.nubis
        s.density_cover = 0.0
        s.cirrus_coverage = 0.0
        s.storms.clear()
        datafield.generate_fields(scene)


@dataclass(frozen=True)
class Job:
    """One command's run: its parsed arguments, the scene it works on, where it writes and Blender's log."""

    args: object
    scene: object
    out: Path
    log: Path
    start: float

    @property
    def label(self) -> str:
        return self.scene.nubis.preset or "scene"

    def seconds(self) -> float:
        return time.perf_counter() - self.start

    def size(self) -> tuple[int, int]:
        return pipeline.resolution(self.scene, getattr(self.args, "width", None), getattr(self.args, "height", None))

    def bake_options(self) -> BakeOptions:
        a = self.args
        return BakeOptions(voxel_size=a.voxel_size, camera_only=a.camera_only, half=a.half, velocity=a.velocity)


def execute(args, in_blender: bool, log: Path, out: Path) -> str:
    """Run one checked command writing to `out`; Blender's own output goes to `log`."""
    start = time.perf_counter()
    vdbclouds.forget_notes()
    with console.quiet(log):
        interrupt.track_blender_tempdir()
        scene = load_scene(args, in_blender)
        if getattr(args, "vdb", None) and args.command != "benchmark":  # the benchmark times the sky first
            _add_vdb_clouds(scene, args.vdb, args.with_cloudscape)
        if getattr(args, "frame", None) is not None:
            scene.frame_set(args.frame)
        pipeline.check_scene(scene)
        ensure_gpu_context()
    return COMMANDS[args.command](Job(args, scene, out, log, start))


def _render(job: Job) -> str:
    args, scene, out = job.args, job.scene, job.out
    w, h = job.size()
    options = RenderOptions(w, h, passes=args.passes, motion=args.motion)
    with console.quiet(job.log):
        rgba = pipeline.render_files(scene, out, options, progress=console.progress("rendering"))
    cover = float((rgba[..., 3] > 0.05).mean()) * 100
    return f"rendered {job.label} at {w}x{h} ({cover:.0f}% cloud cover) in {job.seconds():.1f} s -> {out}"


def _bake(job: Job) -> str:
    args = job.args
    if args.frames or args.distributed or "#" in job.out.name:
        return _bake_sequence(job)
    progress = console.progress("baking")
    with console.quiet(job.log):
        result = pipeline.bake(job.scene, job.out, job.bake_options(), progress)
    nx, ny, nz = result.plan.dims
    return (
        f"baked {job.label}: {nx}x{ny}x{nz} voxels of {result.plan.voxel_size:g} m, "
        f"{result.active_voxels} active, in {result.seconds:.1f} s -> {job.out}"
    )


def _panorama(job: Job) -> str:
    with console.quiet(job.log):
        scene_render.panorama(job.scene, job.out, job.args.width)
    width = job.args.width
    return f"panorama of {job.label} at {width}x{max(width // 2, 2)} in {job.seconds():.1f} s -> {job.out}"


def _cycles(job: Job) -> str:
    args, scene = job.args, job.scene
    w, h = job.size()
    with console.quiet(job.log):
        rgba = pipeline.render_cycles(scene, w, h, args.samples, voxel_size=args.voxel_size, bounces=args.bounces)
        pipeline.save_render(scene, job.out, rgba)
    return f"rendered {job.label} with Cycles at {w}x{h} in {job.seconds():.1f} s -> {job.out}"


def _compare(job: Job) -> str:
    args = job.args
    w, h = job.size()
    if args.draft:
        w = args.width or max(w // 2, limits.SIZE_RANGE[0])
        h = args.height or max(h // 2, limits.SIZE_RANGE[0])
    options = CompareOptions(
        width=w,
        height=h,
        samples=args.samples,
        mode=args.mode,
        voxel_size=args.voxel_size,
        noise_estimate=args.noise_estimate,
        bounces=args.bounces,
        reference=not args.draft,
        voxel_floor=DRAFT_VOXEL if args.draft else 0.0,
        noise_target=args.noise_target,
        reuse_reference=args.reuse_reference,
    )
    with console.quiet(job.log):
        m = comparison.compare(job.scene, job.out, options, step=lambda text: console.current().line(f"{PROG}: {text}"))
    return _compare_summary(job, options, m)


def _compare_summary(job: Job, options: CompareOptions, m: dict) -> str:
    capped = (
        f" (reference march in {m['reference_view_steps']} of {job.scene.nubis.march_steps_max} view steps: "
        "the shader loop limit)"
        if m.get("reference_steps_capped")
        else ""
    )
    noise = f" (noise {m['cycles_noise']['luminance_rel_error'] * 100:.1f}%)" if "cycles_noise" in m else ""
    ref = m["cycles_reference"]
    cycles_time = "Cycles' image reused" if ref["reused"] else f"{m['seconds']['cycles_s']:.0f} s"
    return (
        f"compared {job.label} ({options.mode}) at {options.width}x{options.height}: alpha RMSE "
        f"{m['alpha_rmse']:.4f}, luminance error {m['luminance_rel_error'] * 100:.1f}%, silhouette IoU "
        f"{m['silhouette_iou']:.3f}{capped} against Cycles at {m['samples']} samples{noise}, "
        f"{m['volume_bounces']} volume bounces ({cycles_time}, {job.seconds():.0f} s in all) -> {job.out}"
    )


def _bake_sequence(job: Job) -> str:
    """`bake --frames A-B` (files named with # padding) and `bake --distributed` (core/distributed.py)."""
    args, scene, out = job.args, job.scene, job.out
    options = job.bake_options()
    frames = sequence.parse_frames(args.frames) if args.frames else [scene.frame_current]
    if len(frames) > 1:  # the disk the whole set takes, before any frame is baked
        with console.quiet(job.log):
            _state, plan = snapshot.bake_plan(scene, options, wait=False)
        note = sequence.check_disk_space(out, frames, plan.file_bytes_estimate(args.half), args.half)
        if note:
            console.current().line(note)
    engine = distributed.parse_engine(args.distributed) if args.distributed else None
    progress = console.progress("baking")
    with console.quiet(job.log):
        source = farm.source_of(scene, args.preset, args.blend) if engine else None
        r = farm.bake_sequence(scene, out, frames, options, engine, source, progress)
    first = r.results[0]
    nx, ny, nz = first.plan.dims
    on = f" on {r.engine}" if r.engine else ""
    where = first.path if len(frames) == 1 else f"{first.path.parent / out.name} ({len(frames)} files)"
    return (
        f"baked {job.label}, frame{'s' if len(frames) > 1 else ''} {args.frames or frames[0]}: {nx}x{ny}x{nz} voxels "
        f"of {first.plan.voxel_size:g} m, {sum(x.active_voxels for x in r.results)} active{on}, "
        f"in {r.seconds:.1f} s -> {where}"
    )


def _preview(job: Job) -> str:
    args, scene = job.args, job.scene
    w, h = job.size()
    frames = preview.parse_frames(args.frames, scene.frame_current)
    options = PreviewOptions(w, h, tuple(frames), args.redraws, args.orbit, args.naive, args.quality)
    progress = console.progress("preview")
    with console.quiet(job.log):
        r = preview.preview(scene, job.out, options, progress=progress)
    ms = sorted(x for frame in r.redraw_ms for x in frame)
    median = ms[len(ms) // 2]
    naive = f", naive {sorted(r.naive_ms)[len(r.naive_ms) // 2]:.0f} ms" if r.naive_ms else ""
    return (
        f"previewed {job.label} at {w}x{h} ({r.quality}): {len(frames)} frame(s) x {args.redraws} redraw(s), "
        f"median redraw {median:.1f} ms{naive}, in {job.seconds():.1f} s -> {job.out}"
    )


def _benchmark(job: Job) -> str:
    args = job.args
    options = BenchmarkOptions(*job.size(), quality=args.quality, eevee_samples=args.eevee_samples)
    with console.quiet(job.log):
        try:
            if args.vdb:
                result = _benchmark_vdb(job, options.but(eevee=False))
            elif job.scene.nubis.cloud_layers:
                result = _benchmark_layers(job, options.but(eevee=False))
            else:
                result = preview.benchmark(job.scene, job.out, options)
        except staging.FolderGone as gone:
            raise gone.said("the benchmark ran", "run the benchmark again") from None
    print(preview.table(result))
    size = f"{options.width}x{options.height} ({result['quality']})"
    if "baseline_label" in result and not args.vdb:
        return (
            f"benchmarked {job.label} at {size}: redraw {result['redraw_ms']:.1f} ms, "
            f"{result['redraw_ms'] / result['baseline_redraw_ms']:.2f}x {result['baseline_label']}'s "
            f"{result['baseline_redraw_ms']:.1f} ms in {job.seconds():.1f} s -> {job.out}"
        )
    if args.vdb:
        return (
            f"benchmarked {job.label} with {len(args.vdb)} VDB cloud(s) at {size}: redraw "
            f"{result['redraw_ms']:.1f} ms, {result['redraw_ms'] / result['baseline_redraw_ms']:.2f}x the "
            f"cloudscape's {result['baseline_redraw_ms']:.1f} ms; VDB clouds on the GPU "
            f"{sequence.human_bytes(result['vdb_gpu_bytes'])} in {job.seconds():.1f} s -> {job.out}"
        )
    return (
        f"benchmarked {job.label} at {size}: naive {result['naive_ms']:.0f} ms, redraw "
        f"{result['redraw_ms']:.1f} ms ({result['naive_over_redraw']:.1f}x), EEVEE {result['eevee_ms']:.0f} ms "
        f"({result['eevee_over_redraw']:.0f}x) in {job.seconds():.1f} s -> {job.out}"
    )


def _benchmark_vdb(job: Job, options: BenchmarkOptions) -> dict:
    """`benchmark --vdb`: the preset's own cloudscape on the same view first (its files in out/cloudscape),
    then with the VDB clouds: one run, one machine."""
    args = job.args

    def add_clouds() -> None:
        _add_vdb_clouds(job.scene, args.vdb, args.with_cloudscape)

    return _benchmark_pair(job, options, ("cloudscape", "the cloudscape"), add_clouds)


def _benchmark_layers(job: Job, options: BenchmarkOptions) -> dict:
    """`benchmark` of a layered sky (docs/layers.md): its lowest drawn layer alone on the same view first
    (its files in out/lowest_layer), then the whole sky: what the further layers cost, in one run."""
    s = job.scene.nubis
    # (the layer's settings, its solo switch, whether it is enabled, its base, its name)
    rows = [(s, "first_layer_solo", s.first_layer_enabled, s.layer_bottom, s.first_layer_name)]
    rows += [(c, "solo", c.enabled, c.layer_bottom, c.name) for c in s.cloud_layers]
    lowest = min((i for i, row in enumerate(rows) if row[2]), key=lambda i: rows[i][3], default=0)
    name = rows[lowest][4]
    kept = [getattr(owner, key) for owner, key, *_rest in rows]
    for i, (owner, key, *_rest) in enumerate(rows):
        setattr(owner, key, i == lowest)

    def whole_sky() -> None:
        for (owner, key, *_rest), value in zip(rows, kept, strict=True):
            setattr(owner, key, value)

    return _benchmark_pair(job, options, ("lowest_layer", f"the lowest layer alone ('{name}')"), whole_sky)


def _benchmark_pair(job: Job, options: BenchmarkOptions, baseline: tuple[str, str], change) -> dict:
    """Two benchmarks of the same view in one run: the scene as it is (its files in out/<baseline folder>),
    then after `change()`, the result naming the first as its baseline. Both run in a private folder inside
    `out`, and their files move into place together at the end: a failure of either leaves no file of this
    run, and an earlier run's files as they were (core/staging.py)."""
    scene, out = job.scene, job.out
    folder, label = baseline
    with staging.private_folder(out) as work:
        first = preview.benchmark(scene, work / folder, options)
        first["label"] = label
        change()
        result = preview.benchmark(scene, work / "main", options, baseline=first)
        made = not (out / folder).exists()
        try:
            with staging.output_set() as outputs:
                for done, final in ((work / "main", out), (work / folder, check_output_dir(out / folder))):
                    for path in sorted(p for p in done.iterdir() if p.is_file() and not p.name.startswith(".")):
                        os.replace(path, outputs.stage(final / path.name))
        except BaseException:
            if made:  # the folder this run made for the files that never came
                with contextlib.suppress(OSError):
                    (out / folder).rmdir()
            raise
    return result


COMMANDS = {
    "render": _render,
    "bake": _bake,
    "panorama": _panorama,
    "cycles": _cycles,
    "compare": _compare,
    "preview": _preview,
    "benchmark": _benchmark,
}
