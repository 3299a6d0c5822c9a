"""The headless command line, a stable contract:

    python -m nubis_addon render  [--preset NAME | --blend FILE] --out PATH [--width W --height H --frame F]
    python -m nubis_addon bake    [--preset NAME | --blend FILE] --out PATH.vdb [--voxel-size METRES --camera-only
                                  --half --velocity --frames A-B --distributed local:N|tcp://HOST:PORT]
    python -m nubis_addon cycles  [--preset NAME | --blend FILE] --out PATH [--samples N --width W --height H]
    python -m nubis_addon compare [--preset NAME | --blend FILE] --out DIR [--samples N --width W --height H]
    python -m nubis_addon preview [--preset NAME | --blend FILE] --out DIR [--width W --height H --frames A-B
                                  --redraws N --orbit DEG --quality Q --naive]
    python -m nubis_addon benchmark [--preset NAME | --blend FILE] --out DIR [--width W --height H --quality Q]

and the same as ``blender -b [FILE.blend] --command nubis ...``. Each command prints a one-line summary and
exits 0, or prints a one-line error that says what to do and exits non-zero: 1 for a user error, 2 for a
bad command line, 3 for an internal fault (its log named in the message), 130 and 143 for SIGINT and
SIGTERM. A command's outputs appear together or not at all (core/staging.py).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import tempfile
import time
import traceback
from collections.abc import Iterator, Sequence
from pathlib import Path

from .core import interrupt, limits, staging
from .core.console import Console
from .core.errors import NubisError
from .core.fsutil import check_output_dir, check_output_path
from .core.imageio import IMAGE_SUFFIXES

PROG = "nubis"


class _ArgumentParser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, not argparse's usage dump
        raise NubisError(f"{message} (see '{self.prog} --help')")


def build_parser() -> argparse.ArgumentParser:
    parser = _ArgumentParser(prog=PROG, description="Nubis volumetric clouds, headless.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_ArgumentParser)

    def common(p: argparse.ArgumentParser, frame: bool = True) -> None:
        src = p.add_mutually_exclusive_group()
        src.add_argument("--preset", help="preset name in presets/ (default: 'default') or a .toml path")
        src.add_argument("--blend", help="a .blend file saved with a Nubis cloudscape")
        p.add_argument("--out", required=True, help="output path")
        if frame:
            p.add_argument("--frame", type=int, help="frame to render (wind time)")

    def size(p: argparse.ArgumentParser) -> None:
        p.add_argument("--width", type=int, help="image width in pixels (default: the scene's)")
        p.add_argument("--height", type=int, help="image height in pixels (default: the scene's)")

    p = sub.add_parser("render", help="render the viewport's clouds from the scene camera (PNG or EXR)")
    common(p)
    size(p)
    p.add_argument("--passes", type=int, default=1, help="average N jittered passes for a grain-free image")
    p.add_argument("--motion", help="also write motion vectors (dx, dy pixels per frame, distance, alpha) to an EXR")
    p = sub.add_parser("bake", help="bake the cloud density to an OpenVDB file")
    common(p)
    p.add_argument("--voxel-size", type=float, help="voxel edge in metres (default: the scene's bake setting)")
    p.add_argument("--camera-only", action="store_true", help="bake only what the scene camera sees")
    p.add_argument("--half", action="store_true", help="store the grids as half floats (half the file size)")
    p.add_argument("--velocity", action="store_true", help="add a 'velocity' Vec3 grid for motion blur (m/s)")
    p.add_argument("--frames", help="bake frames A-B, one file each: write the frame as #### in --out")
    p.add_argument(
        "--distributed",
        metavar="local:N|tcp://HOST:PORT",
        help="spread the frames (or one frame's tiles) over Dask workers: N local ones or a running scheduler",
    )
    for name, what in (
        ("cycles", "render the baked clouds with Cycles"),
        ("compare", "render viewport and Cycles side by side, with metrics"),
    ):
        p = sub.add_parser(name, help=what)
        common(p)
        size(p)
        p.add_argument("--samples", type=int, help="Cycles samples per pixel (default: the preset's)")
        p.add_argument("--voxel-size", type=float, help="voxel edge of the bake in metres")
        p.add_argument("--bounces", type=int, help="Cycles volume bounces (default: the scene's)")
        if name == "compare":
            p.add_argument(
                "--mode",
                choices=("single", "full"),
                default="full",
                help="single: single scattering on both sides; full: every term (default)",
            )
            p.add_argument(
                "--noise-estimate",
                action="store_true",
                help="split the samples over two seeds to measure Cycles' own noise",
            )
    _realtime_commands(sub, common, size)
    return parser


def _realtime_commands(sub, common, size) -> None:
    """The real-time viewport headless (docs/viewport.md): `preview` and `benchmark`."""
    from .core.quality import qualities

    levels = tuple(qualities())
    p = sub.add_parser("preview", help="replay the 3D viewport's temporal draw path from the scene camera")
    common(p, frame=False)
    size(p)
    p.add_argument("--frames", help="frames to draw, A-B or N (default: the current frame)")
    p.add_argument("--redraws", type=int, default=1, help="viewport redraws per frame (default 1; 16 fill every pixel)")
    p.add_argument(
        "--orbit", type=float, default=0.0, help="turn the camera by DEG degrees per frame about the vertical"
    )
    p.add_argument("--quality", choices=levels, help="quality level (default: the scene's settings)")
    p.add_argument("--naive", action="store_true", help="also write each frame's naive full-resolution march")
    p = sub.add_parser("benchmark", help="time the viewport's redraw against the naive march and EEVEE")
    common(p, frame=False)
    size(p)
    p.add_argument("--quality", choices=levels, help="quality level (default: the scene's settings)")


@contextlib.contextmanager
def _quiet(log: Path) -> Iterator[None]:
    """Send Blender's and Mesa's own chatter (render progress, EGL notices) to a log file so the user
    sees one summary line; with NUBIS_VERBOSE=1 everything stays on the terminal."""
    if os.environ.get("NUBIS_VERBOSE"):
        yield
        return
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    with open(log, "ab") as f:
        os.dup2(f.fileno(), 1)
        os.dup2(f.fileno(), 2)
        try:
            yield
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])


_console: list[Console] = []  # the running command's terminal (its stderr before any redirection)


def _terminal() -> Console:
    if not _console:
        _console.append(Console())
    return _console[-1]


def _progress(label: str):
    """A progress bar on the user's terminal (also while Blender's output goes to the log), or None."""
    return _terminal().progress(label)


# A field composite slower than this gets an estimate first, then a progress bar.
SLOW_COMPOSITE_S = 5.0


def _composite_progress(preset):
    from .core import fields

    seconds = fields.composite_seconds(preset.layers, preset.params["field_resolution"])
    if seconds < SLOW_COMPOSITE_S:
        return None
    res = preset.params["field_resolution"]
    _terminal().line(
        f"{PROG}: compositing {len(preset.layers)} field layers at {res}x{res} pixels, about {seconds:.0f} s"
    )
    return _progress("field")


_tracked: list[Path] = []


def _track_blender_tempdir() -> None:
    """Have an interrupt remove Blender's current session folder (it ends the process without Blender's
    teardown)."""
    if _tracked:
        interrupt.unregister(_tracked.pop())
    tmp = blender_tempdir()
    if tmp is not None:
        interrupt.register(tmp)
        _tracked.append(tmp)


def blender_tempdir() -> Path | None:
    """Blender's per-session temporary folder (/tmp/blender_XXXXXX), which only Blender's own teardown
    removes; the command line leaves without that teardown (__main__.py), so it removes it itself."""
    if "bpy" not in sys.modules:
        return None
    tmp = Path(sys.modules["bpy"].app.tempdir or ".")
    return tmp if tmp.name.startswith("blender_") and tmp.is_dir() else None


def load_scene(args, in_blender: bool):
    """The scene to work on: a saved .blend, a preset, or (inside Blender) the open file's cloudscape."""
    import bpy

    from .blender import ensure_registered, scene_io
    from .core.presets import load_preset

    if args.blend:
        path = Path(args.blend).expanduser()
        if not path.is_file():
            raise NubisError(f"the .blend file '{path}' does not exist: check the path")
        try:
            bpy.ops.wm.open_mainfile(filepath=str(path), load_ui=False)
        except RuntimeError as err:
            first = str(err).strip().splitlines()[-1] if str(err).strip() else "unreadable"
            raise NubisError(f"cannot open '{path}' ({first}): check that it is a Blender file") from None
        _track_blender_tempdir()
        ensure_registered()
        scene = bpy.context.scene
        if getattr(scene.nubis, "field_a", None) is None:
            raise NubisError(f"'{path}' holds no Nubis cloudscape: add one with New Cloudscape and save the file")
        return scene
    if in_blender and not args.preset and bpy.data.filepath and bpy.context.scene.nubis.field_a is not None:
        return bpy.context.scene
    preset = load_preset(args.preset or "default")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    _track_blender_tempdir()  # factory settings start a new session folder
    ensure_registered()
    scene = bpy.context.scene
    scene_io.apply_preset(scene, preset, progress=_composite_progress(preset))
    return scene


def run(argv: Sequence[str], in_blender: bool = False) -> int:
    """Run one command; returns the exit code. Never raises for user errors."""
    try:
        args = build_parser().parse_args(list(argv))
    except SystemExit as exc:  # --help
        return int(exc.code or 0)
    except NubisError as err:
        print(f"{PROG}: error: {err}", file=sys.stderr)
        return 2
    # One log file for Blender's chatter, kept only when an internal fault needs it.
    fd, log_name = tempfile.mkstemp(prefix="nubis-", suffix=".log")
    os.close(fd)
    log = Path(log_name)
    console = Console()
    _console.append(console)
    interrupt.register(log)
    keep_log = False
    try:
        with interrupt.handle_signals(console.fd):
            try:
                summary = _execute(args, in_blender, log)
            except NubisError as err:
                interrupt.stop()  # a failure caused by an interrupt's clean-up ends as the interrupt
                print(f"{PROG}: error: {err}", file=sys.stderr)
                return 1
            except Exception as err:  # an unexpected fault: one line, the details in the log
                interrupt.stop()
                keep_log = True
                with open(log, "a") as f:
                    traceback.print_exc(file=f)
                if os.environ.get("NUBIS_DEBUG"):
                    traceback.print_exc()
                print(f"{PROG}: internal error: {type(err).__name__}: {err} (details in {log})", file=sys.stderr)
                return 3
            interrupt.stop()
            print(summary)
            return 0
    finally:
        interrupt.unregister(log)
        if not keep_log:
            log.unlink(missing_ok=True)
        if _tracked:
            interrupt.unregister(_tracked.pop())
        _console.remove(console)
        console.close()


def _execute(args, in_blender: bool, log: Path) -> str:
    start = time.perf_counter()
    cmd = args.command
    check_arguments(args)
    # Check the destination before minutes of work, and never leave a partial file there.
    if cmd in ("compare", "preview", "benchmark"):
        out = check_output_dir(args.out)
    elif cmd == "bake":
        out = check_output_path(args.out, (".vdb",))
    else:
        out = check_output_path(args.out, IMAGE_SUFFIXES)
    if getattr(args, "motion", None):
        args.motion = check_output_path(args.motion, (".exr",))
    voxel = getattr(args, "voxel_size", None)
    if cmd == "bake":
        _check_bake_arguments(args, out)

    with _quiet(log):
        from .blender import pipeline
        from .render.gpu_context import ensure_gpu_context

        _track_blender_tempdir()
        scene = load_scene(args, in_blender)
        if getattr(args, "frame", None) is not None:
            scene.frame_set(args.frame)
        pipeline.check_scene(scene)
        ensure_gpu_context()
    label = scene.nubis.preset or "scene"

    if cmd == "render":
        w, h = pipeline.resolution(scene, args.width, args.height)
        with _quiet(log), staging.output_set() as outputs:  # the image and its motion vectors together
            rgba = pipeline.render_viewport(scene, w, h, passes=args.passes)
            pipeline.save_render(scene, outputs.stage(out), rgba)
            if args.motion:
                from .core.imageio import write_image

                write_image(outputs.stage(args.motion), pipeline.render_motion(scene, w, h))
        cover = float((rgba[..., 3] > 0.05).mean()) * 100
        return f"rendered {label} at {w}x{h} ({cover:.0f}% cloud cover) in {time.perf_counter() - start:.1f} s -> {out}"
    if cmd == "bake" and (args.frames or args.distributed or "#" in out.name):
        return _bake_sequence(args, scene, out, voxel, log, label)
    if cmd == "bake":
        progress = _progress("baking")
        with _quiet(log):
            result = pipeline.bake(
                scene, out, voxel, progress, camera_only=args.camera_only, half=args.half, velocity=args.velocity
            )
        nx, ny, nz = result.plan.dims
        return (
            f"baked {label}: {nx}x{ny}x{nz} voxels of {result.plan.voxel_size:g} m, "
            f"{result.active_voxels} active, in {result.seconds:.1f} s -> {out}"
        )
    w, h = pipeline.resolution(scene, args.width, args.height)
    if cmd in ("preview", "benchmark"):
        return _realtime(cmd, args, scene, out, w, h, log, label, start)
    if cmd == "cycles":
        with _quiet(log):
            rgba = pipeline.render_cycles(scene, w, h, args.samples, voxel_size=voxel, bounces=args.bounces)
            pipeline.save_render(scene, out, rgba)
        return f"rendered {label} with Cycles at {w}x{h} in {time.perf_counter() - start:.1f} s -> {out}"
    with _quiet(log):
        if args.bounces is not None:
            scene.cycles.volume_bounces = args.bounces
        m = pipeline.compare(scene, out, w, h, args.samples, args.mode, voxel, args.noise_estimate)
    capped = (
        f" (reference march in {m['reference_view_steps']} of {scene.nubis.march_steps_max} view steps: "
        "the shader loop limit)"
        if m.get("reference_steps_capped")
        else ""
    )
    return (
        f"compared {label} ({args.mode}) at {w}x{h}: alpha RMSE {m['alpha_rmse']:.4f}, luminance error "
        f"{m['luminance_rel_error'] * 100:.1f}%, silhouette IoU {m['silhouette_iou']:.3f}{capped} "
        f"in {time.perf_counter() - start:.1f} s -> {out}"
    )


def _check_bake_arguments(args, out: Path) -> None:
    """--frames, the # padding and --distributed (Dask installed, a valid engine) before any work."""
    from .core import distributed, sequence

    if args.frames and args.frame is not None:
        raise NubisError("--frame and --frames exclude each other: give one frame or a range")
    if args.frames:
        sequence.sequence_paths(out, sequence.parse_frames(args.frames))
    if args.distributed:
        distributed.parse_engine(args.distributed)
        distributed.require()


def _bake_sequence(args, scene, out: Path, voxel, log: Path, label: str) -> str:
    """`bake --frames A-B` (files named with # padding) and `bake --distributed` (core/distributed.py)."""
    from .blender import farm
    from .core import distributed, sequence

    frames = sequence.parse_frames(args.frames) if args.frames else [scene.frame_current]
    engine = distributed.parse_engine(args.distributed) if args.distributed else None
    options = farm.BakeOptions(voxel, args.camera_only, None, args.half, args.velocity)
    progress = _progress("baking")
    with _quiet(log):
        source = farm.source_of(scene, args.preset, args.blend) if engine else None
        r = farm.bake_sequence(scene, out, frames, options, engine, source, progress)
    first = r.results[0]
    nx, ny, nz = first.plan.dims
    on = f" on {r.engine}" if r.engine else ""
    where = first.path if len(frames) == 1 else f"{first.path.parent / out.name} ({len(frames)} files)"
    return (
        f"baked {label}, frame{'s' if len(frames) > 1 else ''} {args.frames or frames[0]}: {nx}x{ny}x{nz} voxels "
        f"of {first.plan.voxel_size:g} m, {sum(x.active_voxels for x in r.results)} active{on}, "
        f"in {r.seconds:.1f} s -> {where}"
    )


def _realtime(cmd: str, args, scene, out: Path, w: int, h: int, log: Path, label: str, start: float) -> str:
    from .blender import preview

    if cmd == "preview":
        frames = preview.parse_frames(args.frames, scene.frame_current)
        progress = _progress("preview")
        with _quiet(log):
            r = preview.preview(
                scene, out, w, h, frames, args.redraws, args.orbit, args.naive, args.quality, progress=progress
            )
        ms = sorted(x for frame in r.redraw_ms for x in frame)
        median = ms[len(ms) // 2]
        naive = f", naive {sorted(r.naive_ms)[len(r.naive_ms) // 2]:.0f} ms" if r.naive_ms else ""
        return (
            f"previewed {label} at {w}x{h} ({r.quality}): {len(frames)} frame(s) x {args.redraws} redraw(s), "
            f"median redraw {median:.1f} ms{naive}, in {time.perf_counter() - start:.1f} s -> {out}"
        )
    with _quiet(log):
        result = preview.benchmark(scene, out, w, h, args.quality)
    print(preview.table(result))
    return (
        f"benchmarked {label} at {w}x{h} ({result['quality']}): naive {result['naive_ms']:.0f} ms, redraw "
        f"{result['redraw_ms']:.1f} ms ({result['naive_over_redraw']:.1f}x), EEVEE {result['eevee_ms']:.0f} ms "
        f"({result['eevee_over_redraw']:.0f}x) in {time.perf_counter() - start:.1f} s -> {out}"
    )


def check_arguments(args) -> None:
    """Every numeric option within what the program can serve (core/limits.py), before any work."""
    for name, (lo, hi) in (
        ("width", limits.SIZE_RANGE),
        ("height", limits.SIZE_RANGE),
        ("samples", limits.SAMPLES_RANGE),
        ("bounces", limits.BOUNCES_RANGE),
        ("passes", limits.PASSES_RANGE),
        ("frame", limits.FRAME_RANGE),
    ):
        limits.check_int(f"--{name}", getattr(args, name, None), lo, hi)
    limits.check_voxel_size("--voxel-size", getattr(args, "voxel_size", None))


def main(argv: Sequence[str] | None = None) -> int:
    return run(sys.argv[1:] if argv is None else argv)
