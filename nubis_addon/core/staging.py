"""All-or-nothing outputs: every file of a command is written into a hidden staging folder beside its
final place and moved into place together at the end.

A failure before the commit (an error, a full disk, an interrupt) removes the staging folders and
keeps the earlier set of outputs whole. The commit itself is a handful of renames inside the same
folders (atomic each, on one file system) run with interrupts deferred, so SIGINT and SIGTERM
cannot split a set. Staging folders are private (mode 0700): after a SIGKILL nothing readable sits
under an output's name, and the next run into that folder removes folders whose process is gone
(only this machine's: a shared folder may hold another machine's run in progress). An output folder
removed, or replaced by a file, while the work runs is said as such (FolderGone), never as a missing file
or a writer's failure; nothing is made again in its place.
"""

from __future__ import annotations

import base64
import contextlib
import errno
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


class FolderGone(NubisError):
    """An output folder was removed, or replaced by a file, while the work ran: nothing was written."""

    def __init__(self, folder: str | os.PathLike, doing: str = "", again: str = ""):
        self.folder = _shown_folder(Path(folder))
        replaced = os.path.lexists(self.folder) and not self.folder.is_dir()
        self.how = "replaced by a file" if replaced else "removed"
        fix = "move the file away, make the folder again" if replaced else "make the folder again"
        when = f"while {doing}" if doing else "before Nubis could write into it"
        super().__init__(
            f"the output folder '{self.folder}' was {self.how} {when}: nothing was written; "
            f"{fix} and {again or 'try again'}"
        )

    def said(self, doing: str, again: str) -> FolderGone:
        """The same failure in the words of the work that met it ("the bake ran", "bake again")."""
        return FolderGone(self.folder, doing, again)


def _shown_folder(folder: Path) -> Path:
    """The folder a message names: a staging folder is named by the output folder that holds it."""
    return folder.parent if folder.name.startswith(PREFIX) else folder


def check_folder(folder: str | os.PathLike) -> None:
    """Raise FolderGone when the output folder (or the staging folder a file is written into) is gone."""
    if not os.path.isdir(folder):
        raise FolderGone(folder)


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
            self._dirs[folder] = _make_staging(folder)
        staged = self._dirs[folder] / final.name
        self._files[final] = staged
        return staged

    def commit(self) -> list[Path]:
        """Move every staged file into place (in the order staged) and remove the staging folders."""
        mode = _file_mode()
        with interrupt.deferred():
            interrupted = interrupt.pending()
            if not interrupted:
                self.check()
            missing = [str(f) for f, s in self._files.items() if not s.is_file()]
            if missing and not interrupted:
                raise RuntimeError(f"staged outputs were never written: {', '.join(missing)}")
            if not interrupted:
                # Every target first: a rename that fails half-way would leave a mixed set.
                for final in self._files:
                    _check_replaceable(final)
                for final, staged in self._files.items():
                    self._move(staged, final, mode)
            done = list(self._files)
            self._files.clear()
            self.discard()
        if interrupted:  # the signal came while the files were written: keep the earlier ones, and stop
            interrupt.stop()
        return done

    def _move(self, staged: Path, final: Path, mode: int) -> None:
        try:
            os.chmod(staged, mode)  # mkstemp-style 0600 files get a normal file's permissions
            os.replace(staged, final)
        except (FileNotFoundError, NotADirectoryError):
            self.check()  # its folder went between the check and the rename
            raise

    def gone(self) -> FolderGone | None:
        """The failure to say when an output folder, or a staging folder in it, is gone (else None)."""
        for folder, staging in self._dirs.items():
            for path in (folder, staging):
                if not os.path.isdir(path):
                    return FolderGone(path)
        return None

    def check(self) -> None:
        """Raise FolderGone when an output folder went since its files were staged: before the commit,
        and before more work into a set whose folder may have gone (a sequence's next frame)."""
        gone = self.gone()
        if gone is not None:
            raise gone

    def discard(self) -> None:
        for staging in self._dirs.values():
            _remove_staging(staging)
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
def private_folder(folder: str | os.PathLike) -> Iterator[Path]:
    """A private folder inside the output folder `folder`, for work that writes whole folders of files
    before they are moved into place (an OutputSet each): named as a staging folder (swept after a kill),
    registered for an interrupt, and removed at the end with whatever it still holds."""
    path = _make_staging(folder)
    try:
        yield path
    finally:
        _remove_staging(path)


_held: dict[Path, int] = {}  # staging folder -> an open descriptor of it, to find it wherever it went


def _make_staging(folder: Path | str) -> Path:
    """A private staging folder in `folder`. Made and registered under the interrupt lock: a signal between
    the two would leave it behind (the watcher removes only what is registered). Made and opened through a
    descriptor of `folder` where the system allows, so a folder moved away the instant the staging folder
    appeared (`mv out elsewhere`) still leaves the run a handle on it, and it is removed where it went."""
    with interrupt.deferred():
        try:
            path, held = _made(Path(folder))
        except (FileNotFoundError, NotADirectoryError):
            raise FolderGone(folder) from None
        interrupt.register(path)
    if held is not None:
        _held[path] = held
    return path


def _made(folder: Path) -> tuple[Path, int | None]:
    """Make the staging folder; it and a descriptor of it (None where folders are not opened)."""
    if not _BY_DESCRIPTOR:
        path = Path(tempfile.mkdtemp(prefix=_prefix(), dir=folder))
        try:
            return path, os.open(path, os.O_RDONLY | _O_DIRECTORY) if _O_DIRECTORY else None
        except OSError:
            return path, None
    parent = os.open(folder, os.O_RDONLY | _O_DIRECTORY)
    try:
        name = _new_folder(parent)
        try:
            return folder / name, os.open(name, os.O_RDONLY | _O_DIRECTORY, dir_fd=parent)
        except OSError:
            return folder / name, None
    finally:
        os.close(parent)


_O_DIRECTORY = getattr(os, "O_DIRECTORY", 0)
# Folders opened as descriptors, and made and opened relative to one (Linux, macOS; not Windows).
_BY_DESCRIPTOR = bool(_O_DIRECTORY) and {os.mkdir, os.open} <= os.supports_dir_fd


def _new_folder(parent: int) -> str:
    """Make a private folder of a new name inside the folder open as `parent`; its name."""
    for _ in range(100):
        name = _prefix() + base64.b32encode(os.urandom(5)).decode("ascii").lower()
        try:
            os.mkdir(name, 0o700, dir_fd=parent)
        except FileExistsError:
            continue
        return name
    raise FileExistsError(errno.EEXIST, "no free name for a staging folder")


def _remove_staging(path: Path) -> None:
    """Remove a staging folder with what it holds, also where it went when its output folder was moved
    away while the work ran (`mv out elsewhere`: found by its open descriptor, where the system says)."""
    fd = _held.pop(path, None)
    where = None
    if fd is not None:
        with contextlib.suppress(OSError):
            where = os.readlink(f"/proc/self/fd/{fd}")
        os.close(fd)
    interrupt.remove_path(path)
    # A removed folder reads "... (deleted)"; only a folder of the same (unique) name is this one.
    if where and where != os.fspath(path) and os.path.basename(where) == path.name and os.path.isdir(where):
        interrupt.remove_path(where)
    interrupt.unregister(path)


@contextlib.contextmanager
def output_set() -> Iterator[OutputSet]:
    """Stage files inside the block; they replace their final paths together only if it succeeds."""
    outputs = OutputSet()
    try:
        yield outputs
        outputs.commit()
    finally:
        outputs.discard()
