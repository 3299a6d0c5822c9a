"""Frame sequences of bakes: Blender's `#` frame padding (`clouds_####.vdb` -> `clouds_0007.vdb`),
the name its Volume object loads as a sequence, and `--frames A-B`."""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

from .errors import NubisError
from .limits import FRAME_RANGE

MAX_SEQUENCE = 100_000  # frames in one command
_HASHES = re.compile(r"#+")


def has_padding(path: str | Path) -> bool:
    return "#" in Path(path).name


def frame_path(pattern: str | Path, frame: int) -> Path:
    """The file of `frame`: the last run of `#` in the file name becomes the frame number padded with
    zeros to the run's length (Blender's convention; a negative frame keeps its sign in front)."""
    pattern = Path(pattern)
    runs = list(_HASHES.finditer(pattern.name))
    if not runs:
        return pattern
    run = runs[-1]
    number = f"{abs(frame):0{len(run.group())}d}"
    if frame < 0:
        number = "-" + number
    return pattern.with_name(pattern.name[: run.start()] + number + pattern.name[run.end() :])


def parse_frames(text: str, most: int | None = None, what: str = "bake") -> list[int]:
    """'A-B' or 'N' to the frames it names, within Blender's frame range and at most `most` of them
    (MAX_SEQUENCE by default) for one command that does `what` to them."""
    most = MAX_SEQUENCE if most is None else most
    m = re.fullmatch(r"\s*(-?\d+)\s*(?:-\s*(-?\d+)\s*)?", text or "")
    if not m:
        raise NubisError(f"--frames takes a frame or a range like 1-24, not '{text}'")
    a = int(m.group(1))
    b = int(m.group(2)) if m.group(2) is not None else a
    if b < a:
        raise NubisError(f"--frames {text}: the last frame comes before the first; write {b}-{a}")
    lo, hi = FRAME_RANGE
    if a < lo or b > hi:
        raise NubisError(f"--frames {text} is out of range: Blender's frames run from {lo} to {hi}")
    if b - a + 1 > most:
        raise NubisError(f"--frames {text} names {b - a + 1} frames: {what} at most {most} in one command")
    return list(range(a, b + 1))


def sequence_paths(pattern: str | Path, frames: list[int]) -> list[Path]:
    """One file per frame; several frames need a `#` run in the name, or they would overwrite each other."""
    if len(frames) > 1 and not has_padding(pattern):
        name = Path(pattern)
        raise NubisError(
            f"--out '{pattern}' has no '#' for the frame number: write it as "
            f"'{name.with_name(name.stem + '_####' + name.suffix)}' to bake frames {frames[0]}-{frames[-1]}"
        )
    return [frame_path(pattern, f) for f in frames]


def human_bytes(n: float) -> str:
    for unit in ("bytes", "KB", "MB", "GB", "TB"):
        if n < 1000 or unit == "TB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1000
    raise AssertionError("unreachable")


def check_disk_space(
    pattern: str | Path, frames: list[int], frame_bytes: int, half: bool = False, free: int | None = None
) -> str:
    """Before a sequence is baked: whether its files (`frame_bytes` each, at most: the bake plan's
    file_bytes_estimate) fit in the free space of their folder, all of them at once, as the set is
    staged whole before it replaces an earlier one (staging.py). Returns the estimate as a line to
    print; refuses, naming how many frames fit, when they do not. `half`: the grids are half floats
    already; `free` overrides the measured space."""
    folder = Path(pattern).parent if str(Path(pattern).parent) else Path(".")
    if free is None:
        try:
            free = shutil.disk_usage(folder).free
        except OSError:  # not there yet or not readable: the writes will say so
            return ""
    count = len(frames)
    total = count * frame_bytes
    where = os.fspath(folder)
    if total > free:
        fit = free // max(frame_bytes, 1)
        if fit >= 1:
            todo = f"bake at most {fit} frame{'s' * (fit > 1)} at a time (--frames {frames[0]}-{frames[0] + fit - 1}), "
        else:
            todo = "free some space, "
        raise NubisError(
            f"--frames {frames[0]}-{frames[-1]} would write {count} files of up to {human_bytes(frame_bytes)} "
            f"each, up to {human_bytes(total)}, but '{where}' has {human_bytes(free)} free: {todo}or bake "
            + ("coarser voxels (--voxel-size)" if half else "coarser voxels (--voxel-size) or half floats (--half)")
        )
    return (
        f"nubis: {count} frames of up to {human_bytes(frame_bytes)} each, up to {human_bytes(total)} "
        f"of the {human_bytes(free)} free in '{where}'"
    )
