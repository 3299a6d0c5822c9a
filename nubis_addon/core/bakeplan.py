"""Where and how finely to bake, and whether the machine can afford it (estimated before any work)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .errors import NubisError
from .state import CloudState

# Float32 density, glow and absorption volumes, the transposed copy handed to OpenVDB and the sparse
# tree itself.
BYTES_PER_VOXEL = 20
DEFAULT_MEMORY_LIMIT = 4 * 1024**3
MAX_SLICE = 8192  # texels per side of one GPU slice


@dataclass(frozen=True)
class BakePlan:
    origin: tuple[float, float, float]  # world centre of voxel (0, 0, 0)
    voxel_size: float
    dims: tuple[int, int, int]  # voxels along x, y, z
    cirrus_slab: float | None = None  # thickness of the baked cirrus slab, when the sky has cirrus

    @property
    def voxels(self) -> int:
        return self.dims[0] * self.dims[1] * self.dims[2]

    @property
    def bytes_estimate(self) -> int:
        return self.voxels * BYTES_PER_VOXEL


def view_footprint(state: CloudState, inv_view_proj: np.ndarray, samples: int = 33) -> tuple[float, ...]:
    """XY bounds of the cloud layer a camera sees: rays through a grid over the image, cut by the
    shell's spheres (and the cirrus sphere) within the draw radius. Baking only this box lets a
    shot's bake use voxels several times finer than a bake of the whole sky."""
    p = state.params
    planet = p["layer_planet_radius"]
    lo, hi = state.shell()
    altitudes = [lo, hi] + ([p["cirrus_altitude"]] if state.has_cirrus() else [])
    t = np.linspace(-1.0, 1.0, samples)
    nx, ny = np.meshgrid(t, t)
    ndc = np.stack([nx.ravel(), ny.ravel()], axis=1)
    m = np.asarray(inv_view_proj, dtype=np.float64)

    def unproject(z: float) -> np.ndarray:
        h = np.c_[ndc, np.full(len(ndc), z), np.ones(len(ndc))] @ m.T
        return h[:, :3] / h[:, 3:4]

    origin = unproject(-1.0)
    direction = unproject(1.0) - origin
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    centre = np.array([0.0, 0.0, -planet])
    points = [origin[:, :2]]
    oc = origin - centre
    b = np.sum(oc * direction, axis=1)
    for alt in altitudes:
        c = np.sum(oc * oc, axis=1) - (planet + alt) ** 2
        disc = b * b - c
        ok = disc >= 0
        for sign in (-1.0, 1.0):
            dist = -b + sign * np.sqrt(np.where(ok, disc, 0.0))
            hit = ok & (dist > 0)
            points.append((origin + direction * dist[:, None])[hit][:, :2])
    xy = np.concatenate(points)
    # Beyond the draw radius there is nothing to bake: pull far hits back onto its circle.
    draw = np.asarray(state.draw_center)
    offset = xy - draw
    dist = np.linalg.norm(offset, axis=1, keepdims=True)
    radius = p["layer_draw_radius"]
    xy = np.where(dist > radius, draw + offset / np.maximum(dist, 1e-9) * radius, xy)
    return float(xy[:, 0].min()), float(xy[:, 0].max()), float(xy[:, 1].min()), float(xy[:, 1].max())


def plan_bake(
    state: CloudState,
    voxel_size: float,
    memory_limit: int = DEFAULT_MEMORY_LIMIT,
    region: tuple[float, float, float, float] | None = None,
) -> BakePlan:
    """The box holding every cloud the viewport can draw: the field, clipped to the draw radius (and to
    `region`, x0 x1 y0 y1, when given), and the shell's altitudes, lowered by the planet's curvature at
    the box's far corners."""
    if not (math.isfinite(voxel_size) and voxel_size > 0):
        raise NubisError(f"the voxel size must be a positive number of metres, not {voxel_size!r}")
    p = state.params
    half = p["field_size"] / 2
    radius = p["layer_draw_radius"]
    cx, cy = state.draw_center
    x0 = max(p["field_origin_x"] - half, cx - radius)
    x1 = min(p["field_origin_x"] + half, cx + radius)
    y0 = max(p["field_origin_y"] - half, cy - radius)
    y1 = min(p["field_origin_y"] + half, cy + radius)
    if region is not None:
        margin = 2.0 * voxel_size
        x0, x1 = max(x0, region[0] - margin), min(x1, region[1] + margin)
        y0, y1 = max(y0, region[2] - margin), min(y1, region[3] + margin)
    if x1 <= x0 or y1 <= y0:
        if region is not None:
            raise NubisError("the camera sees none of the cloud field: aim it at the clouds or bake the whole sky")
        raise NubisError("the data field lies outside the draw radius around the camera: move the camera or the field")
    lo, hi = state.shell()
    slab = None
    if state.has_cirrus():
        # The 2D cirrus layer bakes as a slab at least two voxels thick, so voxel centres cannot miss it.
        slab = max(p["cirrus_thickness"], 2.0 * voxel_size)
        hi = max(hi, p["cirrus_altitude"] + slab / 2)
    planet = p["layer_planet_radius"]
    far = max(math.hypot(x, y) for x in (x0, x1) for y in (y0, y1))
    sag = planet + lo - math.sqrt(max((planet + lo) ** 2 - far**2, 0.0))
    z0, z1 = lo - sag, hi
    v = voxel_size
    dims = tuple(max(1, math.ceil((b - a) / v)) for a, b in ((x0, x1), (y0, y1), (z0, z1)))
    plan = BakePlan((x0 + v / 2, y0 + v / 2, z0 + v / 2), v, dims, slab)
    if plan.bytes_estimate > memory_limit or max(dims[:2]) > MAX_SLICE:
        suggested = v * max((plan.bytes_estimate / memory_limit) ** (1 / 3), max(dims[:2]) / MAX_SLICE) * 1.05
        raise NubisError(
            f"a bake at {v:g} m voxels needs {dims[0]}x{dims[1]}x{dims[2]} voxels "
            f"(about {plan.bytes_estimate / 1024**3:.1f} GB): use a voxel size of at least {math.ceil(suggested)} m"
        )
    return plan


# A comparison bakes only the camera's view, so it can afford finer voxels than a whole-sky bake:
# trilinear interpolation of coarse voxels thickens thin cloud edges (measured: 40 m voxels showed
# Cycles thin cloud 15 % more opaque than the viewport, 20 m halved the alpha error).
COMPARE_VOXEL_BUDGET = 64_000_000
COMPARE_FINEST_VOXEL = 20.0


def comparison_voxel_size(
    state: CloudState, start: float, region: tuple[float, float, float, float], budget: int = COMPARE_VOXEL_BUDGET
) -> float:
    """The finest voxel size, halving from `start` down to 20 m, whose camera-only bake stays within
    `budget` voxels (about 1.3 GB while baking)."""
    size = start
    while size / 2 >= COMPARE_FINEST_VOXEL:
        try:
            finer = plan_bake(state, size / 2, region=region)
        except NubisError:
            break
        if finer.voxels > budget:
            break
        size /= 2
    return size
