"""OpenVDB output: sparse fog-volume FloatGrids with the world transform of the bake box. Atomic."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import bundled, vdbcheck
from .errors import NubisError
from .fsutil import atomic_path, shown, sync_to_disk

# Values below this are dropped from the sparse tree: at sigma 0.04/m and 100 m voxels this is an optical
# depth of 4e-5 per voxel, far below what a render can show.
DEFAULT_TOLERANCE = 1e-5


@dataclass(frozen=True)
class GridInfo:
    name: str
    active_voxels: int
    index_bbox: tuple[tuple[int, int, int], tuple[int, int, int]]
    voxel_size: float
    origin: tuple[float, float, float]  # world position of voxel (0, 0, 0)'s centre
    min_max: tuple[float, float]


def make_transform(voxel_size: float, origin: tuple[float, float, float]):
    vdb = bundled.openvdb()
    v = float(voxel_size)
    # OpenVDB multiplies row vectors, so the translation sits in the last row.
    return vdb.createLinearTransform([[v, 0, 0, 0], [0, v, 0, 0], [0, 0, v, 0], [*map(float, origin), 1.0]])


def write_vdb(
    path: str | os.PathLike,
    grids: dict[str, np.ndarray],
    voxel_size: float,
    origin: tuple[float, float, float],
    metadata: dict[str, str | float | int] | None = None,
    tolerance: float = DEFAULT_TOLERANCE,
) -> Path:
    """Write volumes indexed [z, y, x] as fog-volume grids; voxel (i, j, k)'s centre is origin + (i, j, k) * size."""
    vdb = bundled.openvdb()
    path = Path(path)
    out = []
    for name, vol in grids.items():
        if vol.ndim != 3:
            raise ValueError(f"grid '{name}' must be 3D, got shape {vol.shape}")
        if not np.all(np.isfinite(vol)):
            raise NubisError(f"refusing to write '{path}': grid '{name}' holds NaN or infinite values")
        grid = vdb.FloatGrid()
        grid.copyFromArray(np.ascontiguousarray(vol.transpose(2, 1, 0), dtype=np.float32), tolerance=tolerance)
        grid.transform = make_transform(voxel_size, origin)
        grid.name = name
        grid.gridClass = vdb.GridClass.FOG_VOLUME
        out.append(grid)
    return _write(path, out, metadata)


class SparseGrids:
    """Grids filled block by block as a tiled bake produces them (only active voxels are kept), then
    written in one atomic file. Float blocks are shaped (z, y, x), vector blocks (z, y, x, 3); `ijk` is
    the index of a block's first voxel (x, y, z). Each voxel is written once: blocks never overlap."""

    def __init__(self, voxel_size: float, origin: tuple[float, float, float], tolerance: float = DEFAULT_TOLERANCE):
        self.voxel_size = float(voxel_size)
        self.origin = tuple(float(c) for c in origin)
        self.tolerance = float(tolerance)
        self.grids: dict[str, object] = {}
        self.classes: dict[str, str] = {}

    def grid(self, name: str, vector: bool = False):
        if name not in self.grids:
            vdb = bundled.openvdb()
            grid = vdb.Vec3SGrid() if vector else vdb.FloatGrid()
            grid.transform = make_transform(self.voxel_size, self.origin)
            grid.name = name
            # Velocity is a plain vector field (class unknown, as Houdini and Blender write it).
            grid.gridClass = vdb.GridClass.UNKNOWN if vector else vdb.GridClass.FOG_VOLUME
            if vector:
                grid.vectorType = vdb.VectorType.CONTRAVARIANT_RELATIVE
            self.grids[name] = grid
        return self.grids[name]

    def add(self, name: str, block: np.ndarray, ijk: tuple[int, int, int]) -> None:
        vector = block.ndim == 4
        grid = self.grid(name, vector)  # created even when empty: a bake always has its density grid
        if not np.all(np.isfinite(block)):
            raise NubisError(f"refusing to write grid '{name}': the bake produced NaN or infinite values")
        if not np.any(np.abs(block) > self.tolerance):
            return
        arr = np.ascontiguousarray(block.transpose(2, 1, 0, 3) if vector else block.transpose(2, 1, 0), np.float32)
        self._copy(grid, arr, ijk, vector)

    def _copy(self, grid, arr_xyz: np.ndarray, ijk, vector: bool) -> None:
        tol = (self.tolerance,) * 3 if vector else self.tolerance
        grid.copyFromArray(arr_xyz, ijk=tuple(int(c) for c in ijk), tolerance=tol)

    def add_region(self, other, lo: tuple[int, int, int], shape: tuple[int, int, int]) -> None:
        """Copy the voxels of grid `other` (another process's part of the same bake) inside the box of
        `shape` voxels from index `lo` into the grid of the same name; the box must hold nothing yet."""
        vector = other.valueTypeName.startswith("vec3")
        grid = self.grid(other.name, vector)
        arr = np.zeros((*shape, 3) if vector else shape, np.float32)
        other.copyToArray(arr, ijk=tuple(int(c) for c in lo))
        if np.any(np.abs(arr) > self.tolerance):
            self._copy(grid, arr, lo, vector)

    def active_voxels(self, name: str) -> int:
        return int(self.grids[name].activeVoxelCount()) if name in self.grids else 0

    def memory_bytes(self) -> int:
        return sum(int(g.memUsage()) for g in self.grids.values())

    def write(
        self,
        path: str | os.PathLike,
        metadata: dict[str, str | float | int | bool] | None = None,
        half: bool = False,
        keep: tuple[str, ...] = ("density",),
    ) -> Path:
        """Write the grids that hold active voxels (and those named in `keep` even when empty) to `path`
        atomically; `half` stores float values as 16-bit halves (OpenVDB's saveFloatAsHalf)."""
        grids = [g for n, g in self.grids.items() if n in keep or g.activeVoxelCount() > 0]
        for grid in grids:
            grid.saveFloatAsHalf = bool(half)
        return _write(path, grids, metadata)


def _write(path: str | os.PathLike, grids: list, metadata: dict | None) -> Path:
    vdb = bundled.openvdb()
    path = Path(path)
    with atomic_path(path) as tmp:
        try:
            vdb.write(str(tmp), grids=grids, metadata=dict(metadata or {}))
        except (OSError, RuntimeError, ValueError) as err:
            raise NubisError(
                f"writing '{shown(path)}' failed ({err}): check the free disk space and permissions"
            ) from None
        _check_written(tmp, path, grids)
    return path


def _check_written(tmp: Path, path: Path, grids: list) -> None:
    """The staged file on disk (fsync), its grids' headers readable and its last grid read back whole with
    the voxels written: OpenVDB does not report a full disk, and a file cut short ends early, so the last
    grid is the one that would be missing. (One grid read back, not all: the memory stays bounded.)"""
    vdb = bundled.openvdb()
    failed = NubisError(f"writing '{shown(path)}' failed (the file came out incomplete): check the free disk space")
    sync_to_disk(tmp, path)
    if not grids:
        return
    try:
        names = [g.name for g in vdb.readAllGridMetadata(str(tmp))]
        last = vdb.read(str(tmp), grids[-1].name)
    except (OSError, RuntimeError, ValueError, KeyError):
        raise failed from None
    # (readAllGridMetadata lists the grids in its own order, not the file's.)
    if sorted(names) != sorted(g.name for g in grids) or last.activeVoxelCount() != grids[-1].activeVoxelCount():
        raise failed


def read_grid_info(path: str | os.PathLike) -> dict[str, GridInfo]:
    vdb = bundled.openvdb()
    if not vdbcheck.check(path).metadata_text:
        raise NubisError(f"the metadata of '{vdbcheck.named(path)}' holds text that is not UTF-8: bake it again")
    grids, _meta = vdbcheck.guarded(path, "the grids", lambda: vdb.readAll(str(path)))
    info = {}
    for g in grids:
        origin = tuple(float(c) for c in g.transform.indexToWorld((0, 0, 0)))
        size = float(np.subtract(g.transform.indexToWorld((1, 0, 0)), origin)[0])
        info[g.name] = GridInfo(
            g.name, int(g.activeVoxelCount()), g.evalActiveVoxelBoundingBox(), size, origin, tuple(g.evalMinMax())
        )
    return info


def read_grid_array(path: str | os.PathLike, name: str) -> tuple[np.ndarray, tuple[int, int, int]]:
    """Dense copy of a grid's active bounding box, indexed [z, y, x], with the index of its first voxel."""
    vdb = bundled.openvdb()
    vdbcheck.check(path)
    grid = vdbcheck.guarded(path, f"grid '{name}'", lambda: vdb.read(str(path), name))
    lo, hi = grid.evalActiveVoxelBoundingBox()
    shape = tuple(int(h - lo_ + 1) for lo_, h in zip(lo, hi, strict=True))
    arr = np.zeros(shape, np.float32)
    grid.copyToArray(arr, ijk=lo)
    return arr.transpose(2, 1, 0), tuple(lo)
