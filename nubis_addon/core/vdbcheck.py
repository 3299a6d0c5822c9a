"""An OpenVDB file checked before OpenVDB reads it, and OpenVDB's failures told in one sentence.

OpenVDB trusts the sizes a file states: a string's length, a count of metadata entries, of grids, of a
root node's tiles and children. A file cut short early in its header, or holding garbage, then makes it
allocate whatever those sizes say, up to gigabytes filled with spaces and an out-of-memory kill
(docs/vdb.md#damaged-files). So every size in the part OpenVDB reads first is checked here against the
file's own length before OpenVDB opens it: the header, the file's metadata, each grid's descriptor (its
name, type and where its data starts and ends), the grid's own metadata, its transform's type and its
root node's counts. A file whose grids end past its last byte is cut short, whatever the cut.

Only the standard library: no OpenVDB, no Blender. `guarded()` then turns whatever OpenVDB raises while
reading a checked file (its IoError, LookupError, KeyError, a std::bad_alloc as MemoryError, ...) into
one sentence naming the file.
"""

from __future__ import annotations

import os
import struct
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

from .errors import NubisError
from .fsutil import not_a_file, printable_name

MAGIC = 0x56444220  # " BDV": the first eight bytes of every OpenVDB file, little-endian
# OpenVDB's file format versions where the layout read here changed (openvdb/version.h).
FORMAT_OLDEST = 213  # the root node as a table of tiles and children (OpenVDB 2.0, 2013)
FORMAT_INSTANCING = 216  # a descriptor names the grid it instances
FORMAT_UUID_TEXT = 218  # the file's UUID as 36 characters
FORMAT_SELECTIVE_COMPRESSION = 220  # one compression byte in the header (until 222)
FORMAT_GRID_COMPRESSION = 222  # compression flags per grid, before its metadata
FORMAT_NEWEST = 299  # beyond this the version is not a version but garbage
UUID_CHARS = 36
MAX_TYPE_NAME = 256  # grid, metadata and map type names are short identifiers
MAX_GRID_NAME = 4096

# Bytes of one value of each tree type OpenVDB registers ("Tree_float_5_4_3" holds float).
VALUE_BYTES = {
    "float": 4, "double": 8, "int32": 4, "int64": 8, "bool": 1, "mask": 1, "half": 2,
    "vec3s": 12, "vec3d": 24, "vec3i": 12, "ptidx32": 4, "ptidx64": 8, "ptdataidx32": 4, "ptdataidx64": 8,
}  # fmt: skip
# A linear map's stored size in bytes after its type name (openvdb/math/Maps.h: Vec3d fields, Mat4d).
MAP_BYTES = {
    "UniformScaleMap": 5 * 24, "ScaleMap": 5 * 24, "UniformScaleTranslateMap": 6 * 24,
    "ScaleTranslateMap": 6 * 24, "TranslationMap": 24, "AffineMap": 128, "UnitaryMap": 128,
}  # fmt: skip
FRUSTUM_MAP = "NonlinearFrustumMap"
FRUSTUM_BYTES = 2 * 24 + 8 + 8  # its box (two Vec3d), taper and depth
# Metadata types OpenVDB registers with a fixed size (openvdb/Metadata.h); strings take any size.
METADATA_BYTES = {
    "bool": 1, "int32": 4, "int64": 8, "float": 4, "double": 8, "vec2i": 8, "vec2s": 8, "vec2d": 16,
    "vec3i": 12, "vec3s": 12, "vec3d": 24, "vec4i": 16, "vec4s": 16, "vec4d": 32, "mat4s": 64, "mat4d": 128,
}  # fmt: skip
DELAYED_LOAD = "__delayedload"
BLOSC_HEADER = 16
BLOSC_PAD = 256
# The least a root node's tile and child take on disk in a 5_4_3 tree: a tile's origin, value and active
# flag; a child's origin and its two 32^3-bit masks (child and value).
ROOT_TILE_BYTES = 12 + 1
ROOT_CHILD_BYTES = 12 + 2 * 4096
# The least one grid descriptor takes: two empty strings' lengths and three 64-bit offsets.
DESCRIPTOR_BYTES = 4 + 4 + 24

_CACHE_ENTRIES = 32


class Damaged(Exception):
    """Raised inside the parser; becomes a NubisError naming the file."""


class NotVdb(Exception):
    """The file does not begin with OpenVDB's magic number."""


@dataclass(frozen=True)
class GridEntry:
    name: str
    type_name: str  # as the file states it: "Tree_float_5_4_3", "_HalfFloat" stripped
    half: bool  # values stored as 16-bit halves
    grid_pos: int
    block_pos: int
    end_pos: int


@dataclass(frozen=True)
class FileLayout:
    path: str
    size: int
    version: int
    library: tuple[int, int]
    grids: tuple[GridEntry, ...]
    metadata_text: bool  # the file's own metadata is UTF-8 text where it is text: OpenVDB's Python reads it

    def value_type(self, grid: GridEntry) -> str:
        return tree_value_type(grid.type_name)


def tree_value_type(type_name: str) -> str:
    """ "Tree_float_5_4_3" -> "float" ("" when the name is not a standard tree type's)."""
    parts = type_name.split("_")
    return parts[1] if len(parts) >= 3 and parts[0] == "Tree" else ""


def named(path: str | os.PathLike) -> str:
    """The path as a message shows it: a long name shortened, so no message line runs to pages."""
    text = os.fspath(path)
    head, tail = os.path.split(text)
    if len(head) > 160:
        head = f"{head[:60]}...{head[-60:]}"
    return os.path.join(head, printable_name(tail)) if head else printable_name(tail)


class _Reader:
    """Reads a region of the file, refusing any read or stated size past its end before reading it."""

    def __init__(self, handle, start: int, end: int, total: int):
        self.handle, self.pos, self.end, self.total = handle, start, end, total
        handle.seek(start)

    def left(self) -> int:
        return self.end - self.pos

    def take(self, n: int, what: str) -> bytes:
        if n < 0 or n > self.left():
            if self.end >= self.total:
                raise Damaged(f"cut short: {what} needs {n} bytes at byte {self.pos}, the file ends at {self.total}")
            raise Damaged(f"{what} states {n} bytes at byte {self.pos}, past the end of its grid")
        data = self.handle.read(n)
        if len(data) != n:
            raise Damaged(f"cut short: {what} at byte {self.pos} could not be read whole")
        self.pos += n
        return data

    def u32(self, what: str) -> int:
        return struct.unpack("<I", self.take(4, what))[0]

    def i64(self, what: str) -> int:
        return struct.unpack("<q", self.take(8, what))[0]

    def string(self, what: str, limit: int | None = None) -> bytes:
        n = self.u32(f"the length of {what}")
        if limit is not None and n > limit:
            raise Damaged(f"{what} at byte {self.pos - 4} states a length of {n} bytes, not a name")
        return self.take(n, what)

    def type_name(self, what: str) -> str:
        raw = self.string(what, MAX_TYPE_NAME)
        try:
            text = raw.decode("ascii")
        except UnicodeDecodeError:
            text = ""
        if not text.isprintable() or (raw and not text):
            raise Damaged(f"{what} at byte {self.pos - len(raw)} is not text")
        return text


def _header(r: _Reader) -> tuple[int, tuple[int, int]]:
    magic = struct.unpack("<q", r.take(8, "the header"))[0]
    if magic != MAGIC:
        raise NotVdb
    version = r.u32("the file format version")
    if version < FORMAT_OLDEST or version > FORMAT_NEWEST:
        raise Damaged(f"its file format version reads {version}, not one OpenVDB has written")
    library = (r.u32("the library version"), r.u32("the library version"))
    if r.take(1, "the grid offsets flag") == b"\0":
        raise Damaged("it was written as a stream, without the grid offsets a file has")
    if FORMAT_SELECTIVE_COMPRESSION <= version < FORMAT_GRID_COMPRESSION:
        r.take(1, "the compression flag")
    r.take(UUID_CHARS if version >= FORMAT_UUID_TEXT else 16, "the file's UUID")
    return version, library


def _metadata(r: _Reader, what: str) -> bool:
    """A MetaMap: a count, then each entry's name, type name and size-prefixed value. Whether its names and
    text values are all UTF-8 (OpenVDB's Python module aborts the process turning other bytes into text)."""
    count = r.u32(f"the count of {what}")
    if count * 12 > r.left():
        raise Damaged(f"{what} states {count} entries at byte {r.pos - 4}, more than the file can hold")
    text = True
    for _ in range(count):
        text = _utf8(r.string(f"a name in {what}")) and text
        kind = r.type_name(f"a type name in {what}")
        size = r.u32(f"the size of a value in {what}")
        value = r.take(size, f"a value in {what}")
        # OpenVDB reads a known type's own size, whatever size the file states: a size that differs would
        # leave it reading the rest of the file from the wrong byte.
        if kind in METADATA_BYTES and size != METADATA_BYTES[kind]:
            raise Damaged(f"a {kind} value in {what} states {size} bytes, not {METADATA_BYTES[kind]}")
        if kind == DELAYED_LOAD and size and not _delayed_load_fits(value):
            raise Damaged(f"the delayed-load table in {what} states more than its {size} bytes hold")
        if kind == "string":
            text = _utf8(value) and text
    return text


def _utf8(raw: bytes) -> bool:
    try:
        raw.decode("utf-8")
    except UnicodeDecodeError:
        return False
    return True


def _delayed_load_fits(value: bytes) -> bool:
    """OpenVDB's delayed-load table (io/DelayedLoadMetadata): a node count, then a mask of one byte a node
    and compressed sizes of eight bytes a node, each either raw (its length 0) or Blosc-compressed (its
    length, then a Blosc header stating the bytes it expands to). OpenVDB sizes its arrays by the count and
    by the Blosc headers before reading: all of it must agree and fit the value."""
    if len(value) < 12:
        return False
    count, at = struct.unpack_from("<I", value)[0], 4
    for item, optional in ((1, False), (8, True)):
        if at + 4 > len(value):
            return False
        n = struct.unpack_from("<I", value, at)[0]
        at += 4
        if optional and n == 0xFFFFFFFF:  # no compressed sizes stored
            continue
        if n == 0:
            at += count * item
        elif n < BLOSC_HEADER or at + BLOSC_HEADER > len(value):
            return False
        else:
            # OpenVDB pads buffers under BLOSC_PAD bytes before compressing them.
            expands = struct.unpack_from("<I", value, at + 4)[0]
            if not count * item <= expands <= max(count * item, BLOSC_PAD):
                return False
            at += n
        if at > len(value):
            return False
    return True


def _descriptor(r: _Reader, version: int) -> GridEntry:
    raw = r.string("a grid's name", MAX_GRID_NAME)
    try:
        name = raw.decode("utf-8")
    except UnicodeDecodeError:
        name = "\n"
    if not name.replace("\x1e", "").isprintable():  # the separator OpenVDB puts before a duplicate's number
        raise Damaged(f"a grid's name at byte {r.pos - len(raw)} is not text")
    type_name = r.type_name(f"the type of grid '{printable_name(name)}'")
    if version >= FORMAT_INSTANCING:
        r.string(f"the instance parent of grid '{printable_name(name)}'")
    grid_pos, block_pos, end_pos = (r.i64(f"the offsets of grid '{printable_name(name)}'") for _ in range(3))
    if not r.pos <= grid_pos <= block_pos <= end_pos:
        raise Damaged(f"grid '{printable_name(name)}' states its data at bytes {grid_pos}-{end_pos}, out of order")
    if end_pos > r.total:
        raise Damaged(f"cut short: grid '{printable_name(name)}' ends at byte {end_pos}, the file at {r.total}")
    half = type_name.endswith("_HalfFloat")
    return GridEntry(name.split("\x1e")[0], type_name.removesuffix("_HalfFloat"), half, grid_pos, block_pos, end_pos)


def _grid_body(handle, grid: GridEntry, version: int, total: int) -> None:
    """The start of a grid's data: its compression, metadata, transform and root node's counts."""
    if version < FORMAT_GRID_COMPRESSION:
        return  # older layouts put the topology first; the descriptor's offsets were checked
    shown = printable_name(grid.name)
    r = _Reader(handle, grid.grid_pos, grid.end_pos, total)
    r.u32(f"the compression of grid '{shown}'")
    _metadata(r, f"the metadata of grid '{shown}'")
    kind = r.type_name(f"the transform of grid '{shown}'")
    if kind == FRUSTUM_MAP:  # its box, taper and depth, then a linear map of its own
        r.take(FRUSTUM_BYTES, f"the transform of grid '{shown}'")
        kind = r.type_name(f"the frustum's second map in grid '{shown}'")
    if kind not in MAP_BYTES:
        raise Damaged(f"grid '{shown}' has a transform of type '{printable_name(kind)}', which OpenVDB does not know")
    r.take(MAP_BYTES[kind], f"the transform of grid '{shown}'")
    value = VALUE_BYTES.get(tree_value_type(grid.type_name))
    if value is None or not grid.type_name.endswith("_5_4_3") or grid.block_pos == grid.grid_pos:
        return
    r.u32(f"the buffer count of grid '{shown}'")
    r.take(value, f"the background of grid '{shown}'")
    tiles, children = r.u32(f"the tiles of grid '{shown}'"), r.u32(f"the children of grid '{shown}'")
    if tiles * (ROOT_TILE_BYTES + value) + children * ROOT_CHILD_BYTES > r.left():
        raise Damaged(f"grid '{shown}' states {tiles} tiles and {children} nodes, more than its data can hold")


def _parse(handle, size: int) -> tuple[int, tuple[int, int], list[GridEntry], bool]:
    r = _Reader(handle, 0, size, size)
    version, library = _header(r)
    text = _metadata(r, "the file's metadata")
    count = r.u32("the grid count")
    if count * DESCRIPTOR_BYTES > r.left():
        raise Damaged(f"it states {count} grids, more than its {size} bytes can hold")
    grids = []
    for _ in range(count):
        grid = _descriptor(r, version)
        grids.append(grid)
        _grid_body(handle, grid, version, size)
        r = _Reader(handle, grid.end_pos, size, size)
    return version, library, grids, text


_cache: OrderedDict = OrderedDict()


def check(path: str | os.PathLike) -> FileLayout:
    """The file's layout, every size in it checked against its length; one sentence when it is not a
    readable VDB file (see the module's note). Remembered per (path, size, modification time)."""
    path = os.fspath(path)
    why = not_a_file(Path(path))
    if why:
        raise NubisError(_not_a_file_sentence(path, why))
    st = os.stat(path)
    key = (path, st.st_size, st.st_mtime_ns)
    if key in _cache:
        _cache.move_to_end(key)
        return _cache[key]
    if st.st_size == 0:
        raise NubisError(f"'{named(path)}' is empty (0 bytes): export or copy the file again")
    try:
        with open(path, "rb") as handle:
            version, library, grids, text = _parse(handle, st.st_size)
    except NotVdb:
        raise NubisError(
            f"'{named(path)}' is not an OpenVDB file (it does not begin as one): export it as .vdb"
        ) from None
    except Damaged as why_damaged:
        raise NubisError(f"'{named(path)}' is damaged ({why_damaged}): export or copy the file again") from None
    except OSError as err:
        raise NubisError(f"cannot read '{named(path)}' ({err.strerror}): check the file's permissions") from None
    layout = FileLayout(path, st.st_size, version, library, tuple(grids), text)
    _cache[key] = layout
    while len(_cache) > _CACHE_ENTRIES:
        _cache.popitem(last=False)
    return layout


def _not_a_file_sentence(path: str, why: str) -> str:
    if why == "does not exist":
        return f"the VDB '{named(path)}' is not there (moved or deleted?): point the Volume at the file again"
    if why.startswith("is a folder"):
        return f"'{named(path)}' is a folder, not a VDB file: choose a .vdb file inside it"
    if why.startswith("is a device"):
        return f"'{named(path)}' is a device, pipe or other special file, not a VDB file: choose a .vdb file"
    if why.startswith("has a name longer"):
        return f"the VDB path '{named(path)}' has a name longer than the file system allows: rename or move it"
    return f"the VDB '{named(path)}' {why}: choose a .vdb file that can be read"


T = TypeVar("T")


def guarded(path: str | os.PathLike, doing: str, call: Callable[[], T]) -> T:
    """`call()` (an OpenVDB read of `path`, already check()ed) with every failure told in one sentence:
    `doing` says what was being read ("grid 'density'")."""
    try:
        return call()
    except NubisError:
        raise
    except MemoryError:
        raise NubisError(
            f"reading {doing} of '{named(path)}' ran out of memory (the file states sizes it cannot hold, or "
            "it is too large for this machine): export or copy it again, or at a coarser voxel size"
        ) from None
    except Exception as err:  # noqa: BLE001 - OpenVDB raises many types (IoError, LookupError, KeyError, ...)
        detail = " ".join(str(err).split())[:200] or type(err).__name__
        raise NubisError(
            f"cannot read {doing} of '{named(path)}' ({detail}): the file is damaged or not one this Blender's "
            "OpenVDB reads; export or copy it again"
        ) from None
