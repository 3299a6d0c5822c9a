"""The headless command line, a stable contract:

    python -m nubis_addon render  [--preset NAME | --blend FILE] --out PATH [--width W --height H --frame F]
                                  [--passes N --motion PATH.exr] [--vdb FILE ... --with-cloudscape]
    python -m nubis_addon bake    [--preset NAME | --blend FILE] --out PATH.vdb [--frame F --voxel-size METRES
                                  --camera-only --half --velocity --frames A-B --distributed local:N|tcp://HOST:PORT]
    python -m nubis_addon cycles  [--preset NAME | --blend FILE] --out PATH [--samples N --width W --height H]
                                  [--frame F --bounces N --voxel-size METRES]
    python -m nubis_addon compare [--preset NAME | --blend FILE] --out DIR [--samples N --width W --height H]
                                  [--frame F --mode single|full --bounces N --voxel-size METRES --noise-estimate
                                  --noise-target PERCENT --reuse-reference --draft] [--vdb FILE ... --with-cloudscape]
    python -m nubis_addon preview [--preset NAME | --blend FILE] --out DIR [--width W --height H --frames A-B
                                  --redraws N --orbit DEG --quality Q --naive]
    python -m nubis_addon benchmark [--preset NAME | --blend FILE] --out DIR [--width W --height H --quality Q]
                                    [--eevee-samples N] [--vdb FILE ... --with-cloudscape]
    python -m nubis_addon panorama [--preset NAME | --blend FILE] --out PATH.exr [--width W --frame F]

and the same as ``blender -b [FILE.blend] --command nubis ...``. Each command prints a one-line summary and
exits 0, or prints a one-line error that says what to do and exits non-zero: 1 for a user error, 2 for a
bad command line, 3 for an internal fault (its log named in the message), 130 and 143 for SIGINT and
SIGTERM. A command's outputs appear together or not at all (core/staging.py). The full reference, every
option explained: docs/cli.md.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import sys
import tempfile
import traceback
import warnings
from collections.abc import Sequence
from pathlib import Path

from .core import console as terminal
from .core import distributed, interrupt, limits, sequence, vdbplacement, vdbread
from .core.console import Console
from .core.errors import NubisError
from .core.fsutil import check_output_dir, check_output_path, check_utf8_name
from .core.imageio import IMAGE_SUFFIXES
from .core.quality import qualities

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

    def vdb(p: argparse.ArgumentParser) -> None:
        p.add_argument(
            "--vdb",
            action="append",
            metavar="FILE",
            help="draw this OpenVDB cloud (repeatable; its float grid 'density', extinction per metre) with the "
            "preset's sky, sun and camera; the procedural clouds are off unless --with-cloudscape",
        )
        p.add_argument(
            "--with-cloudscape", action="store_true", help="with --vdb: keep the preset's procedural clouds too"
        )

    def size(p: argparse.ArgumentParser) -> None:
        p.add_argument("--width", type=int, help="image width in pixels (default: the scene's)")
        p.add_argument("--height", type=int, help="image height in pixels (default: the scene's)")

    p = sub.add_parser("render", help="render the viewport's clouds from the scene camera (PNG or EXR)")
    common(p)
    size(p)
    p.add_argument("--passes", type=int, default=1, help="average N jittered passes for a grain-free image")
    p.add_argument("--motion", help="also write motion vectors (dx, dy pixels per frame, distance, alpha) to an EXR")
    vdb(p)
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
        p.add_argument(
            "--bounces",
            type=int,
            help="Cycles volume bounces (default: the scene's for cycles; for compare's full mode, enough to "
            "converge, 256: docs/convergence.md)",
        )
        if name == "compare":
            vdb(p)
            p.add_argument(
                "--mode",
                choices=("single", "full"),
                default="full",
                help="single: single scattering on both sides; full: every term (default)",
            )
            p.add_argument(
                "--draft",
                action="store_true",
                help="a first look in about a minute: half the scene's width and height (unless given) and no "
                "reference-march diagnostic",
            )
            p.add_argument(
                "--noise-estimate",
                action="store_true",
                help="split the samples over two seeds to measure Cycles' own noise",
            )
            p.add_argument(
                "--noise-target",
                type=float,
                metavar="PERCENT",
                help="add samples (seed pairs, starting from --samples) until Cycles' own noise is at most this "
                "percentage of the luminance; implies --noise-estimate",
            )
            p.add_argument(
                "--reuse-reference",
                action="store_true",
                help="keep the Cycles image of an earlier comparison in --out when the bake and everything Cycles "
                "sees are unchanged (after a viewport-only edit): the viewport is rendered again, Cycles is not",
            )
    _realtime_commands(sub, common, size, vdb)
    p = sub.add_parser("panorama", help="write an equirectangular HDR of the clouds and the sky (a World environment)")
    common(p)
    p.add_argument(
        "--width", type=int, default=1024, help="panorama width in pixels, the height is half (default 1024)"
    )
    return parser


def _realtime_commands(sub, common, size, vdb) -> None:
    """The real-time viewport headless (docs/viewport.md): `preview` and `benchmark`."""
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
    vdb(p)
    p.add_argument("--quality", choices=levels, help="quality level (default: the scene's settings)")
    p.add_argument("--eevee-samples", type=int, default=16, metavar="N", help="EEVEE's samples in its row (default 16)")


_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")


def printable(text: str) -> str:
    """A message with its control characters escaped (\\x1b, \\x00): names from a preset, an image path or
    the command line reach the terminal as text, never as escape sequences that drive it."""
    return _CONTROL.sub(lambda m: f"\\x{ord(m.group()):02x}", str(text))


def run(argv: Sequence[str], in_blender: bool = False) -> int:
    """Run one command; returns the exit code. Never raises for user errors."""
    closed = terminal.reserve_standard_fds()
    try:
        args = build_parser().parse_args(list(argv))
    except SystemExit as exc:  # --help
        return int(exc.code or 0)
    except NubisError as err:
        print(f"{PROG}: error: {printable(err)}", file=sys.stderr)
        return 2
    interrupt.sweep_temp()  # what killed runs left in the temporary folder
    # One log file for Blender's chatter, kept only when an internal fault needs it (under a name of
    # its own then: the name it has while the run goes on is one that sweep_temp removes after a kill).
    with interrupt.deferred():  # made and registered together
        fd, log_name = tempfile.mkstemp(prefix=interrupt.owned_prefix("log"), suffix=".log")
        os.close(fd)
        log = Path(log_name)
        interrupt.register(log)
    console = Console()
    terminal.push(console)
    keep_log = False
    default_showwarning = warnings.showwarning
    warnings.showwarning = _console_warning(console, default_showwarning)
    try:
        with interrupt.handle_signals(console.fd):
            try:
                summary = _execute(args, in_blender, log)
            except NubisError as err:
                interrupt.stop()  # a failure caused by an interrupt's clean-up ends as the interrupt
                terminal.break_bar(console.fd)
                print(f"{PROG}: error: {printable(err)}", file=sys.stderr)
                return 1
            except Exception as err:  # an unexpected fault: one line, the details in the log
                interrupt.stop()
                keep_log = True
                with open(log, "a") as f:
                    traceback.print_exc(file=f)
                log = _kept(log)
                terminal.break_bar(console.fd)
                if os.environ.get("NUBIS_DEBUG"):
                    traceback.print_exc()
                print(
                    f"{PROG}: internal error: {type(err).__name__}: {printable(err)} (details in {log})",
                    file=sys.stderr,
                )
                return 3
            interrupt.stop()
            return _print_summary(summary, stdout_closed=1 in closed)
    finally:
        warnings.showwarning = default_showwarning
        interrupt.unregister(log)
        if not keep_log:
            log.unlink(missing_ok=True)
        interrupt.untrack_blender_tempdir()
        terminal.pop(console)
        console.close()


def _kept(log: Path) -> Path:
    """The log of an internal fault, moved to a name that sweep_temp leaves alone (the message names it)."""
    with interrupt.deferred():
        fd, name = tempfile.mkstemp(prefix="nubis-", suffix=".log")
        os.close(fd)
        try:
            os.replace(log, name)
        except OSError:
            os.unlink(name)
            return log
        interrupt.unregister(log)
        interrupt.register(name)
    return Path(name)


def _print_summary(summary: str, stdout_closed: bool = False) -> int:
    """The run's one line on stdout. A stdout that cannot be written (a full disk, /dev/full, a closed
    pipe, a closed descriptor) is said on stderr; the outputs are already in place, but scripts must not
    read success."""
    if stdout_closed:
        print(f"{PROG}: error: could not write the summary to standard output (it is closed)", file=sys.stderr)
        return 1
    try:
        print(summary, flush=True)
        return 0
    except OSError as err:
        # Python would try the same buffered line again at exit and print a traceback there.
        with contextlib.suppress(OSError):
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            os.close(devnull)
        reason = err.strerror or type(err).__name__
        print(f"{PROG}: error: could not write the summary to standard output ({reason})", file=sys.stderr)
        return 1


_PACKAGE = str(Path(__file__).resolve().parent)


def _console_warning(console: Console, fallback):
    """Warnings of this package go to the user's terminal as one line (Blender's chatter, and with it
    Python's default warning output, goes to the log that is deleted at exit); others go where they did."""

    def show(message, category, filename, lineno, file=None, line=None):
        if str(filename).startswith(_PACKAGE):
            console.line(f"{PROG}: warning: {printable(message)}")
        else:
            fallback(message, category, filename, lineno, file, line)

    return show


def _execute(args, in_blender: bool, log: Path) -> str:
    """Check the command line and the destination before minutes of work, then run the command
    (blender/headless/commands.py): it never leaves a partial file there."""
    check_arguments(args)
    if args.command in ("compare", "preview", "benchmark"):
        out = check_output_dir(args.out)
    elif args.command == "bake":
        out = check_output_path(args.out, (".vdb",))
    elif args.command == "panorama":
        out = check_output_path(args.out, (".exr",))
    else:
        out = check_output_path(args.out, IMAGE_SUFFIXES)
    if getattr(args, "motion", None):
        args.motion = check_output_path(args.motion, (".exr",))
        if _same_file(args.motion, out):
            raise NubisError(
                f"--out and --motion name the same file '{out}': give the motion vectors a file of their own"
            )
    if args.command == "bake":
        _check_bake_arguments(args, out)
    from .blender.headless import commands  # bpy loads only now: `--help` and argument errors stay fast

    return commands.execute(args, in_blender, log, out)


def _same_file(a: Path, b: Path) -> bool:
    """Whether two output paths are one file: the same path once resolved, or two links to one file."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist yet
        return False


def _check_bake_arguments(args, out: Path) -> None:
    """--frames, the # padding and --distributed (Dask installed, a valid engine) before any work."""
    if args.frames and args.frame is not None:
        raise NubisError("--frame and --frames exclude each other: give one frame or a range")
    if args.frames:
        sequence.sequence_paths(out, sequence.parse_frames(args.frames))
    if args.distributed:
        distributed.parse_engine(args.distributed)
        distributed.require()


def check_arguments(args) -> None:
    """Every numeric option within what the program can serve (core/limits.py), and output names the
    writers can take, before any work."""
    for flag in ("out", "motion"):
        if getattr(args, flag, None):
            check_utf8_name(f"--{flag}", getattr(args, flag))
    for name, (lo, hi) in (
        ("width", limits.SIZE_RANGE),
        ("height", limits.SIZE_RANGE),
        ("samples", limits.SAMPLES_RANGE),
        ("bounces", limits.BOUNCES_RANGE),
        ("passes", limits.PASSES_RANGE),
        ("frame", limits.FRAME_RANGE),
        ("redraws", limits.REDRAWS_RANGE),
        ("eevee_samples", limits.SAMPLES_RANGE),
    ):
        limits.check_int(f"--{name.replace('_', '-')}", getattr(args, name, None), lo, hi)
    limits.check_voxel_size("--voxel-size", getattr(args, "voxel_size", None))
    limits.check_orbit("--orbit", getattr(args, "orbit", None))
    if args.command == "preview" and args.frames:
        sequence.parse_frames(args.frames, limits.PREVIEW_FRAMES_MAX, "preview")
    files = getattr(args, "vdb", None) or []
    if len(files) > vdbplacement.MAX_CLOUDS:
        raise NubisError(
            f"--vdb names {len(files)} files: at most {vdbplacement.MAX_CLOUDS} VDB clouds are drawn at once"
        )
    for path in files:
        vdbread.check_fits(path)  # missing, damaged, no float grid, too large to draw: said before any work
    if getattr(args, "with_cloudscape", False) and not files:
        raise NubisError("--with-cloudscape goes with --vdb: the procedural clouds are on without it")
    limits.check_noise_target("--noise-target", getattr(args, "noise_target", None))


def main(argv: Sequence[str] | None = None) -> int:
    return run(sys.argv[1:] if argv is None else argv)
