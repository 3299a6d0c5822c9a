"""The bake or render the interface runs while the artist keeps working, one at a time.

Bake VDB, Bake Sequence and Render Clouds are modal: a timer steps them a group of tiles at a time and the
artist goes on orbiting, scrubbing, editing, undoing and saving meanwhile. Each reads the scene once when
it starts (blender/snapshot.py, pipeline.viewport_shot) and nothing of it afterwards, so none of that
changes its result. What the artist does to the work itself is defined here:

- a second bake or render while one runs is refused with a sentence (start() raises);
- opening another file, File > New, and quitting cancel it: its steps are closed before the file goes, so
  nothing is written and an earlier file at its path stays as it was (files are written after the last
  tile, atomically);
- Esc cancels it (the operator's modal handler);
- a step that fails ends it: the operator says the sentence and clears it, and a work whose operator is
  gone all the same (Blender freed it after an error) is cleared when the next one starts, so a failed
  bake never leaves every later one refused.
"""

from __future__ import annotations

import atexit
import os
from collections.abc import Callable, Iterator

import bpy

from ..core.errors import NubisError
from . import handlers, mainthread, pipeline, snapshot


class Work:
    """A list of (label, steps) jobs run in order; each `steps` is a generator yielding the fraction done
    and returning its result (pipeline.bake_steps, pipeline.render_shot_steps)."""

    def __init__(self, doing: str, jobs: list[tuple[str, Iterator]]):
        self.doing = doing
        self.jobs = list(jobs)
        self.results: list = []
        self.cancelled = ""  # why it was stopped from outside, once it was
        self.on_cancel: Callable[[], None] | None = None  # the operator's clean-up (timer, progress)
        self.owner = None  # the operator stepping it (None when a script steps it)

    @property
    def label(self) -> str:
        return self.jobs[0][0] if self.jobs else ""

    @property
    def done(self) -> bool:
        return not self.jobs

    def step(self) -> float:
        """One step of the current job; the overall fraction done after it."""
        _label, steps = self.jobs[0]
        try:
            fraction = next(steps)
        except StopIteration as finished:
            self.results.append(finished.value)
            self.jobs.pop(0)
            fraction = 1.0
        total = len(self.results) + len(self.jobs)
        return (len(self.results) + (0.0 if fraction >= 1.0 else fraction)) / max(total, 1)

    def run(self) -> list:
        """To its end, at once (background mode, scripts)."""
        while self.jobs:
            self.step()
        return self.results

    def close(self) -> None:
        """Close every job's steps: a bake not finished writes nothing, a render leaves its image alone."""
        jobs, self.jobs = self.jobs, []
        for _label, steps in jobs:
            steps.close()


def bake_jobs(
    scene, path: str, voxel_size: float | None = None, tiles_per_step: int | None = None
) -> list[tuple[str, Iterator]]:
    """Bake VDB with the scene's bake settings: one job, its snapshot taken now; `tiles_per_step`
    pipeline.TILES_PER_STEP unless given."""
    options = snapshot.scene_options(scene, voxel_size)
    steps = pipeline.bake_steps(scene, path, options, tiles_per_step or pipeline.TILES_PER_STEP)
    return [(os.path.basename(path), steps)]


def sequence_jobs(
    scene, folder: str, frames: list[int], tiles_per_step: int | None = None
) -> list[tuple[str, Iterator]]:
    """Bake Sequence: one job per frame, `clouds_NNNN.vdb` in `folder`, every frame's snapshot taken now
    (the timeline is back on its frame before the first tile)."""
    options = snapshot.scene_options(scene)
    snaps = snapshot.take_sequence(scene, frames, options)
    return [
        (
            f"frame {snap.frame}",
            pipeline.snapshot_steps(
                snap,
                os.path.join(folder, f"clouds_{snap.frame:04d}.vdb"),
                options.half,
                tiles_per_step or pipeline.TILES_PER_STEP,
            ),
        )
        for snap in snaps
    ]


def render_jobs(scene) -> list[tuple[str, Iterator]]:
    """Render Clouds from the scene camera at the render size: one job, its shot taken now."""
    w, h = pipeline.resolution(scene, None, None)
    return [(f"{w}x{h}", pipeline.render_shot_steps(pipeline.viewport_shot(scene, w, h)))]


_current: list[Work] = []


def current() -> Work | None:
    """The running work; one whose operator is gone is cleared first (it can step no more)."""
    while _current and _orphaned(_current[0]):
        _clear(_current[0])
    return _current[0] if _current else None


def _orphaned(work: Work) -> bool:
    """Its operator was freed without ending it: any look at a freed operator raises ReferenceError."""
    if work.owner is None:
        return False
    try:
        getattr(work.owner, "_work", None)
    except ReferenceError:
        return True
    return False


def _clear(work: Work) -> None:
    """Unregister `work`, close its steps (nothing is written) and take its operator's progress down."""
    finish(work)
    work.close()
    if work.on_cancel is not None:
        try:
            work.on_cancel()
        except (ReferenceError, RuntimeError):
            pass  # the window it showed progress in is gone


def start(work: Work) -> Work:
    """Make `work` the running one, or refuse when another runs."""
    running = current()
    if running is not None:
        work.close()
        raise NubisError(refusal(running))
    _current.append(work)
    return work


def refusal(running: Work) -> str:
    what = f"{running.doing} {running.label}".strip()
    return f"Nubis is already {what}: wait for it to finish, or press Esc to cancel it, then start again"


def finish(work: Work) -> None:
    """`work` ended (run to its end, failed or cancelled by Esc)."""
    if work in _current:
        _current.remove(work)


def cancel(reason: str) -> Work | None:
    """Stop the running work from outside (a file load, quitting): its steps are closed, its operator
    cleans up, and the artist is told why. Returns the work it stopped."""
    work = current()
    if work is None:
        return None
    work.cancelled = reason
    _clear(work)
    mainthread.report(f"{work.doing.capitalize()} cancelled ({reason}): nothing was written", "WARNING")
    return work


@bpy.app.handlers.persistent
def on_load_pre(*_args) -> None:
    """Another file is opened, or File > New: the work belongs to the file being closed."""
    cancel("another file was opened")


def _at_exit() -> None:
    cancel("Blender quit")


_HANDLERS = ((bpy.app.handlers.load_pre, on_load_pre),)


def register() -> None:
    handlers.add(_HANDLERS)
    atexit.register(_at_exit)


def unregister() -> None:
    cancel("the extension was disabled")
    handlers.remove(_HANDLERS)
    atexit.unregister(_at_exit)
