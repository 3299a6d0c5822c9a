"""The options of each job, one frozen dataclass a job: built once where the job is asked for (the command
line, an operator, a Flamenco or Dask task) and passed whole, by name, to the function that uses each
option. A new option is added here once and read where it acts, not restated along the way."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass


@dataclass(frozen=True)
class BakeOptions:
    """What a bake makes. Carried as a plain dict by farm tasks (distributed.plain)."""

    voxel_size: float | None = None  # metres; None: the scene's Bake Voxel Size
    camera_only: bool = False  # only the part of the sky the scene camera sees
    size: tuple[int, int] | None = None  # the camera's aspect for camera_only (None: the render size)
    half: bool = False  # float grids stored as 16-bit halves
    velocity: bool = False  # a `velocity` grid beside the density
    thin_cirrus: bool = False  # the cirrus slab two voxels thin (compare: docs/sources.md#comparison-set-up)
    active_share: float = 1.0  # the share of evaluated voxels the memory bound counts (bakeplan.measured_share)
    vdb: bool = True  # False leaves the VDB clouds out (compare's Cycles renders their own files)

    def but(self, **changes) -> BakeOptions:
        return dataclasses.replace(self, **changes)

    @classmethod
    def of(cls, value: BakeOptions | dict) -> BakeOptions:
        """The options a task carried as a dict (a tuple comes back a list), or the options themselves."""
        if isinstance(value, cls):
            return value
        size = value.get("size")
        return cls(**{**value, "size": tuple(size) if size else None})


@dataclass(frozen=True)
class RenderOptions:
    """`render`: the viewport's clouds from the scene camera to an image (blender/jobs/pipeline.py render_files)."""

    width: int
    height: int
    passes: int = 1  # jittered passes accumulated (more: less grain)
    motion: str | None = None  # also the motion vectors to this EXR


@dataclass(frozen=True)
class CompareOptions:
    """`compare`: the viewport against Cycles rendering the bake of the same view (blender/jobs/pipeline.py)."""

    width: int
    height: int
    samples: int | None = None  # Cycles' samples (None: enough for the noise target or the mode's default)
    mode: str = "single"  # "single" (single scattering) or "full"
    voxel_size: float | None = None  # the bake's voxels (None: a pixel's footprint at the clouds)
    noise_estimate: bool = False  # split Cycles' samples into two seeds and measure its noise
    bounces: int | None = None  # Cycles' volume bounces (None: the mode's default)
    reference: bool = True  # also the reference march (the viewport's own offline light)
    voxel_floor: float = 0.0  # the coarsest the bake may go (a draft's voxel size)
    noise_target: float | None = None  # per cent: add samples until Cycles' noise is under it
    reuse_reference: bool = False  # reuse Cycles' image from an earlier run of the same view
    viewport_passes: int | None = None  # the viewport's passes (None: 4, or with a noise target its own goal)

    def but(self, **changes) -> CompareOptions:
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class PreviewOptions:
    """`preview`: the viewport's own draw path replayed from the scene camera (blender/jobs/preview.py)."""

    width: int
    height: int
    frames: tuple[int, ...]
    redraws: int = 1  # redraws of the temporal viewport per frame
    orbit: float = 0.0  # degrees the camera turns per frame
    naive: bool = False  # also the naive full-resolution march of each frame
    quality: str | None = None  # a quality level's name (None: the scene's)


@dataclass(frozen=True)
class BenchmarkOptions:
    """`benchmark` and the sidebar's Benchmark: the naive march, the temporal redraws and EEVEE on one view."""

    width: int
    height: int
    quality: str | None = None
    eevee: bool = True  # also EEVEE rendering the bake of the same view
    eevee_samples: int = 16  # EEVEE's samples in that render (its cost on llvmpipe is per sample)
    rounds: int = 3  # alternating rounds; each measurement reports its median

    def but(self, **changes) -> BenchmarkOptions:
        return dataclasses.replace(self, **changes)
