"""All-or-nothing outputs: every file of a command is written into a hidden staging folder beside its
final place and moved into place together at the end.

A failure before the commit (an error, a full disk, an interrupt) removes the staging folders and
keeps the earlier set of outputs whole. The commit itself is a handful of renames inside the same
folders (atomic each, on one file system) run with interrupts deferred, so SIGINT and SIGTERM
cannot split a set. Staging folders are private (mode 0700): after a SIGKILL nothing readable sits
under an output's name, and the next run into that folder removes folders whose process is gone
(only this machine's: a shared folder may hold another machine's run in progress).
"""

from __future__ import annotations

import contextlib
import os
import re
import tempfile
from collections.abc import Iterator
from pathlib import Path

from . import interrupt
from .errors import NubisError

PREFIX = ".nubis-tmp-"
_HOST = interrupt.HOST
_STALE = re.compile(re.escape(f"{PREFIX}{_HOST}-") + r"(\d+)-")
_alive = interrupt.process_alive


def _prefix() -> str:
    return f"{PREFIX}{_HOST}-{os.getpid()}-"


def sweep_stale(folder: str | os.PathLike) -> None:
    """Remove staging folders left in ``folder`` by runs that were killed (SIGKILL, power loss)."""
    with contextlib.suppress(OSError):
        for entry in os.scandir(folder):
            m = _STALE.match(entry.name)
            if m and entry.is_dir(follow_symlinks=False) and not _alive(int(m.group(1))):
                interrupt.remove_path(entry.path)


_mode: list[int] = []


def _file_mode() -> int:
    """A new file's usual permissions. The umask is read from /proc where it can be: setting it to read
    it changes it for the whole process, Blender's other threads included, so that is done once only."""
    if not _mode:
        umask = None
        with contextlib.suppress(OSError, ValueError):
            for line in Path("/proc/self/status").read_text().splitlines():
                if line.startswith("Umask:"):
                    umask = int(line.split()[1], 8)
        if umask is None:
            umask = os.umask(0o022)
            os.umask(umask)
        _mode.append(0o666 & ~umask)
    return _mode[0]


class OutputSet:
    """Final paths and where each is staged; :meth:`commit` moves them all into place."""

    def __init__(self) -> None:
        self._dirs: dict[Path, Path] = {}  # final folder -> its staging folder
        self._files: dict[Path, Path] = {}  # final path -> staged path

    def stage(self, final: str | os.PathLike) -> Path:
        """The path to write ``final`` to; it appears under its own name only at the commit."""
        final = Path(final)
        folder = final.parent if str(final.parent) else Path(".")
        if final in self._files:
            return self._files[final]
        _check_replaceable(final)  # say so before the file is made, when the folder is already there
        if folder not in self._dirs:
            sweep_stale(folder)
            # Made and registered under the interrupt lock: a signal between the two would leave the
            # folder behind (the watcher removes only what is registered).
            with interrupt.deferred():
                staging = Path(tempfile.mkdtemp(prefix=_prefix(), dir=folder))
                interrupt.register(staging)
            self._dirs[folder] = staging
        staged = self._dirs[folder] / final.name
        self._files[final] = staged
        return staged

    def commit(self) -> list[Path]:
        """Move every staged file into place (in the order staged) and remove the staging folders."""
        mode = _file_mode()
        with interrupt.deferred():
            interrupted = interrupt.pending()
            missing = [str(f) for f, s in self._files.items() if not s.is_file()]
            if missing and not interrupted:
                raise RuntimeError(f"staged outputs were never written: {', '.join(missing)}")
            if not interrupted:
                # Every target first: a rename that fails half-way would leave a mixed set.
                for final in self._files:
                    _check_replaceable(final)
                for final, staged in self._files.items():
                    os.chmod(staged, mode)  # mkstemp-style 0600 files get a normal file's permissions
                    os.replace(staged, final)
            done = list(self._files)
            self._files.clear()
            self.discard()
        if interrupted:  # the signal came while the files were written: keep the earlier ones, and stop
            interrupt.stop()
        return done

    def discard(self) -> None:
        for staging in self._dirs.values():
            interrupt.remove_path(staging)
            interrupt.unregister(staging)
        self._dirs.clear()
        self._files.clear()


def _check_replaceable(final: Path) -> None:
    """A file can replace `final` by a rename: not so when a folder has its name (a link to one is
    replaced as a link)."""
    if os.path.isdir(final) and not os.path.islink(final):
        raise NubisError(
            f"cannot write '{final}': a folder has that name, move or remove it, or choose another output folder"
        )


@contextlib.contextmanager
def output_set() -> Iterator[OutputSet]:
    """Stage files inside the block; they replace their final paths together only if it succeeds."""
    outputs = OutputSet()
    try:
        yield outputs
        outputs.commit()
    finally:
        outputs.discard()
