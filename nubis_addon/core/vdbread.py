"""An artist's OpenVDB cloud read for the real-time renderer: checked, then packed into bricks.

Any float grid of a .vdb file (Houdini, EmberGen, Blender's Mesh to Volume, the extension's own bake) is
read as Blender's Principled Volume reads it at Density 1: its values are extinction per unit of the
space its Volume's Render > Space names (render_space_factor). The file is checked before anything large
is made: its layout first (core/vdbcheck.py: a damaged or cut-short file is one sentence, never an
allocation it states), then one sentence for a file with no float grid, an empty grid, negative or NaN
values, or a transform that is not a uniform scale with a rotation and a translation. Its size is planned
from the tree's own counts (ReadPlan): a grid whose bricks and index would not fit the GPU budget is read
at a coarser level (its voxels averaged 2, 4, ... per side), refused only when even the coarsest does not
fit. The grid is copied out of OpenVDB one block of 16 leaves per side at a time (one node's voxels at a
time for a coarser level), only where its tree has nodes, so the memory and the time this takes follow
the cloud, not its bounding box (core/bricks.py, docs/vdb.md#levels-of-detail).
"""

from __future__ import annotations

import math
import os
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from . import bricks as brickmod
from . import bundled, vdbcheck
from .errors import NubisError
from .sequence import human_bytes

# Two transform axes whose lengths differ by more than this share, or which are further from square than
# this cosine, are not a uniform scale with a rotation.
UNIFORM_TOLERANCE = 1e-4


@dataclass
class VdbCloud:
    """A grid packed for the GPU: `index_to_world` (4x4, world = M @ (i, j, k, 1)) places voxel (i, j, k)'s
    centre; `bounds` the active voxels' box in the grid's index space (lo, hi: inclusive voxel indices)."""

    path: str
    grid: str
    bricks: brickmod.Bricks
    index_to_world: np.ndarray
    voxel_size: float
    active_voxels: int
    value_max: float
    bounds: tuple[tuple[int, int, int], tuple[int, int, int]]
    # Extinction per metre per unit of value: 1, or the `nubis_density_scale` a Nubis bake writes (its
    # values are densities, docs/bake.md), so the extension's own bakes read back as they were drawn.
    value_scale: float = 1.0
    # The bricks hold value / storage_scale: half floats end at 65504 (read_cloud).
    storage_scale: float = 1.0
    # 0: the file's own voxels; n: each voxel the mean of 2^n x 2^n x 2^n of them (read_cloud's levels).
    level: int = 0
    # Why a coarser level is drawn ("" at the file's own voxels).
    level_reason: str = ""

    @property
    def gpu_bytes(self) -> int:
        return self.bricks.gpu_bytes

    @property
    def level_note(self) -> str:
        """Why the cloud is drawn coarser than its file, in a sentence's end ("" at the file's own voxels)."""
        if not self.level:
            return ""
        step = 2**self.level
        return (
            f"drawn at level {self.level}, {self.voxel_size:g} m voxels each the mean of {step} x {step} x {step} of "
            f"its file's: {self.level_reason}"
        )


@dataclass(frozen=True)
class GridChoice:
    name: str
    value_type: str


def float_grids(path: str | os.PathLike) -> list[GridChoice]:
    """The file's grids, from its layout checked by core/vdbcheck.py (nothing large is read)."""
    layout = vdbcheck.check(path)
    return [GridChoice(g.name, vdbcheck.tree_value_type(g.type_name) or g.type_name) for g in layout.grids]


def choose_grid(path: str | os.PathLike, name: str = "") -> str:
    """`name`, or `density`, or the file's only float grid; a sentence naming the float grids otherwise."""
    grids = float_grids(path)
    shown = vdbcheck.named(path)
    floats = [g.name for g in grids if g.value_type in ("float", "double")]
    if not floats:
        held = ", ".join(f"'{g.name}' ({g.value_type})" for g in grids[:8]) or "no grids"
        raise NubisError(f"'{shown}' has no float grid to draw as a cloud (it holds {held}): export a density grid")
    if name:
        if name not in floats:
            raise NubisError(f"'{shown}' has no float grid '{name}': choose one of {_listed(floats)}")
        return name
    if "density" in floats:
        return "density"
    if floats == [""]:
        # Blender's Volume names its grids by name: Cycles and EEVEE draw nothing from a nameless one.
        raise NubisError(
            f"'{shown}' holds one float grid with no name, which Blender's renderers cannot draw: name it "
            "'density' where the file is made and export it again"
        )
    if len(floats) == 1:
        return floats[0]
    raise NubisError(f"'{shown}' has no 'density' grid: choose one of its float grids ({_listed(floats)})")


def _listed(names: list[str]) -> str:
    shown = [f"'{n}'" if n else "'' (no name)" for n in names[:12]]
    return ", ".join(shown) + (f" and {len(names) - 12} more" if len(names) > 12 else "")


def index_to_world(grid, path: str = "") -> np.ndarray:
    """The grid's linear transform as a 4x4 matrix (column vectors), checked to be a uniform scale, a
    rotation and a translation."""
    t = grid.transform
    if not t.isLinear:
        raise NubisError(f"grid '{grid.name}' has a frustum (non-linear) transform: resample it to a linear one first")
    o = np.array(t.indexToWorld((0.0, 0.0, 0.0)), np.float64)
    with np.errstate(over="ignore", invalid="ignore"):  # a damaged transform is said below, not warned of
        cols = [np.array(t.indexToWorld(tuple(float(c) for c in e)), np.float64) - o for e in np.eye(3)]
        lengths = np.array([np.linalg.norm(c) for c in cols])
    shown = vdbcheck.named(path)
    if not (np.all(np.isfinite(lengths)) and np.all(np.isfinite(o))) or lengths.min() <= 0.0:
        raise NubisError(
            f"grid '{grid.name}' of '{shown}' has a degenerate transform (voxels of size 0 or not finite): "
            "export it again"
        )
    uniform = lengths.max() - lengths.min() <= UNIFORM_TOLERANCE * lengths.max()
    unit = [c / n for c, n in zip(cols, lengths, strict=True)]
    square = all(abs(float(np.dot(unit[a], unit[b]))) <= UNIFORM_TOLERANCE for a, b in ((0, 1), (0, 2), (1, 2)))
    if not (uniform and square):
        sizes = " x ".join(f"{n:g}" for n in lengths)
        kind = "a sheared transform" if not square else "non-uniform voxels"
        raise NubisError(
            f"grid '{grid.name}' of '{shown}' has {kind} ({sizes} m): resample it to cubic voxels (Blender: "
            "Volume to Mesh and Mesh to Volume, or a Houdini VDB Resample) and export again"
        )
    m = np.eye(4)
    for a in range(3):
        m[:3, a] = cols[a]
    m[:3, 3] = o
    return m


# ---- reading a grid into bricks: planned from the tree's counts, then copied node by node -------------

NODE = 128  # voxels per side of a 5_4_3 tree's lower internal node: where the tree says there is data
CHUNK_LEAVES = NODE // brickmod.LEAF  # leaves per side of one block copied out of OpenVDB
CHUNK_BYTES = (NODE + 1) ** 3 * 4 * 3  # one block as copied, transposed and divided (float32)
HALF_MAX = 65504.0  # the largest half float


@dataclass(frozen=True)
class ReadPlan:
    """What reading a grid into bricks allocates, known from its tree before any voxel is copied: the
    index covers the active box, leaf-aligned, with one empty leaf before it (core/bricks.py); at least one
    brick per leaf that holds voxels and per leaf's worth of active tile (dense regions stored as tiles)."""

    lo: tuple[int, int, int]  # the active voxels' box (i, j, k), inclusive
    hi: tuple[int, int, int]
    least_bricks: int

    @property
    def leaf_lo(self) -> tuple[int, int, int]:
        return tuple((c // brickmod.LEAF - 1) * brickmod.LEAF for c in self.lo)

    @property
    def leaves(self) -> tuple[int, int, int]:
        """Leaves of the index along (x, y, z)."""
        return tuple((self.hi[a] - self.leaf_lo[a]) // brickmod.LEAF + 1 for a in range(3))

    @property
    def index_leaves(self) -> int:
        return math.prod(self.leaves)

    @property
    def gpu_bytes(self) -> int:
        """The least the bricks' atlas and the index take on the GPU."""
        if self.least_bricks > (brickmod.MAX_ATLAS_SIDE // brickmod.BRICK) ** 3:
            return self.least_bricks * brickmod.BRICK**3 * 2 + self.index_leaves * 4
        return brickmod.gpu_bytes_estimate(self.least_bricks, self.index_leaves)

    def coarser(self, level: int) -> ReadPlan:
        """The plan of the grid averaged 2^level voxels per side: its box divided, its bricks at least the
        finest ones' share (each coarse leaf holds up to 8^level fine ones; more when the cloud is sparse,
        which the packing finds)."""
        if level == 0:
            return self
        step = 2**level
        lo = tuple(c // step for c in self.lo)
        hi = tuple(c // step for c in self.hi)
        return ReadPlan(lo, hi, max(1, -(-self.least_bricks // step**3)))

    def fits(self, limit: int) -> bool:
        return max(self.leaves) <= brickmod.MAX_ATLAS_SIDE and self.gpu_bytes <= limit


def plan_read(grid) -> ReadPlan:
    lo, hi = (tuple(int(c) for c in corner) for corner in grid.evalActiveVoxelBoundingBox())
    tile_voxels = int(grid.activeVoxelCount()) - int(grid.activeLeafVoxelCount())
    least = int(grid.leafCount()) + -(-max(tile_voxels, 0) // brickmod.LEAF**3)
    return ReadPlan(lo, hi, least)


def check_plan(plan: ReadPlan, path: str, name: str, limit: int, level: int = 0) -> None:
    """One sentence when the plan, averaged to `level`, cannot be drawn: its index too large for a 3D
    texture, or its bricks and index over the GPU budget (applied before any voxel is copied)."""
    coarse = plan.coarser(level)
    step = 2**level
    averaged = f" averaged {step} x {step} x {step} voxels to one" if level else ""
    widest = max(coarse.leaves)
    if widest > brickmod.MAX_ATLAS_SIDE:
        a = coarse.leaves.index(widest)
        raise NubisError(
            f"grid '{name}' of '{vdbcheck.named(path)}' spans {plan.hi[a] - plan.lo[a] + 1} voxels along "
            f"{'xyz'[a]}, more than the {brickmod.MAX_ATLAS_SIDE * brickmod.LEAF * step} a cloud's index texture "
            f"can hold{averaged}: crop it to the cloud (stray voxels far from it widen its box) or export it at a "
            "coarser voxel size"
        )
    if coarse.gpu_bytes > limit:
        why = f" even{averaged}" if level else ""
        raise NubisError(_too_large(path, name, coarse.gpu_bytes, limit, why))


def estimate_gpu_bytes(path: str | os.PathLike, grid_name: str = "") -> tuple[int, int]:
    """(active voxels, bytes the cloud takes on the GPU at least), from the grid's tree before any brick is
    made."""
    path = str(path)
    grid = _read_grid(path, choose_grid(path, grid_name))
    return int(grid.activeVoxelCount()), plan_read(grid).gpu_bytes


def check_fits(path: str | os.PathLike, grid_name: str = "", limit: int = brickmod.DEFAULT_GPU_LIMIT) -> VdbCloud:
    """The file read and packed as the renderer will draw it, or refused in one sentence: what every command
    asks of a --vdb file before any work. Remembered (_RECENT), so the draw that follows reads it once."""
    return read_cloud(path, grid_name, limit)


def _read_grid(path: str, name: str):
    vdb = bundled.openvdb()
    return vdbcheck.guarded(path, f"grid '{name}'", lambda: vdb.read(str(path), name))


def _check_values(grid, path: str, name: str) -> tuple[float, float]:
    shown = vdbcheck.named(path)
    if grid.valueTypeName not in ("float", "double"):
        raise NubisError(
            f"grid '{name}' of '{shown}' holds {grid.valueTypeName} values, not floats: choose a float grid"
        )
    if int(grid.activeVoxelCount()) == 0:
        raise NubisError(f"grid '{name}' of '{shown}' is empty (no active voxels): there is no cloud to draw")
    vmin, vmax = (float(v) for v in grid.evalMinMax())
    if not (np.isfinite(vmin) and np.isfinite(vmax)):
        raise NubisError(
            f"grid '{name}' of '{shown}' holds NaN or infinite values: fix the simulation or export it again"
        )
    if vmin < 0.0:
        raise NubisError(
            f"grid '{name}' of '{shown}' holds negative values (down to {vmin:g}): a density cannot be "
            "negative; clamp it at 0 where it is made, or choose another grid"
        )
    return vmin, vmax


def node_occupancy(grid, plan: ReadPlan) -> tuple[np.ndarray, tuple[int, int, int]]:
    """Which lower internal nodes (NODE voxels per side) of the index's extent hold anything, (nz, ny, nx),
    and the first node's (i, j, k) in nodes: one probe per node of the tree, no voxel copied."""
    acc = grid.getConstAccessor()
    background = float(grid.background)
    first = tuple(c // NODE for c in plan.leaf_lo)
    last = tuple((plan.leaf_lo[a] + plan.leaves[a] * brickmod.LEAF) // NODE for a in range(3))
    occ = np.zeros(tuple(last[a] - first[a] + 1 for a in (2, 1, 0)), bool)
    for nz in range(occ.shape[0]):
        for ny in range(occ.shape[1]):
            for nx in range(occ.shape[2]):
                ijk = ((first[0] + nx) * NODE, (first[1] + ny) * NODE, (first[2] + nz) * NODE)
                depth = acc.getValueDepth(ijk)
                if depth >= 2:
                    occ[nz, ny, nx] = True
                elif depth >= 0:  # a tile above the nodes: dense when active or not the background
                    value, active = acc.probeValue(ijk)
                    occ[nz, ny, nx] = bool(active) or float(value) != background
    return occ, first


def _occupied(occ: np.ndarray, first: tuple[int, int, int], v0, shape) -> bool:
    """Whether the file's voxels from `v0` (i, j, k), `shape` (x, y, z) per side, meet a node holding
    anything."""
    sel = []
    for a in (2, 1, 0):
        lo = v0[a] // NODE - first[a]
        hi = (v0[a] + shape[a] - 1) // NODE - first[a] + 1
        if hi <= 0 or lo >= occ.shape[2 - a]:
            return False
        sel.append(slice(max(lo, 0), hi))
    return bool(occ[tuple(sel)].any())


def _chunks(plan: ReadPlan, occ: np.ndarray, first: tuple[int, int, int], step: int = 1):
    """The blocks to copy: (leaf0 (lz, ly, lx), leaves (nz, ny, nx), first voxel (i, j, k)) of the plan's
    index, for each block of CHUNK_LEAVES leaves per side whose file voxels (`step` per voxel of the plan)
    meet a node holding anything."""
    lx, ly, lz = plan.leaves
    for cz in range(0, lz, CHUNK_LEAVES):
        for cy in range(0, ly, CHUNK_LEAVES):
            for cx in range(0, lx, CHUNK_LEAVES):
                n = (min(CHUNK_LEAVES, lz - cz), min(CHUNK_LEAVES, ly - cy), min(CHUNK_LEAVES, lx - cx))
                v0 = tuple(plan.leaf_lo[a] + (cx, cy, cz)[a] * brickmod.LEAF for a in range(3))
                fine = tuple((n[2 - a] * brickmod.LEAF + 1) * step for a in range(3))  # the extra voxel included
                if _occupied(occ, first, tuple(c * step for c in v0), fine):
                    yield (cz, cy, cx), n, v0


# The last clouds read, by file (path, size, modification time) and reading: a command checks its --vdb
# files before any work and draws them after, from one read.
_RECENT: OrderedDict = OrderedDict()
_RECENT_ENTRIES = 2


def read_cloud(
    path: str | os.PathLike, grid_name: str = "", limit: int = brickmod.DEFAULT_GPU_LIMIT, dtype=np.float16
) -> VdbCloud:
    """The file's grid, checked and packed into bricks (see the module's note). Refused before any voxel is
    copied when its plan does not fit `limit` bytes, and while packing when the bricks pass it."""
    path = str(path)
    layout = vdbcheck.check(path)
    key = (path, layout.size, os.stat(path).st_mtime_ns, grid_name, limit, np.dtype(dtype).str)
    if key in _RECENT:
        _RECENT.move_to_end(key)
        return _RECENT[key]
    cloud = _read_cloud(path, grid_name, limit, dtype)
    _RECENT[key] = cloud
    while len(_RECENT) > _RECENT_ENTRIES:
        _RECENT.popitem(last=False)
    return cloud


MAX_LEVEL = 4  # the coarsest level drawn: 16 x 16 x 16 of the file's voxels to one
# The most voxels a coarser level is averaged from (every voxel of the nodes the tree holds, copied a node at a
# time): the copy's time follows it, and a small file can state billions of voxels of active tiles.
MAX_LEVEL_READ = 2**30


@dataclass(frozen=True)
class _Source:
    """A grid being read: what every block of it needs."""

    path: str
    name: str
    grid: object
    limit: int
    dtype: object
    storage: float  # values are stored divided by this (half floats end at 65504)
    occupancy: tuple  # node_occupancy() of the finest plan


class _OverBudget(Exception):
    def __init__(self, need: int):
        super().__init__(need)
        self.need = need


def _read_cloud(path: str, grid_name: str, limit: int, dtype) -> VdbCloud:
    name = choose_grid(path, grid_name)
    grid = _read_grid(path, name)
    _vmin, vmax = _check_values(grid, path, name)
    m = index_to_world(grid, path)
    finest = plan_read(grid)
    fitting = [n for n in range(MAX_LEVEL + 1) if finest.coarser(n).fits(limit)]
    if not fitting:
        check_plan(finest, path, name, limit, MAX_LEVEL)  # says why even the coarsest level does not fit
    # Half floats end at 65504: larger values are stored divided, the factor kept (stays exact in ratio).
    storage = max(1.0, vmax / (HALF_MAX * 0.5)) if np.dtype(dtype) == np.float16 else 1.0
    src = _Source(path, name, grid, limit, dtype, storage, node_occupancy(grid, finest))
    copied = int(src.occupancy[0].sum()) * NODE**3
    if fitting[0] > 0 and copied > MAX_LEVEL_READ:
        why = (
            f", and a coarser level would be averaged from the {copied / 1e9:.1f} billion voxels of its tree's nodes, "
            f"more than the {MAX_LEVEL_READ / 1e9:.1f} billion one is built from"
        )
        raise NubisError(_too_large(path, name, finest.gpu_bytes, limit, why))
    finest_need = finest.gpu_bytes  # what the file's own voxels take at least, for the note
    for level in range(fitting[0], MAX_LEVEL + 1):
        plan = finest.coarser(level)
        try:
            packed = _pack(src, plan, level)
        except _OverBudget as over:
            if level == MAX_LEVEL:
                raise NubisError(_too_large(path, name, over.need, limit)) from None
            finest_need = over.need if level == 0 else finest_need
            continue  # the cloud is sparser than its counts said: one level coarser
        step = 2**level
        # A coarse voxel's centre is the centre of the 2^level file voxels it averages.
        coarse = np.diag([step, step, step, 1.0])
        coarse[:3, 3] = (step - 1) / 2.0
        at = m @ coarse
        voxel = float(np.linalg.norm(at[:3, 0]))
        active = int(grid.activeVoxelCount())
        cloud = VdbCloud(path, name, packed, at, voxel, active, vmax, (plan.lo, plan.hi), _value_scale(path), storage)
        cloud.level, cloud.level_reason = level, _level_reason(finest, finest_need, limit) if level else ""
        return cloud
    raise AssertionError("unreachable: the last level returns or raises")


def _level_reason(finest: ReadPlan, need: int, limit: int) -> str:
    if max(finest.leaves) > brickmod.MAX_ATLAS_SIDE:
        a = finest.leaves.index(max(finest.leaves))
        return (
            f"it spans {finest.hi[a] - finest.lo[a] + 1} voxels along {'xyz'[a]}, more than the "
            f"{brickmod.MAX_ATLAS_SIDE * brickmod.LEAF} a cloud's index texture holds; crop it to draw it finer"
        )
    return (
        f"its own voxels need at least {human_bytes(need)} on the GPU, over the {human_bytes(limit)} "
        "budget for VDB clouds; raise the budget in the preferences to draw it finer"
    )


def _pack(src: _Source, plan: ReadPlan, level: int) -> brickmod.Bricks:
    """The grid at `level` packed into bricks, block by block; _OverBudget when the bricks pass the limit."""
    lx, ly, lz = plan.leaves
    # A few more than the plan's least: a leaf whose neighbour's first voxels hold cloud is kept too.
    packer = brickmod.BrickPacker((lz, ly, lx), plan.leaf_lo, src.dtype, plan.least_bricks * 23 // 20)
    occ, first = src.occupancy
    for leaf0, n, v0 in _chunks(plan, occ, first, 2**level):
        shape = tuple(n[a] * brickmod.LEAF + 1 for a in range(3))  # (z, y, x), the extra voxel included
        block = _block(src, v0, shape) if level == 0 else _averaged_block(src, v0, shape, 2**level)
        packer.add(_checked_block(block, src.path, src.name, src.storage), leaf0)
        if packer.held_bytes > src.limit:
            raise _OverBudget(packer.held_bytes)
    packed = packer.finish()
    if packed.gpu_bytes > src.limit:
        raise _OverBudget(packed.gpu_bytes)
    return packed


def _copied(src: _Source, v0, shape_xyz) -> np.ndarray:
    """The file's voxels from v0 (i, j, k), shaped (x, y, z), as OpenVDB copies them."""
    out = np.zeros(shape_xyz, np.float32)
    vdbcheck.guarded(src.path, f"grid '{src.name}'", lambda: src.grid.copyToArray(out, ijk=tuple(v0)))
    return out


def _block(src: _Source, v0, shape) -> np.ndarray:
    return _copied(src, v0, shape[::-1]).transpose(2, 1, 0)


def _averaged_block(src: _Source, v0, shape, step: int) -> np.ndarray:
    """A block (z, y, x) of the grid averaged `step` voxels per side from coarse voxel v0 (i, j, k): the
    file's voxels copied a node's worth at a time, where its tree has nodes. The mean keeps each coarse
    voxel's optical depth on average (a box filter); inactive values below zero count as empty."""
    out = np.zeros(shape, np.float32)
    occ, first = src.occupancy
    sub = max(1, NODE // step)  # coarse voxels per side of one copy
    for cz in range(0, shape[0], sub):
        for cy in range(0, shape[1], sub):
            for cx in range(0, shape[2], sub):
                size = (min(sub, shape[2] - cx), min(sub, shape[1] - cy), min(sub, shape[0] - cz))  # x, y, z
                f0 = tuple((v0[a] + (cx, cy, cz)[a]) * step for a in range(3))
                fine_shape = tuple(c * step for c in size)
                if not _occupied(occ, first, f0, fine_shape):
                    continue
                fine = _copied(src, f0, fine_shape)
                np.maximum(fine, 0.0, out=fine)
                pooled = fine.reshape(size[0], step, size[1], step, size[2], step).mean(axis=(1, 3, 5))
                out[cz : cz + size[2], cy : cy + size[1], cx : cx + size[0]] = pooled.transpose(2, 1, 0)
    return out


def _checked_block(block: np.ndarray, path: str, name: str, storage: float) -> np.ndarray:
    """A copied block (z, y, x), its inactive values checked too (evalMinMax sees active ones only)."""
    if not np.isfinite(block).all():
        raise NubisError(
            f"grid '{name}' of '{vdbcheck.named(path)}' holds NaN or infinite values: fix the simulation or export "
            "it again"
        )
    if block.min() < 0.0:
        np.maximum(block, 0.0, out=block)  # inactive voxels below zero: never drawn as cloud
    if storage != 1.0:
        block = block / np.float32(storage)
    np.minimum(block, HALF_MAX, out=block)  # an inactive value beyond the active ones' maximum
    return np.ascontiguousarray(block)


def _value_scale(path: str) -> float:
    if not vdbcheck.check(path).metadata_text:
        return 1.0  # not a Nubis bake (it writes UTF-8), and OpenVDB's Python would abort on its text
    try:
        meta = dict(vdbcheck.guarded(path, "the metadata", lambda: bundled.openvdb().readMetadata(path)))
        scale = float(meta.get("nubis_density_scale", 1.0))
    except (NubisError, ValueError, TypeError):
        return 1.0
    return scale if np.isfinite(scale) and scale > 0 else 1.0


def _too_large(path: str, name: str, need: int, limit: int, why: str = "") -> str:
    return (
        f"grid '{name}' of '{vdbcheck.named(path)}' needs at least {human_bytes(need)} on the GPU as bricks, over the "
        f"{human_bytes(limit)} a cloud may take{why}: export it at a coarser voxel size (or a coarser level of its "
        "simulation), or crop it"
    )
