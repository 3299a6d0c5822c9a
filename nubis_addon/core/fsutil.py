"""File-system helpers: outputs are checked before expensive work and always written atomically."""

from __future__ import annotations

import contextlib
import errno
import os
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path

from . import staging
from .errors import NubisError


def not_a_file(path: Path) -> str:
    """Why `path` cannot be read as a regular file, in a few words ("" when it can): it does not exist, it
    is a folder, a device or another special file, or its name is longer than the file system allows or
    holds a NUL character (a TOML string can; no file name does)."""
    try:
        st = path.stat()
    except FileNotFoundError:
        return "does not exist"
    except ValueError:  # os.stat refuses an embedded NUL before asking the system
        return "has a NUL character (\\x00) in its name, which no file name can hold"
    except OSError as err:
        if err.errno == errno.ENAMETOOLONG:
            return "has a name longer than the file system allows"
        return f"cannot be read ({err.strerror})"
    if stat.S_ISDIR(st.st_mode):
        return "is a folder, not a file"
    if not stat.S_ISREG(st.st_mode):
        return "is a device or special file, not a regular file"
    return ""


def undecodable_name(path: str | os.PathLike) -> str:
    """The path as a message shows it when its bytes are not UTF-8 ("x\\xff.png"), else "". Python keeps
    such bytes as lone surrogates; OpenImageIO and OpenVDB take UTF-8 strings only and fail on them with a
    multi-line TypeError, and only once the work is done."""
    text = os.fspath(path)
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return os.fsencode(text).decode("utf-8", "backslashreplace")
    return ""


def check_utf8_name(what: str, path: str | os.PathLike) -> None:
    """Refuse an output path whose name is not UTF-8 text, before any work; `what` names it ("--out")."""
    name = undecodable_name(path)
    if name:
        raise NubisError(
            f"{what} '{name}' is not valid UTF-8: the image and volume writers take UTF-8 file names only, "
            "choose a name without those bytes"
        )


def shown(path: str | os.PathLike) -> Path:
    """The path a message should name: a file staged in an output set's hidden folder is named by where it
    goes (``out/clouds.vdb``, not ``out/.nubis-tmp-.../clouds.vdb``)."""
    path = Path(path)
    return path.parent.parent / path.name if path.parent.name.startswith(staging.PREFIX) else path


def sync_to_disk(staged: Path, final: Path) -> None:
    """fsync a staged file before it replaces `final`: a full disk that shows only when the data reaches it
    fails here, while the old file is still in place."""
    try:
        fd = os.open(staged, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
    except OSError as err:
        raise NubisError(f"writing '{shown(final)}' failed ({err.strerror}): check the free disk space") from None


def check_output_path(path: str | os.PathLike, suffixes: tuple[str, ...] | None = None) -> Path:
    """Fail early, before minutes of rendering, when ``path`` cannot be written."""
    out = Path(path).expanduser()
    check_utf8_name("the output", out)
    if suffixes is not None and out.suffix.lower() not in suffixes:
        raise NubisError(f"cannot write '{out}': use one of the extensions {', '.join(suffixes)}")
    parent = out.parent if str(out.parent) else Path(".")
    check_output_dir(parent, create=True)
    limit = _name_max(parent)
    if len(os.fsencode(out.name)) > limit:
        raise NubisError(
            f"cannot write '{printable_name(out.name)}': the file name is longer than the {limit} bytes "
            "the file system allows, choose a shorter name"
        )
    if out.is_dir():
        raise NubisError(f"cannot write '{out}': it is a folder, give a file name")
    if out.exists() and not os.access(out, os.W_OK):
        raise NubisError(f"cannot write '{out}': the file is read-only, choose another path or change its permissions")
    return out


def _name_max(folder: Path) -> int:
    try:
        return int(os.pathconf(folder, "PC_NAME_MAX"))
    except (OSError, ValueError, AttributeError):  # not every platform or file system says
        return 255


def printable_name(name: str, keep: int = 40) -> str:
    """A long file name shortened for a message: its start and its end."""
    return name if len(name) <= 2 * keep else f"{name[:keep]}...{name[-keep:]}"


def _check_staging_left(folder: Path) -> None:
    """A folder inside a staging folder (staging.py) that has gone: its output folder was removed or replaced
    meanwhile, and nothing is made again in its place (staging.FolderGone)."""
    for part in (folder, *folder.parents):
        if part.name.startswith(staging.PREFIX):
            if not part.is_dir():
                raise staging.FolderGone(part)
            return


def check_output_dir(folder: str | os.PathLike, create: bool = True) -> Path:
    d = Path(folder).expanduser()
    check_utf8_name("the output folder", d)
    _check_staging_left(d)
    if create:
        try:
            d.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise NubisError(f"cannot create the folder '{d}' ({err.strerror}): choose a writable location") from None
    if not d.is_dir():
        raise NubisError(f"the folder '{d}' does not exist: create it or choose another location")
    # os.access lies for root on read-only mounts, so probe with a real file.
    try:
        with tempfile.NamedTemporaryFile(dir=d, prefix=".nubis-probe-"):
            pass
    except OSError as err:
        raise NubisError(f"cannot write into '{d}' ({err.strerror}): choose a writable location") from None
    return d


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path (in a private staging folder beside ``path``); it replaces ``path`` only
    if the block succeeds. A failed or interrupted write therefore never leaves a half-written file
    where a good one was, nor a temporary file (staging.py). A writer that fails because the folder went
    meanwhile (removed, or replaced by a file) is said as that (staging.FolderGone), not as its own error."""
    with staging.output_set() as outputs:
        staged = outputs.stage(path)
        try:
            yield staged
        except (OSError, NubisError):
            gone = outputs.gone()
            if gone is None:
                raise
            raise gone from None
