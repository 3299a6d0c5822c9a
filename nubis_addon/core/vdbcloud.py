"""An artist's OpenVDB cloud read for the real-time renderer: checked, then packed into bricks.

Any float grid of a .vdb file (Houdini, EmberGen, Blender's Mesh to Volume, the extension's own bake) is
read as Blender's Principled Volume reads it at Density 1: its values are extinction per metre of world
space. The file is checked before anything large is made: one sentence for a file that is not a VDB, has
no float grid, an empty grid, negative or NaN values, a transform that is not a uniform scale with a
rotation and a translation, or a size whose bricks would not fit the GPU budget. The grid is then copied
out of OpenVDB one slab of leaves at a time (a slab is the leaves' whole extent in x and y, 9 voxels
deep), so the memory this takes follows the cloud, not its bounding box (core/bricks.py).
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import bricks as brickmod
from . import bundled
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

    @property
    def gpu_bytes(self) -> int:
        return self.bricks.gpu_bytes


@dataclass(frozen=True)
class GridChoice:
    name: str
    value_type: str


def float_grids(path: str | os.PathLike) -> list[GridChoice]:
    """The file's grids, checked to be a readable VDB (metadata only: nothing large is read)."""
    path = Path(path)
    if not path.is_file():
        raise NubisError(f"the VDB '{path}' is not there (moved or deleted?): point the Volume at the file again")
    vdb = bundled.openvdb()
    try:
        grids = vdb.readAllGridMetadata(str(path))
    except (OSError, RuntimeError, ValueError, TypeError) as err:
        raise NubisError(
            f"'{path}' is not an OpenVDB file this Blender reads ({str(err).strip() or type(err).__name__}): "
            "export it again as .vdb"
        ) from None
    out = []
    for g in grids:
        meta = dict(g.metadata)
        out.append(GridChoice(str(g.name), str(meta.get("value_type", g.valueTypeName))))
    return out


def choose_grid(path: str | os.PathLike, name: str = "") -> str:
    """`name`, or `density`, or the file's only float grid; a sentence naming the float grids otherwise."""
    grids = float_grids(path)
    floats = [g.name for g in grids if g.value_type in ("float", "double")]
    if not floats:
        held = ", ".join(f"'{g.name}' ({g.value_type})" for g in grids) or "no grids"
        raise NubisError(f"'{path}' has no float grid to draw as a cloud (it holds {held}): export a density grid")
    if name:
        if name not in floats:
            raise NubisError(f"'{path}' has no float grid '{name}': choose one of {', '.join(floats)}")
        return name
    if "density" in floats:
        return "density"
    if len(floats) == 1:
        return floats[0]
    raise NubisError(f"'{path}' has no 'density' grid: choose one of its float grids ({', '.join(floats)})")


def index_to_world(grid, path: str = "") -> np.ndarray:
    """The grid's linear transform as a 4x4 matrix (column vectors), checked to be a uniform scale, a
    rotation and a translation."""
    t = grid.transform
    if not t.isLinear:
        raise NubisError(f"grid '{grid.name}' has a frustum (non-linear) transform: resample it to a linear one first")
    o = np.array(t.indexToWorld((0.0, 0.0, 0.0)), np.float64)
    cols = [np.array(t.indexToWorld(tuple(float(c) for c in e)), np.float64) - o for e in np.eye(3)]
    lengths = np.array([np.linalg.norm(c) for c in cols])
    if lengths.min() <= 0.0:
        raise NubisError(
            f"grid '{grid.name}' of '{path}' has a degenerate transform (voxels of size 0): export it again"
        )
    uniform = lengths.max() - lengths.min() <= UNIFORM_TOLERANCE * lengths.max()
    unit = [c / n for c, n in zip(cols, lengths, strict=True)]
    square = all(abs(float(np.dot(unit[a], unit[b]))) <= UNIFORM_TOLERANCE for a, b in ((0, 1), (0, 2), (1, 2)))
    if not (uniform and square):
        sizes = " x ".join(f"{n:g}" for n in lengths)
        kind = "a sheared transform" if not square else "non-uniform voxels"
        raise NubisError(
            f"grid '{grid.name}' of '{path}' has {kind} ({sizes} m): resample it to cubic voxels (Blender: "
            "Volume to Mesh and Mesh to Volume, or a Houdini VDB Resample) and export again"
        )
    m = np.eye(4)
    for a in range(3):
        m[:3, a] = cols[a]
    m[:3, 3] = o
    return m


def estimate_gpu_bytes(path: str | os.PathLike, grid_name: str = "") -> tuple[int, int]:
    """(active voxels, bytes the cloud takes on the GPU at least: one brick per leaf that holds voxels),
    from reading the grid's tree, before any brick is made."""
    grid = _read_grid(path, choose_grid(path, grid_name))
    leaves = int(grid.leafCount())
    (lo, hi) = grid.evalActiveVoxelBoundingBox()
    return int(grid.activeVoxelCount()), brickmod.gpu_bytes_estimate(leaves, _index_leaves(lo, hi))


def _index_leaves(lo, hi) -> int:
    n = 1
    for a in range(3):
        n *= (int(hi[a]) - int(lo[a])) // brickmod.LEAF + 3
    return n


def _read_grid(path, name: str):
    vdb = bundled.openvdb()
    try:
        return vdb.read(str(path), name)
    except (OSError, RuntimeError, ValueError, TypeError, KeyError) as err:
        raise NubisError(f"cannot read grid '{name}' of '{path}' ({err}): export the file again") from None


def read_cloud(
    path: str | os.PathLike, grid_name: str = "", limit: int = brickmod.DEFAULT_GPU_LIMIT, dtype=np.float16
) -> VdbCloud:
    """The file's grid, checked and packed into bricks (see the module's note). Refused before packing when
    even one brick per leaf would pass `limit` bytes, and after packing (before any GPU upload) when the
    bricks do."""
    path = str(path)
    name = choose_grid(path, grid_name)
    grid = _read_grid(path, name)
    if grid.valueTypeName not in ("float", "double"):
        raise NubisError(
            f"grid '{name}' of '{path}' holds {grid.valueTypeName} values, not floats: choose a float grid"
        )
    active = int(grid.activeVoxelCount())
    if active == 0:
        raise NubisError(f"grid '{name}' of '{path}' is empty (no active voxels): there is no cloud to draw")
    m = index_to_world(grid, path)
    lo, hi = (tuple(int(c) for c in corner) for corner in grid.evalActiveVoxelBoundingBox())
    least = brickmod.gpu_bytes_estimate(int(grid.leafCount()), _index_leaves(lo, hi))
    if least > limit:
        raise NubisError(_too_large(path, name, least, limit))
    # The index covers the active box, leaf-aligned, with one empty leaf before it (core/bricks.py).
    leaf_lo = tuple((c // brickmod.LEAF - 1) * brickmod.LEAF for c in lo)
    leaves = tuple((hi[a] - leaf_lo[a]) // brickmod.LEAF + 1 for a in range(3))  # (x, y, z)
    packer = brickmod.BrickPacker((leaves[2], leaves[1], leaves[0]), leaf_lo, dtype)
    nx, ny = leaves[0] * brickmod.LEAF + 1, leaves[1] * brickmod.LEAF + 1
    slab_leaves = max(1, (64 * 1024**2) // (nx * ny * 4 * brickmod.LEAF))  # slabs of at most about 64 MB
    vmax, vmin = 0.0, 0.0
    for lz0 in range(0, leaves[2], slab_leaves):
        lz1 = min(leaves[2], lz0 + slab_leaves)
        k0 = leaf_lo[2] + lz0 * brickmod.LEAF
        block_xyz = np.zeros((nx, ny, (lz1 - lz0) * brickmod.LEAF + 1), np.float32)
        grid.copyToArray(block_xyz, ijk=(leaf_lo[0], leaf_lo[1], k0))
        block = block_xyz.transpose(2, 1, 0)
        if not np.isfinite(block).all():
            raise NubisError(
                f"grid '{name}' of '{path}' holds NaN or infinite values: fix the simulation or export it again"
            )
        vmin = min(vmin, float(block.min()))
        vmax = max(vmax, float(block.max()))
        if vmin < 0.0:
            raise NubisError(
                f"grid '{name}' of '{path}' holds negative values (down to {vmin:g}): a density cannot be "
                "negative; clamp it at 0 where it is made, or choose another grid"
            )
        packer.add(np.ascontiguousarray(block), lz0)
        held = packer.count * brickmod.BRICK**3 * packer.dtype.itemsize
        if held > limit:
            raise NubisError(_too_large(path, name, held, limit))
    packed = packer.finish()
    if packed.gpu_bytes > limit:
        raise NubisError(_too_large(path, name, packed.gpu_bytes, limit))
    voxel = float(np.linalg.norm(m[:3, 0]))
    return VdbCloud(path, name, packed, m, voxel, active, vmax, (lo, hi), _value_scale(path))


def _value_scale(path: str) -> float:
    try:
        meta = dict(bundled.openvdb().readMetadata(path))
        scale = float(meta.get("nubis_density_scale", 1.0))
    except (OSError, RuntimeError, ValueError, TypeError):
        return 1.0
    return scale if np.isfinite(scale) and scale > 0 else 1.0


def _too_large(path: str, name: str, need: int, limit: int) -> str:
    return (
        f"grid '{name}' of '{path}' needs at least {human_bytes(need)} on the GPU as bricks, over the "
        f"{human_bytes(limit)} a cloud may take: export it at a coarser voxel size (or a coarser level of its "
        "simulation), or crop it"
    )


MAX_CLOUDS = 4  # VDB clouds drawn at once (the uniform block holds their placements)


@dataclass(eq=False)
class Placement:
    """A VDB cloud where its Volume object puts it: `object_to_world` (4x4) after the grid's own transform,
    its values times `multiplier` as extinction per metre (Blender's Principled Volume at Density
    `multiplier`)."""

    cloud: VdbCloud
    object_to_world: np.ndarray
    multiplier: float = 1.0

    @property
    def extinction_scale(self) -> float:
        """Extinction per metre per unit of the grid's value: the Density times the file's own scale."""
        return self.multiplier * self.cloud.value_scale

    # Where the cloud stands is fixed once placed (a moved object is a new Placement): its geometry is
    # computed once, not on every upload of the uniform block.
    @functools.cached_property
    def index_to_world(self) -> np.ndarray:
        return np.asarray(self.object_to_world, np.float64) @ self.cloud.index_to_world

    @functools.cached_property
    def world_to_leaf_index(self) -> np.ndarray:
        """3x4 rows taking world (x, y, z, 1) to index coordinates relative to the bricks' leaf origin."""
        inv = np.linalg.inv(self.index_to_world)
        inv[:3, 3] -= np.asarray(self.cloud.bricks.leaf_origin, np.float64)
        return inv[:3]

    @functools.cached_property
    def world_box(self) -> tuple[np.ndarray, np.ndarray]:
        """The world box around the active voxels and the half voxel a sample reads beyond them."""
        lo, hi = (np.asarray(c, np.float64) for c in self.cloud.bounds)
        corners = np.array(
            [
                [x, y, z, 1.0]
                for x in (lo[0] - 1, hi[0] + 1)
                for y in (lo[1] - 1, hi[1] + 1)
                for z in (lo[2] - 1, hi[2] + 1)
            ]
        )
        world = corners @ self.index_to_world.T
        return world[:, :3].min(axis=0), world[:, :3].max(axis=0)

    @functools.cached_property
    def voxel_size(self) -> float:
        """World length of a voxel's edge (the object's scale included; its smallest axis if not uniform)."""
        m = self.index_to_world
        return float(min(np.linalg.norm(m[:3, a]) for a in range(3)))


@dataclass(frozen=True)
class GpuLayout:
    """How the clouds share the GPU's two textures (render/vdbclouds.py), as the uniform block tells the
    shader (render/uniforms.py): bricks per side of the one atlas, each cloud's first brick in it, each
    cloud's first z slice in the one index texture, and that texture's shape (z, y, x)."""

    per_side: tuple[int, int, int]
    first_brick: tuple[int, ...]
    first_slice: tuple[int, ...]
    index_shape: tuple[int, int, int]


def gpu_layout(placements) -> GpuLayout:
    counts = [p.cloud.bricks.count for p in placements]
    shapes = [p.cloud.bricks.index.shape for p in placements]
    firsts = tuple(sum(counts[:i]) for i in range(len(counts)))
    slices = tuple(sum(s[0] for s in shapes[:i]) for i in range(len(shapes)))
    index = (sum(s[0] for s in shapes), max((s[1] for s in shapes), default=0), max((s[2] for s in shapes), default=0))
    return GpuLayout(brickmod.atlas_shape(max(sum(counts), 1)), firsts, slices, index)
