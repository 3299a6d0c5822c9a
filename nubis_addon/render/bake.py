"""The VDB bake on the GPU: the viewport's own density shader, evaluated tile by tile.

Each draw evaluates one block of a tile: up to `rows` x `slices` fragments, the block's Z slices stacked
up the render target (shaders/nubis_bake_frag.glsl), so a software rasterizer gets large draws and one
read-back per block. Blocks hold absolute voxel indices, so any split of the box into tiles, on any
number of machines, computes exactly the values a whole-box bake does."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import gpu
import numpy as np

from ..core.bakeplan import BakePlan, Tile
from .engine import CloudGPU, fullscreen_batch, shader
from .offscreens import read_pixels

# Fragments per block: 128 x 8192 is 1 M voxels, 16 MiB of float RGBA read back.
MAX_TARGET_ROWS = 8192


PACK = 4  # voxels per fragment in the density-only permutation


class BlockBaker:
    """Evaluates blocks of the bake box: `block(i0, j0, nx, ny, k0, k1)` returns float RGBA shaped
    (k1 - k0, ny, nx, 4): density, glow, absorption, 1; with `velocity` the displacement of the clouds
    over one frame (P.motion.x seconds of wind time; x, y, z metres) and the density; with `packed`
    the density alone, shaped (k1 - k0, ny, nx) (nx a multiple of 4)."""

    def __init__(self, gpu_inputs: CloudGPU, plan: BakePlan, width: int, velocity: bool = False, packed=False):
        self.gpu_inputs = gpu_inputs
        self.plan = plan
        self.width = width
        self.packed = packed and not velocity
        defines = gpu_inputs.defines(NUBIS_BAKE_VELOCITY=int(velocity), NUBIS_BAKE_PACKED=int(self.packed))
        self.sh = shader("bake", defines)
        self.batch = fullscreen_batch("bake", defines)
        self.offscreen = gpu.types.GPUOffScreen(width, MAX_TARGET_ROWS, format="RGBA32F")

    def free(self) -> None:
        self.offscreen.free()

    def __enter__(self) -> BlockBaker:
        return self

    def __exit__(self, *exc) -> None:
        self.free()

    def blocks(self, i0: int, j0: int, nx: int, ny: int, k0: int, k1: int) -> Iterator[tuple[int, np.ndarray]]:
        """The slices k0..k1 of a tile in as few draws as the target allows: (first slice, block)."""
        per_draw = max(1, MAX_TARGET_ROWS // ny)
        for k in range(k0, k1, per_draw):
            yield k, self.block(i0, j0, nx, ny, k, min(k + per_draw, k1))

    def block(self, i0: int, j0: int, nx: int, ny: int, k0: int, k1: int) -> np.ndarray:
        if nx > self.width or ny * (k1 - k0) > MAX_TARGET_ROWS:
            raise ValueError(f"block {nx}x{ny}x{k1 - k0} does not fit the {self.width}x{MAX_TARGET_ROWS} target")
        rows = ny * (k1 - k0)
        plan = self.plan
        cols = -(-nx // PACK) if self.packed else nx
        with self.offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            gpu.state.blend_set("NONE")
            gpu.state.scissor_test_set(True)
            gpu.state.scissor_set(0, 0, cols, rows)
            self.gpu_inputs.bind(self.sh)
            self.sh.uniform_float("bake_origin", (*plan.origin, 0.0))
            self.sh.uniform_float("bake_voxel", (plan.voxel_size, 0.0, 0.0, 0.0))
            self.sh.uniform_float("bake_tile", (float(i0), float(j0), float(k0), float(ny)))
            self.batch.draw(self.sh)
            gpu.state.scissor_test_set(False)
            px = read_pixels(fb, cols, rows)
        if self.packed:
            return px.reshape(k1 - k0, ny, cols * PACK)[..., :nx]
        return px.reshape(k1 - k0, ny, nx, 4)


def bake_tiles(
    gpu_inputs: CloudGPU,
    plan: BakePlan,
    tiles: tuple[Tile, ...] | list[Tile],
    sink: Callable[[tuple[int, int, int], np.ndarray], None],
    progress: Callable[[float], None] | None = None,
    velocity: bool = False,
    packed: bool = False,
) -> None:
    """Evaluate every span of every tile and hand each block to `sink(ijk of its first voxel, block)`
    (see BlockBaker.block); with `velocity`, each block carries 8 channels: the density pass's four,
    then the velocity pass's displacement and density; with `packed` (and no velocity) the block is
    the density alone. Empty tiles cost nothing."""
    total = sum(t.voxels for t in tiles) or 1
    done = 0
    width = max((t.nx for t in tiles), default=1)
    with BlockBaker(gpu_inputs, plan, width, packed=packed and not velocity) as density:
        motion = BlockBaker(gpu_inputs, plan, width, velocity=True) if velocity else None
        try:
            for t in tiles:
                for k0, k1 in t.spans:
                    for k, block in density.blocks(t.i0, t.j0, t.nx, t.ny, k0, k1):
                        if motion is not None:
                            moved = motion.block(t.i0, t.j0, t.nx, t.ny, k, k + block.shape[0])
                            block = np.concatenate([block, moved], axis=-1)
                        sink((t.i0, t.j0, k), block)
                        done += block.shape[0] * t.nx * t.ny
                        if progress:
                            progress(done / total)
        finally:
            if motion is not None:
                motion.free()


def bake_density(
    gpu_inputs: CloudGPU, plan: BakePlan, progress: Callable[[float], None] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fine density, storm glow emission and rain absorption at every voxel centre of the whole box,
    each shaped (z, y, x): the dense reference the tiled bake is tested against (small boxes only)."""
    nx, ny, nz = plan.dims
    vol = np.empty((nz, ny, nx, 4), np.float32)
    whole = Tile(0, 0, nx, ny, ((0, nz),))

    def put(ijk, block):
        vol[ijk[2] : ijk[2] + block.shape[0]] = block

    bake_tiles(gpu_inputs, plan, [whole], put, progress)
    return vol[..., 0].copy(), vol[..., 1].copy(), vol[..., 2].copy()
