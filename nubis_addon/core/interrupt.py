"""Interrupts: SIGINT, SIGTERM and SIGHUP (a closed terminal) end a run at once, with one line, the
conventional exit code (128 + signal: 130, 143 and 129) and no temporary file left behind.

Python runs a signal handler only between bytecodes of the main thread, so a Ctrl-C during a long
Cycles render (C code, minutes) would otherwise wait for the render to finish. Instead the signal's
number is written to a wake-up pipe by Python's C-level handler, and a watcher thread (Blender
releases the GIL while it renders) removes every registered temporary path and leaves with
``os._exit``: no teardown of Blender, which is what crashed after a KeyboardInterrupt.

Commits of staged outputs run inside :func:`deferred`, so an interrupt waits until a set of files
is either wholly in place or not at all (see ``staging.py``). No bpy here: every command can use it.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import signal
import socket
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path

from . import console

MESSAGE = "nubis: interrupted\n"
# SIGHUP does not exist on Windows.
SIGNALS = tuple(s for s in (signal.SIGINT, signal.SIGTERM, getattr(signal, "SIGHUP", None)) if s is not None)

# Held while dying (from before the snapshot of the registered paths until os._exit), while committing
# outputs and while a temporary path is made and registered: a path is either registered before the
# snapshot or never made. (The main thread runs on between bytecodes while the watcher cleans up.)
_lock = threading.Lock()
_pending: list[int] = []  # signals received and not yet acted on
_paths: dict[str, None] = {}  # registered temporary files and folders, in registration order
_installed: dict = {}


# Temporary files and folders carry the machine and the process that made them ("nubis-world-HOST-PID-..."),
# so that a later run can tell the litter of a killed run (SIGKILL, power loss: nothing cleans up) from
# the files of a run still going, and remove only the former (sweep_temp). The host keeps a temporary
# folder shared between machines safe: another machine's process ids mean nothing here.
HOST = re.sub(r"[^A-Za-z0-9.]", "_", socket.gethostname()) or "host"
_OWNED = re.compile(r"nubis-[a-z]+-" + re.escape(HOST) + r"-(\d+)-")
# Blender names its session folder itself (blender_XXXXXX): a marker file inside says whose it is.
_MARKER = re.compile(r"\.nubis-" + re.escape(HOST) + r"-(\d+)")


def owned_prefix(kind: str) -> str:
    """The prefix of a temporary name of this process: ``nubis-KIND-HOST-PID-``."""
    return f"nubis-{kind}-{HOST}-{os.getpid()}-"


def process_alive(pid: int) -> bool:
    """Whether a process of this machine with this id exists (one of another user's counts as alive)."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def sweep_temp(folder: str | os.PathLike | None = None) -> None:
    """Remove from the temporary folder what runs of this machine left when they were killed: the
    temporary files and folders named by owned_prefix, and Blender's session folders marked by
    track_blender_tempdir, of processes that no longer exist. Nothing else is touched (another user's
    or a running process's files, logs kept for an internal error, Blender's own unmarked folders)."""
    folder = Path(folder or tempfile.gettempdir())
    with contextlib.suppress(OSError):
        for entry in os.scandir(folder):
            m = _OWNED.match(entry.name)
            if m is None and entry.name.startswith("blender_") and entry.is_dir(follow_symlinks=False):
                m = _blender_owner(entry.path)
            if m is not None and not process_alive(int(m.group(1))):
                remove_path(entry.path)


def _blender_owner(path: str) -> re.Match | None:
    with contextlib.suppress(OSError):
        for entry in os.scandir(path):
            m = _MARKER.fullmatch(entry.name)
            if m is not None:
                return m
    return None


def register(path: str | os.PathLike) -> None:
    """Remove ``path`` (a file or a whole folder) if the run is interrupted."""
    _paths[os.fspath(path)] = None


@contextlib.contextmanager
def temporary_dir(prefix: str) -> Iterator[str]:
    """A private temporary folder, registered from the moment it exists and removed at the end; its name
    is ``prefix`` ("nubis-world-"), the host and the process id, so that sweep_temp finds it after a
    SIGKILL."""
    with deferred():
        path = tempfile.mkdtemp(prefix=f"{prefix}{HOST}-{os.getpid()}-")
        register(path)
    try:
        yield path
    finally:
        unregister(path)
        shutil.rmtree(path, ignore_errors=True)


def unregister(path: str | os.PathLike) -> None:
    _paths.pop(os.fspath(path), None)


def remove_registered() -> None:
    """Remove every registered path, newest first (a staging folder may hold a nested one)."""
    for path in reversed(list(_paths)):
        remove_path(path)
    _paths.clear()


def remove_path(path: str | os.PathLike) -> None:
    """Delete a file or a folder tree. A folder is first renamed away, so that a writer still working
    in it (the main thread inside a C call, when an interrupt cleans up) can create nothing new under
    its old path; then its tree is removed."""
    path = os.fspath(path)
    if os.path.isdir(path) and not os.path.islink(path):
        doomed = f"{path}-x"
        try:
            os.rename(path, doomed)
        except FileNotFoundError:
            return
        except OSError:
            doomed = path
        for _attempt in range(20):
            shutil.rmtree(doomed, ignore_errors=True)
            if not os.path.exists(doomed):
                return
            time.sleep(0.01)
        return
    with contextlib.suppress(FileNotFoundError, OSError):
        os.unlink(path)


def pending() -> bool:
    """True once SIGINT or SIGTERM has arrived: a commit then keeps the earlier outputs instead."""
    return bool(_pending)


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """Run a short block that an interrupt must not cut in half: moving outputs into place, making a
    temporary path and registering it. Not reentrant: never nest two."""
    with _lock:
        yield


def stop() -> None:
    """If SIGINT or SIGTERM has arrived (see :func:`pending`), end the process as the watcher would;
    otherwise return."""
    if _pending:
        _die(_pending[0])


def _die(signum: int) -> None:
    _lock.acquire()  # never released: the process ends here
    remove_registered()
    console.last_words(_installed.get("message_fd"), MESSAGE)
    os._exit(128 + signum)


def _watch(read_fd: int) -> None:
    while True:
        try:
            data = os.read(read_fd, 16)
        except OSError:
            return
        if not data:
            return
        for signum in data:
            if signum in SIGNALS:
                _pending.append(signum)
                _die(signum)


def _note_in_main_thread(signum, frame) -> None:
    """The watcher thread acts on the signal; the main thread only notes it, which it does as soon as
    the C call it was in returns, possibly before the watcher gets to run: a commit about to start
    then sees it."""
    _pending.append(signum)


@contextlib.contextmanager
def handle_signals(message_fd: int | None = None) -> Iterator[None]:
    """Within the block, SIGINT and SIGTERM print ``nubis: interrupted`` to ``message_fd`` (the
    terminal, even while Blender's chatter is redirected to a log), remove the registered temporary
    paths and exit with 130 or 143. Outside the main thread this does nothing (Python allows signal
    handlers only there)."""
    if _installed or threading.current_thread() is not threading.main_thread():
        yield
        return
    read_fd, write_fd = os.pipe()
    os.set_blocking(write_fd, False)
    previous = {s: signal.getsignal(s) for s in SIGNALS}
    old_wakeup = signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
    for s in SIGNALS:
        signal.signal(s, _note_in_main_thread)
    _installed.update(message_fd=message_fd)
    watcher = threading.Thread(target=_watch, args=(read_fd,), name="nubis-signals", daemon=True)
    watcher.start()
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler if handler is not None else signal.SIG_DFL)
        signal.set_wakeup_fd(old_wakeup)
        os.close(write_fd)  # the watcher reads end-of-file and returns (or ends a late-interrupted run)
        watcher.join(timeout=1.0)
        os.close(read_fd)
        _installed.clear()
        _pending.clear()


_tracked: list[Path] = []


def blender_tempdir() -> Path | None:
    """Blender's per-session temporary folder (/tmp/blender_XXXXXX), which only Blender's own teardown
    removes; the command line leaves without that teardown (__main__.py), so it removes it itself.
    Found through the loaded bpy module, so this module never imports bpy."""
    if "bpy" not in sys.modules:
        return None
    tmp = Path(sys.modules["bpy"].app.tempdir or ".")
    return tmp if tmp.name.startswith("blender_") and tmp.is_dir() else None


def track_blender_tempdir() -> None:
    """Have an interrupt remove Blender's current session folder (it ends the process without Blender's
    teardown); call again after anything that starts a new session folder (loading factory settings)."""
    untrack_blender_tempdir()
    tmp = blender_tempdir()
    if tmp is not None:
        register(tmp)
        _tracked.append(tmp)
        # Whose folder it is, for sweep_temp after a SIGKILL (Blender picks the name, not Nubis).
        with contextlib.suppress(OSError):
            (tmp / f".nubis-{HOST}-{os.getpid()}").touch()


def untrack_blender_tempdir() -> None:
    if _tracked:
        unregister(_tracked.pop())
