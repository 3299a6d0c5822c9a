"""The bake or render the interface runs while the artist keeps working, one at a time.

Bake VDB, Bake Sequence and Render Clouds are modal: a timer steps them a group of tiles at a time and the
artist goes on orbiting, scrubbing, editing, undoing and saving meanwhile. Each reads the scene once when
it starts (blender/jobs/snapshot.py, pipeline.viewport_shot) and nothing of it afterwards, so none of that
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
import traceback
from collections.abc import Callable, Iterator

import bpy

from ...core.errors import NubisError
from ..host import handlers, mainthread
from . import pipeline, snapshot


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


class ModalSteps:
    """Long work the artist can cancel: it runs a group of tiles per timer tick (pipeline.bake_steps,
    pipeline.render_shot_steps), the status bar shows its progress, Esc stops it and nothing is written.
    It reads the scene once, when it starts (blender/jobs/snapshot.py), so the artist keeps working meanwhile;
    one runs at a time, and opening another file or quitting cancels it (above). In background
    mode (scripts, the tests) it runs to its end at once."""

    doing = "baking"
    cancelled = "Bake cancelled: no file was written, earlier bakes are untouched"
    _progress = None
    _work = None

    def jobs(self, context):
        """(label, stepped bake) pairs, run in order."""
        raise NotImplementedError

    def finished(self, context, results) -> str:
        raise NotImplementedError

    def execute(self, context):
        running = current()
        if running is not None:  # before the scene is read: a refused start costs nothing
            self.report({"ERROR"}, refusal(running))
            return {"CANCELLED"}
        try:
            self._work = Work(self.doing, list(self.jobs(context)))
        except NubisError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        if bpy.app.background:
            try:
                message = self.finished(context, self._work.run())
            except NubisError as err:
                self.report({"ERROR"}, str(err))
                return {"CANCELLED"}
            self.report({"INFO"}, message)
            return {"FINISHED"}
        self.start(context)
        context.window_manager.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def start(self, context) -> None:
        """Register the work as this operator's (above) and show its progress."""
        start(self._work)
        self._work.owner = self
        self._progress = _Progress(context)
        self._work.on_cancel = self._progress.end

    def _end(self, context) -> None:
        """Unregister the work and close its steps (a cancelled bake writes nothing); any number of times."""
        finish(self._work)
        try:
            self._work.close()
        finally:
            if self._progress is not None:
                self._progress.end()

    def cancel(self, context) -> None:
        """Blender ends the operator without its modal handler (its window closed): the work ends with it."""
        self._end(context)

    def modal(self, context, event):
        if self._work.cancelled:  # stopped from outside (above), which cleaned up and said why
            return {"CANCELLED"}
        try:
            return self._tick(context, event)
        except Exception as err:  # whatever failed, the work ends here: left running it refuses every later one
            self._end(context)
            self.report({"ERROR"}, self._failure(err))
            return {"CANCELLED"}

    def _tick(self, context, event):
        if event.type == "ESC":
            self._end(context)
            self.report({"WARNING"}, self.cancelled)
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        label = self._work.label
        overall = self._work.step()
        context.window_manager.progress_update(int(overall * 100))
        if context.workspace is not None:
            context.workspace.status_text_set(f"Nubis: {self.doing} {label}, {overall * 100:.0f}% (Esc cancels)")
        if not self._work.done:
            return {"RUNNING_MODAL"}
        self._end(context)
        self.report({"INFO"}, self.finished(context, self._work.results))
        return {"FINISHED"}

    def _failure(self, err: Exception) -> str:
        """The sentence a failed step reports: a NubisError's own, else the unexpected error, traced to the
        console."""
        if isinstance(err, NubisError):
            return str(err)
        traceback.print_exc()
        return (
            f"{self.doing.capitalize()} stopped on an unexpected error ({type(err).__name__}: {err}): "
            "see the system console for details, and report it"
        )


class _Progress:
    """A modal work's timer, progress bar and status text, taken down once (by its operator, or by
    cancel when a file is opened)."""

    def __init__(self, context):
        wm = context.window_manager
        self.timer = wm.event_timer_add(0.01, window=context.window)
        wm.progress_begin(0, 100)
        self.shown = True

    def end(self) -> None:
        if not self.shown:
            return
        self.shown = False
        _end_progress(self.timer)


def _end_progress(timer) -> None:
    """Take the work's timer, progress bar and status text down (from its operator, or from cancel)."""
    context = bpy.context
    wm = context.window_manager
    if timer is not None:
        wm.event_timer_remove(timer)
    wm.progress_end()
    if context.workspace is not None:
        context.workspace.status_text_set(None)
