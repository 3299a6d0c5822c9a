"""The user's terminal, kept apart from Blender's chatter: the command line sends file descriptors 1
and 2 to a log while Blender works, so progress, warnings and the interrupt line are written to a
copy of the terminal's stderr made before that. No bpy here."""

from __future__ import annotations

import contextlib
import os
import sys
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

_bars: set[int] = set()  # descriptors whose last line is an unfinished progress bar
# Every write to a terminal and the bookkeeping of its bar go under this lock, so that the interrupt line,
# written by the signal watcher thread while the main thread draws the bar, never lands inside a bar's line
# or under a later bar: it is the last line the user reads (docs/measurements.md#terminal-output).
_lock = threading.Lock()


def _put(fd: int, text: str) -> None:
    """One write to a terminal; the caller holds ``_lock``. A closed or gone terminal is not an error."""
    with contextlib.suppress(OSError):
        os.write(fd, text.encode("utf-8", "replace"))


def _end_bar(fd: int) -> None:
    if fd in _bars:
        _bars.discard(fd)
        _put(fd, "\n")


def break_bar(fd: int) -> None:
    """End an unfinished progress bar's line on ``fd``, so that the next message (an error, the interrupt
    line) starts a line of its own and the bar stays visible above it."""
    with _lock:
        _end_bar(fd)


def last_words(fd: int | None, text: str) -> None:
    """Write ``text`` as the last line this process writes to any terminal: an unfinished bar's line is
    ended first, and every later write, from any thread, waits for good (the caller ends the process)."""
    _lock.acquire()  # never released
    if fd is not None:
        _end_bar(fd)
        _put(fd, text)


class Console:
    def __init__(self) -> None:
        self.fd = os.dup(2)
        self.tty = os.isatty(self.fd)

    def write(self, text: str) -> None:
        with _lock:
            _put(self.fd, text)

    def line(self, text: str) -> None:
        with _lock:
            _end_bar(self.fd)
            _put(self.fd, text.rstrip("\n") + "\n")

    def progress(self, label: str) -> Callable[[float], None] | None:
        """A progress bar on a terminal; nothing when stderr is a file or a pipe (logs stay clean)."""
        if not self.tty:
            return None

        def report(fraction: float) -> None:
            fraction = min(max(fraction, 0.0), 1.0)
            bar = "#" * int(fraction * 30)
            text = f"\r{label} [{bar:<30}] {fraction * 100:5.1f}%" + ("\n" if fraction >= 1.0 else "")
            with _lock:
                _put(self.fd, text)
                (_bars.discard if fraction >= 1.0 else _bars.add)(self.fd)

        return report

    def close(self) -> None:
        with contextlib.suppress(OSError):
            os.close(self.fd)


def reserve_standard_fds() -> set[int]:
    """Open /dev/null on any of descriptors 0, 1 and 2 that is closed (`2>&-`), and return which were.
    Otherwise the next file opened takes the number: the log, then its copy made for the terminal, and
    Blender's chatter meant for stderr lands in whatever file holds 2. Python leaves sys.stderr None then,
    and print(file=None) writes to stdout: the streams get the /dev/null descriptors instead."""
    closed = set()
    for fd in (0, 1, 2):
        try:
            os.fstat(fd)
        except OSError:
            closed.add(fd)
            null = os.open(os.devnull, os.O_RDWR)
            if null != fd:
                os.dup2(null, fd)
                os.close(null)
    for fd, name in ((1, "stdout"), (2, "stderr")):
        if getattr(sys, name) is None:
            setattr(sys, name, open(fd, "w", buffering=1, closefd=False, errors="backslashreplace"))  # noqa: SIM115
    return closed


_stack: list[Console] = []  # the running command's terminal (its stderr before any redirection)


def push(console: Console) -> None:
    _stack.append(console)


def pop(console: Console) -> None:
    if console in _stack:
        _stack.remove(console)


def current() -> Console:
    if not _stack:
        _stack.append(Console())
    return _stack[-1]


def progress(label: str) -> Callable[[float], None] | None:
    """A progress bar on the user's terminal (also while Blender's output goes to the log), or None."""
    return current().progress(label)


@contextlib.contextmanager
def quiet(log: Path) -> Iterator[None]:
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
