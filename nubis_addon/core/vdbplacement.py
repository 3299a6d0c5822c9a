"""Where VDB clouds stand and how they share the GPU: a cloud's placement in the world (its object's
transform, the space its values are read in, how flat a transform may be), and how up to MAX_CLOUDS clouds'
bricks share one atlas within the GPU's budget (docs/vdb.md)."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from . import bricks as brickmod
from . import vdbread
from .errors import NubisError
from .sequence import human_bytes

MAX_CLOUDS = 4  # VDB clouds drawn at once (the uniform block holds their placements)


# The flattest placement drawn: its axes' scales within a million times of one another (its matrix's
# condition number within a million), so float32 inverts it to a few digits.
FLATTEST = 1e-6


@dataclass(eq=False)
class Placement:
    """A VDB cloud where its Volume object puts it: `object_to_world` (4x4) after the grid's own transform,
    its values times `multiplier` as extinction (Blender's Principled Volume at Density `multiplier`), per
    metre of the space Blender's Volume > Render > Space names (`space`, see render_space_factor)."""

    cloud: vdbread.VdbCloud
    object_to_world: np.ndarray
    multiplier: float = 1.0
    space: str = "OBJECT"  # Blender's default for a Volume

    def check(self, label: str) -> None:
        """One sentence when the placement cannot be drawn: an object scaled to zero (its matrix has no
        inverse), a transform or a Density that is not a finite number."""
        m = np.asarray(self.object_to_world, np.float64)
        if not np.all(np.isfinite(m)) or not np.isfinite(self.multiplier) or self.multiplier < 0.0:
            raise NubisError(
                f"the object of the Nubis cloud '{label}' has a transform or Density that is not a finite number: "
                "reset its transform (Alt-G, Alt-R, Alt-S) or its Density"
            )
        lengths = np.linalg.norm(m[:3, :3], axis=0)
        scale = ", ".join(f"{v:g}" for v in lengths)
        if lengths.min() == 0.0 or np.linalg.det(m[:3, :3]) == 0.0:
            raise NubisError(
                f"the object of the Nubis cloud '{label}' is scaled to zero along an axis (scale {scale}): "
                "give it a scale above zero"
            )
        # Relative, so a uniform scale of any size is drawn: only a matrix too flat to invert in float32.
        if lengths.min() < FLATTEST * lengths.max() or np.linalg.cond(m[:3, :3]) > 1.0 / FLATTEST:
            raise NubisError(
                f"the object of the Nubis cloud '{label}' is flattened: its axes' scales ({scale}) differ more "
                f"than {1.0 / FLATTEST:g} times, which the GPU's float32 cannot invert; make its scales closer"
            )

    @property
    def extinction_scale(self) -> float:
        """Extinction per metre of world per unit of the grid's value: the Density times the file's own scale,
        and Render > Space's factor for the object's scale."""
        scale = self.multiplier * self.cloud.value_scale * self.cloud.storage_scale
        return scale * render_space_factor(self.object_to_world, self.space)

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


RENDER_SPACES = ("OBJECT", "WORLD")  # Blender's Volume > Render > Space


def render_space_factor(object_to_world, space: str) -> float:
    """What Blender's renderers multiply a Volume's extinction by for its object's transform. Space = World:
    the values are per metre of the world whatever the object's scale (1). Space = Object: per unit of the
    object's own space, so a larger object is thinner per metre; Cycles takes one factor for the whole
    object, one over the length its transform gives the unit diagonal (1, 1, 1)/sqrt(3): 1/s for a uniform
    scale s, the scales' root mean square for a non-uniform one, whatever the rotation (Cycles'
    `object_volume_density`, docs/vdb.md#render-space)."""
    if space not in RENDER_SPACES:
        raise NubisError(f"unknown Volume render space {space!r}: use one of {', '.join(RENDER_SPACES)}")
    if space == "WORLD":
        return 1.0
    m = np.asarray(object_to_world, np.float64)[:3, :3]
    length = float(np.linalg.norm(m @ np.full(3, 1.0 / math.sqrt(3.0))))
    return 1.0 / length if length > 0.0 and math.isfinite(length) else 1.0


@dataclass(frozen=True)
class GpuLayout:
    """How the clouds share the GPU's two textures (render/vdbatlas.py), as the uniform block tells the
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


def shared_gpu_bytes(placements) -> int:
    """What the clouds' shared textures take on the GPU (half-float atlas, float index)."""
    if not placements:
        return 0
    layout = gpu_layout(placements)
    return brickmod.gpu_bytes_estimate(sum(p.cloud.bricks.count for p in placements), math.prod(layout.index_shape))


def why_not_together(placements, limit: int = brickmod.DEFAULT_GPU_LIMIT) -> str:
    """Why these clouds cannot share the GPU's two textures, in a few words ("" when they can)."""
    if not placements:
        return ""
    shape = gpu_layout(placements).index_shape
    if max(shape) > brickmod.MAX_ATLAS_SIDE:
        return (
            f"with the clouds before it, their leaf indices would be {shape[2]}x{shape[1]}x{shape[0]} texels, "
            f"over the {brickmod.MAX_ATLAS_SIDE} per side a 3D texture may have"
        )
    need = shared_gpu_bytes(placements)
    if need > limit:
        return f"with the clouds before it, they need {human_bytes(need)} on the GPU, over the {human_bytes(limit)}"
    return ""
