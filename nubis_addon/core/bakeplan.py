"""Where and how finely to bake, and whether the machine can afford it (estimated before any work)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import cloudlayers
from .camera import pixel_footprint
from .errors import NubisError
from .state import CloudState, wind_vector

# The bake is sparse and tiled (docs/bake.md): the box is cut into columns of TILE x TILE voxels, each
# evaluated only over the slices where the data field says cloud can be, and the active voxels go
# straight into OpenVDB trees. Memory follows the clouds: about 4.5 bytes per active float voxel in a
# tree of full 8^3 leaves (values plus masks), 13.5 for a Vec3 velocity, plus one tile's read-back.
BYTES_PER_ACTIVE_VOXEL = 4.5
BYTES_PER_VELOCITY_VOXEL = 13.5
DEFAULT_MEMORY_LIMIT = 4 * 1024**3
TILE = 128  # voxels per side of one tile
MAX_TILES = 200_000  # beyond this the box alone is absurd: refuse before planning every tile
# What the process holds besides the trees: Blender, the noise textures, one block's read-back.
BASE_BYTES = 600 * 1024**2
# The file on disk, per voxel the GPU evaluates (most of them hold no cloud, and OpenVDB stores only the
# active ones, compressed). A sequence's disk estimate must be an upper bound, so these sit a margin above
# the densest bundled preset's bake (docs/measurements.md#bake-planning). A velocity grid holds three floats
# where the density holds one. Each file adds its header, metadata and tree (FILE_OVERHEAD_BYTES).
FILE_BYTES_PER_EVALUATED_VOXEL = {False: 1.6, True: 1.25}  # by `half`
FILE_BYTES_VELOCITY_FACTOR = 4
FILE_OVERHEAD_BYTES = 16 * 1024


@dataclass(frozen=True)
class Tile:
    """A column of the bake box: voxels i0.. i0 + nx - 1 and j0.. j0 + ny - 1, and the slice ranges
    [k0, k1) where the data field allows cloud (empty: nothing to evaluate)."""

    i0: int
    j0: int
    nx: int
    ny: int
    spans: tuple[tuple[int, int], ...] = ()

    @property
    def voxels(self) -> int:
        return self.nx * self.ny * sum(k1 - k0 for k0, k1 in self.spans)


@dataclass(frozen=True)
class BakePlan:
    origin: tuple[float, float, float]  # world centre of voxel (0, 0, 0)
    voxel_size: float
    dims: tuple[int, int, int]  # voxels along x, y, z
    cirrus_slab: float | None = None  # thickness of the baked cirrus slab, when the sky has cirrus
    tiles: tuple[Tile, ...] = ()
    velocity: bool = False  # a velocity grid is baked too
    extra_grids: int = 0  # float grids beside density the field can produce (absorption, glow)
    # The share of the evaluated voxels the estimate counts as active: 1, the bound, unless a probe bake
    # measured how much of them the clouds fill (measured_share).
    active_share: float = 1.0

    @property
    def voxels(self) -> int:
        return self.dims[0] * self.dims[1] * self.dims[2]

    @property
    def evaluated_voxels(self) -> int:
        """Voxels the GPU evaluates: those of the tiles' spans (an upper bound on the active ones)."""
        return sum(t.voxels for t in self.tiles)

    @property
    def bytes_per_active_voxel(self) -> float:
        return BYTES_PER_ACTIVE_VOXEL * (1 + self.extra_grids) + (BYTES_PER_VELOCITY_VOXEL if self.velocity else 0)

    @property
    def bytes_estimate(self) -> int:
        return int(BASE_BYTES + self.evaluated_voxels * self.active_share * self.bytes_per_active_voxel)

    def file_bytes_estimate(self, half: bool = False) -> int:
        """About the most bytes the baked file takes on disk (bytes_estimate is memory, not the file)."""
        per = FILE_BYTES_PER_EVALUATED_VOXEL[bool(half)] * (FILE_BYTES_VELOCITY_FACTOR if self.velocity else 1)
        return int(FILE_OVERHEAD_BYTES + self.evaluated_voxels * per)


def _camera_rays(inv_view_proj: np.ndarray, samples: int) -> tuple[np.ndarray, np.ndarray]:
    """Origins and unit directions of a samples x samples grid of the camera's rays over the image."""
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
    return origin, direction


def _sphere_hits(origin: np.ndarray, direction: np.ndarray, planet: float, altitudes):
    """For each altitude's sphere about the planet's centre and each of its two crossings: (distance
    along every ray, which rays cross it ahead of their origin)."""
    oc = origin - np.array([0.0, 0.0, -planet])
    b = np.sum(oc * direction, axis=1)
    for alt in altitudes:
        c = np.sum(oc * oc, axis=1) - (planet + alt) ** 2
        disc = b * b - c
        ok = disc >= 0
        for sign in (-1.0, 1.0):
            dist = -b + sign * np.sqrt(np.where(ok, disc, 0.0))
            yield dist, ok & (dist > 0)


def view_footprint(state: CloudState, inv_view_proj: np.ndarray, samples: int = 33) -> tuple[float, ...]:
    """XY bounds of the cloud layer a camera sees: rays through a grid over the image, cut by the
    shell's spheres (and the cirrus sphere) within the draw radius. Baking only this box lets a
    shot's bake use voxels several times finer than a bake of the whole sky."""
    p = state.params
    planet = p["layer_planet_radius"]
    lo, hi = state.shell()
    altitudes = [lo, hi] + ([p["cirrus_altitude"]] if state.has_cirrus() else [])
    origin, direction = _camera_rays(inv_view_proj, samples)
    points = [origin[:, :2]]
    for dist, hit in _sphere_hits(origin, direction, planet, altitudes):
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
    memory_limit: int | None = None,
    region: tuple[float, float, float, float] | None = None,
    velocity: bool = False,
    tile: int = TILE,
    thin_cirrus: bool = False,
    active_share: float = 1.0,
) -> BakePlan:
    """The box holding every cloud the viewport can draw: the field, clipped to the draw radius (and to
    `region`, x0 x1 y0 y1, when given), and the shell's altitudes, lowered by the planet's curvature at
    the box's far corners; cut into tiles (plan_tiles). Refuses, naming a voxel size that fits, when
    the estimated memory exceeds `memory_limit` (DEFAULT_MEMORY_LIMIT when None). `active_share` is the
    share of the evaluated voxels the estimate counts as active (BakePlan.active_share): 1 but after a
    probe (measured_share)."""
    if not (math.isfinite(voxel_size) and voxel_size > 0):
        raise NubisError(f"the voxel size must be a positive number of metres, not {voxel_size!r}")
    if not (0.0 < active_share <= 1.0):
        raise NubisError(f"the active share of a bake must lie in (0, 1], not {active_share!r}")
    if memory_limit is None:
        memory_limit = DEFAULT_MEMORY_LIMIT
    plan, need = _plan(state, voxel_size, memory_limit, region, velocity, tile, thin_cirrus, active_share)
    if need is None:
        return plan

    def fits(v: float) -> bool:
        return _plan(state, v, memory_limit, region, velocity, tile, thin_cirrus, active_share)[1] is None

    # A first guess from the estimate alone (memory as the cube of the voxel size, tiles as its square).
    tiles_over = math.ceil(plan.dims[0] / tile) * math.ceil(plan.dims[1] / tile) / MAX_TILES
    scale = max(((need - BASE_BYTES) / max(memory_limit - BASE_BYTES, 1.0)) ** (1 / 3), tiles_over**0.5)
    suggested = smallest_fitting_voxel(fits, voxel_size, voxel_size * scale)
    raise BakeTooLarge(
        f"a bake at {voxel_size:g} m voxels needs {plan.dims[0]}x{plan.dims[1]}x{plan.dims[2]} voxels "
        f"(about {need / 1024**3:.1f} GB): use a voxel size of at least {suggested:g} m",
        suggested,
    )


class BakeTooLarge(NubisError):
    """A bake that would not fit in memory; `suggested` is the smallest voxel size that does."""

    def __init__(self, message: str, suggested: float) -> None:
        super().__init__(message)
        self.suggested = suggested


def _plan(
    state, voxel_size, memory_limit, region, velocity, tile, thin_cirrus, active_share=1.0
) -> tuple[BakePlan, float | None]:
    """The plan at this voxel size and None, or a plan without tiles and the bytes it would need (a
    coarse bound when the box alone has too many tiles) when it does not fit in `memory_limit`."""
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
        # `thin_cirrus` makes it just that: a ray at a grazing angle then crosses it over a short
        # stretch of the cirrus, as the 2D layer the viewport samples at one point (a comparison).
        slab = 2.0 * voxel_size if thin_cirrus else max(p["cirrus_thickness"], 2.0 * voxel_size)
        hi = max(hi, p["cirrus_altitude"] + slab / 2)
    planet = p["layer_planet_radius"]
    far = max(math.hypot(x, y) for x in (x0, x1) for y in (y0, y1))
    sag = planet + lo - math.sqrt(max((planet + lo) ** 2 - far**2, 0.0))
    z0, z1 = lo - sag, hi
    v = voxel_size
    dims = tuple(max(1, math.ceil((b - a) / v)) for a, b in ((x0, x1), (y0, y1), (z0, z1)))
    plan = BakePlan((x0 + v / 2, y0 + v / 2, z0 + v / 2), v, dims, slab, velocity=velocity)
    n_tiles = math.ceil(dims[0] / tile) * math.ceil(dims[1] / tile)
    if n_tiles > MAX_TILES:
        # The box alone is absurd: refused before planning every tile, with a coarse bound (a tenth of
        # the box in cloud) for the message.
        return plan, BASE_BYTES + plan.voxels * 0.1 * BYTES_PER_ACTIVE_VOXEL
    tiles = tuple(plan_tiles(state, plan, tile))
    plan = BakePlan(
        plan.origin, v, dims, slab, tiles, velocity=velocity, extra_grids=_extra_grids(state), active_share=active_share
    )
    return plan, (plan.bytes_estimate if plan.bytes_estimate > memory_limit else None)


# The largest size the search tries: a whole sky at 10 km voxels holds a few thousand of them.
_SEARCH_MAX = 10_000.0


def smallest_fitting_voxel(fits, refused: float, guess: float) -> float:
    """The smallest voxel size above `refused` (which `fits` refuses) that `fits` accepts, to three
    significant figures (whole metres from 100 m on), starting from `guess`.

    A size scaled from the estimate alone (memory as the cube of the voxel size) undershoots: the tiles'
    slices keep margins of whole voxels and their field windows a texel more, so the estimate falls
    slower than the cube, and the size so named was refused in turn. This asks the very check the bake
    makes: up by quarters from the guess until a size fits, then halving the gap to the last refused
    size (the estimate falls as the voxels grow, so the boundary found is the smallest size that fits)."""
    lo, hi = refused, max(guess, refused * 1.01)
    while not fits(hi):
        if hi >= _SEARCH_MAX:
            return hi
        lo, hi = hi, min(hi * 1.25, _SEARCH_MAX)
    step = 10.0 ** (math.floor(math.log10(hi)) - 2)

    def at(k: int) -> float:
        return round(k * step, 12)

    a, b = math.floor(lo / step), math.ceil(hi / step)
    for _ in range(20):  # hi rounded up to the step: the estimate need not fall at every size
        if fits(at(b)):
            break
        b += 1
    else:
        return hi
    while b - a > 1:
        mid = (a + b) // 2
        if fits(at(mid)):
            b = mid
        else:
            a = mid
    return at(b)


def _extra_grids(state: CloudState) -> int:
    """How many float grids beside density the sky can fill: absorption where it rains, glow in storms."""
    rain = state.field_a is not None and float(np.max(state.field_a[..., 1])) > 0
    return int(rain or bool(state.storms)) + int(bool(state.storms))


def _texel_window(lo: float, hi: float, origin: float, size: float, n: int) -> slice:
    """The field texels a bilinear lookup between world coordinates lo and hi can read, with a texel of
    margin, as a slice: the lookup clamps its uv, so a window past an edge reads the edge's texel."""
    s0 = ((lo - origin) / size + 0.5) * n - 0.5
    s1 = ((hi - origin) / size + 0.5) * n - 0.5
    a = max(math.floor(s0) - 1, 0)
    b = min(math.floor(s1) + 2, n - 1)
    if a > n - 1:
        return slice(n - 1, n)
    if b < 0:
        return slice(0, 1)
    return slice(a, b + 1)


def _z_at(altitude: float, r: float, planet: float) -> float:
    """Height above the tangent plane of a point at `altitude` over the sphere, r metres from the axis."""
    return math.sqrt(max((planet + altitude) ** 2 - r * r, 0.0)) - planet


@dataclass(frozen=True)
class _LayerBounds:
    """What bounds one drawn cloud layer's clouds, read from its field (plan_tiles)."""

    cover: np.ndarray  # coverage x its multiplier, clipped
    coverage: np.ndarray  # where the density can be non-zero
    top_type: np.ndarray
    bottom_type: np.ndarray
    col_lo: np.ndarray  # each column's own bottom and top altitudes (min and max height)
    col_hi: np.ndarray
    storm: np.ndarray | None  # storm coverage, where the sky has storms
    dense: np.ndarray  # where the density multiplier (field B alpha) is non-zero
    extent: tuple[float, float]  # the altitudes its clouds can reach (cloudlayers.disjoint_extents)
    bottom: float
    from_wind: float  # how far upwind its anvil reads its storm coverage


def _layer_bounds(state: CloudState) -> list[_LayerBounds]:
    layers = state.drawn_layers()
    out = []
    for layer, extent in zip(layers, cloudlayers.disjoint_extents(layers), strict=True):
        p, fa, fb = layer.params, layer.field_a, layer.field_b
        bottom, thick = p["layer_bottom"], p["layer_top"] - p["layer_bottom"]
        cover = np.clip(fa[..., 0] * p["density_coverage"], 0.0, 1.0)
        out.append(
            _LayerBounds(
                cover=cover,
                coverage=(cover > 0) & (fb[..., 3] > 0),
                top_type=np.clip(fa[..., 2], 0.0, 1.0),
                bottom_type=np.clip(fa[..., 3], 0.0, 1.0),
                col_lo=bottom + fb[..., 1] * thick,
                col_hi=bottom + fb[..., 2] * thick,
                storm=(fb[..., 0] > 0) & (fb[..., 3] > 0) if state.storms else None,
                dense=fb[..., 3] > 0,
                extent=extent,
                bottom=bottom,
                from_wind=float(np.hypot(*wind_vector(p["wind_direction"]))) * state.params["storm_anvil_shift"],
            )
        )
    return out


def _layer_altitudes(b: _LayerBounds, window, storm_window) -> list[tuple[float, float]]:
    """The altitudes one layer's clouds can take over a tile's field texels (`window`; the anvil reads
    `storm_window`, the texels upwind): the column bounds, and the anvil's band under the layer's top."""
    out = []
    if b.coverage[window].any():
        lo, hi = _column_bounds(
            float(b.cover[window].max()),
            float(b.top_type[window].max()),
            float(b.bottom_type[window].min()),
            (float(b.col_lo[window].min()), float(b.col_lo[window].max())),
            (float(b.col_hi[window].min()), float(b.col_hi[window].max())),
        )
        lo, hi = max(lo, b.extent[0]), min(hi, b.extent[1])
        if hi > lo:
            out.append((lo, hi))
    if b.storm is not None and b.storm[storm_window].any() and b.dense[window].any():
        band = 0.22 * (b.extent[1] - b.bottom)
        out.append((b.extent[1] - band, b.extent[1]))
    return out


def plan_tiles(state: CloudState, plan: BakePlan, tile: int = TILE) -> list[Tile]:
    """Cut the box into tiles and find, for each, the slices that can hold cloud: conservative bounds
    read straight from each drawn cloud layer's field, so no cloud is ever skipped. The density is zero
    wherever the bilinear coverage (field A red) or the density multiplier (field B alpha) is zero, and
    below or above the column's own min and max heights (field B green, blue; the vertical profile is
    zero outside them, GPU Pro 7); a superstorm's anvil spreads its storm coverage (field B red) downwind
    under the layer's top (GDC22); the cirrus slab lies around its altitude where field C red is
    non-zero. Tiles beyond the draw radius, outside the field or outside a clip box are empty."""
    p = state.params
    v = plan.voxel_size
    ox, oy, oz = plan.origin
    nx, ny, nz = plan.dims
    planet = p["layer_planet_radius"]
    fx, fy, fs = p["field_origin_x"], p["field_origin_y"], p["field_size"]
    if state.field_a is None or state.field_b is None:  # no field to bound the clouds by: every slice
        return [
            Tile(i0, j0, min(tile, nx - i0), min(tile, ny - j0), ((0, nz),))
            for j0 in range(0, ny, tile)
            for i0 in range(0, nx, tile)
        ]
    res_y, res_x = state.field_a.shape[:2]
    layers = _layer_bounds(state)
    cirrus = None
    if plan.cirrus_slab and p["density_sigma"] > 0 and p["cirrus_opacity"] > 0:
        cirrus = state.field_c[..., 0] * p["cirrus_coverage"] > 0
    radius = p["layer_draw_radius"]
    dcx, dcy = state.draw_center
    clip = state.clip_box
    margin_z = v + 4.0  # a voxel, and the shader's float32 altitude near a 6371 km sphere
    tiles = []
    for j0 in range(0, ny, tile):
        for i0 in range(0, nx, tile):
            tx, ty = min(tile, nx - i0), min(tile, ny - j0)
            xa, xb = ox + i0 * v, ox + (i0 + tx - 1) * v
            ya, yb = oy + j0 * v, oy + (j0 + ty - 1) * v
            spans = _vdb_spans(state, (xa, xb, ya, yb), v, oz, nz)
            tiles.append(Tile(i0, j0, tx, ty, _merge(spans)))
            # Nearest point of the tile to the draw centre: clouds exist only inside the radius.
            near = math.hypot(max(xa - dcx, 0.0, dcx - xb), max(ya - dcy, 0.0, dcy - yb))
            if near >= radius or xb < fx - fs / 2 or xa > fx + fs / 2 or yb < fy - fs / 2 or ya > fy + fs / 2:
                continue
            if clip is not None and (xb < clip[0] or xa > clip[2] or yb < clip[1] or ya > clip[3]):
                continue
            rmin = math.hypot(max(xa, 0.0, -xb), max(ya, 0.0, -yb))
            rmax = max(math.hypot(x, y) for x in (xa, xb) for y in (ya, yb))
            window = (_texel_window(ya, yb, fy, fs, res_y), _texel_window(xa, xb, fx, fs, res_x))
            altitudes = []
            for b in layers:
                w = b.from_wind
                upwind = (_texel_window(ya - w, yb + w, fy, fs, res_y), _texel_window(xa - w, xb + w, fx, fs, res_x))
                altitudes += _layer_altitudes(b, window, upwind)
            if cirrus is not None and cirrus[window].any():
                c = p["cirrus_altitude"]
                altitudes.append((c - plan.cirrus_slab / 2, c + plan.cirrus_slab / 2))
            for lo, hi in altitudes:
                k0 = max(math.floor((_z_at(lo, rmax, planet) - margin_z - oz) / v), 0)
                k1 = min(math.ceil((_z_at(hi, rmin, planet) + margin_z - oz) / v) + 1, nz)
                if k1 > k0:
                    spans.append((k0, k1))
            tiles[-1] = Tile(i0, j0, tx, ty, _merge(spans))
    return tiles


def _vdb_spans(state: CloudState, rect: tuple[float, float, float, float], v: float, oz: float, nz: int) -> list:
    """The slices of the artists' VDB clouds' world boxes (core/vdbread.py) over a tile's rectangle, with
    the half voxel a sample reads."""
    xa, xb, ya, yb = rect
    spans = []
    for lo_box, hi_box in (placed.world_box for placed in state.vdb_clouds):
        if xb >= lo_box[0] - v and xa <= hi_box[0] + v and yb >= lo_box[1] - v and ya <= hi_box[1] + v:
            k0 = max(math.floor((lo_box[2] - v - oz) / v), 0)
            k1 = min(math.ceil((hi_box[2] + v - oz) / v) + 1, nz)
            if k1 > k0:
                spans.append((k0, k1))
    return spans


def _column_bounds(
    c: float, top_type: float, bottom_type: float, lo: tuple[float, float], hi: tuple[float, float]
) -> tuple[float, float]:
    """Altitudes outside which a column's density is zero, for coverage up to `c`, top types up to
    `top_type`, bottom types from `bottom_type` and column bottoms and tops within `lo` and `hi`.

    The base shape (at most 1) times the vertical profile must exceed 1 - coverage before the coverage
    remap leaves anything (GPU Pro 7's remap of the base shape by coverage), so the profile must: its
    top ramp (from ramp x to ramp y, both rising with the top type; shaders/nubis_density_lib.glsl)
    passes 1 - c below ramp x + c (ramp y - ramp x), its bottom ramp passes it above (1 - c) x the
    bottom ramp's end. Both bounds grow with the types and the coverage, so the extremes bound them."""
    if top_type < 0.5:
        rx, ry = 0.10 + (0.40 - 0.10) * top_type * 2, 0.20 + (0.60 - 0.20) * top_type * 2
    else:
        rx, ry = 0.40 + (0.70 - 0.40) * (top_type * 2 - 1), 0.60 + (1.00 - 0.60) * (top_type * 2 - 1)
    h_top = min(rx + c * (ry - rx), 1.0)
    h_bottom = max((1.0 - c) * (0.05 + 0.30 * bottom_type), 0.0)
    # altitude = (1 - h) bottom + h top, rising in h, the bottom and the top (the shader divides by at
    # least a metre of thickness: bounded the same way).
    return (1 - h_bottom) * lo[0] + h_bottom * hi[0], (1 - h_top) * lo[1] + h_top * hi[1]


def _merge(spans: list[tuple[int, int]]) -> tuple[tuple[int, int], ...]:
    out: list[list[int]] = []
    for k0, k1 in sorted(spans):
        if out and k0 <= out[-1][1]:
            out[-1][1] = max(out[-1][1], k1)
        else:
            out.append([k0, k1])
    return tuple((a, b) for a, b in out)


# A comparison bakes only the camera's view, so it can afford finer voxels than a whole-sky bake:
# trilinear interpolation of coarse voxels thickens thin cloud edges, a difference between the viewport
# and Cycles that would be the bake's, not the light model's (docs/measurements.md#bake-planning).
COMPARE_VOXEL_BUDGET = 64_000_000  # the fixed budget of comparison_voxel_size (the benchmark's EEVEE bake)
COMPARE_FINEST_VOXEL = 20.0
# The camera's own voxel size: voxels per pixel footprint at the nearest cloud, and the finest it goes.
# Trilinear reconstruction spreads a voxel over its neighbours, so one voxel per footprint still
# thickens the thinnest edges; 1.5 per footprint takes most of that away for 1.5^3 (3.4) times the
# voxels (docs/measurements.md#bake-planning).
CAMERA_VOXELS_PER_FOOTPRINT = 1.5
CAMERA_FINEST_VOXEL = 15.0


def nearest_cloud_distance(state: CloudState, inv_view_proj: np.ndarray, samples: int = 33) -> float:
    """Metres from the camera to the nearest point of the cloud shell (or the cirrus) that a ray through
    the image reaches within the draw radius: 0 from inside the shell."""
    p = state.params
    planet = p["layer_planet_radius"]
    lo, hi = state.shell()
    origin, direction = _camera_rays(inv_view_proj, samples)
    altitude = float(np.linalg.norm(origin[0] - np.array([0.0, 0.0, -planet]))) - planet
    if lo <= altitude <= hi:
        return 0.0
    altitudes = [lo, hi] + ([p["cirrus_altitude"]] if state.has_cirrus() else [])
    best = math.inf
    for dist, hit in _sphere_hits(origin, direction, planet, altitudes):
        points = (origin + direction * dist[:, None])[hit][:, :2]
        inside = np.linalg.norm(points - np.asarray(state.draw_center), axis=1) < p["layer_draw_radius"]
        if inside.any():
            best = min(best, float(dist[hit][inside].min()))
    return best


def camera_footprint_voxel(
    state: CloudState,
    inv_view_proj: np.ndarray,
    width: int,
    height: int,
    start: float,
    finest: float = CAMERA_FINEST_VOXEL,
) -> float:
    """The voxel size a camera asks for, memory aside: a pixel's footprint at the nearest cloud it sees
    over CAMERA_VOXELS_PER_FOOTPRINT, no finer than `finest`, no coarser than `start`."""
    angle, size = pixel_footprint(inv_view_proj, width, height)
    near = nearest_cloud_distance(state, inv_view_proj)
    footprint = (near * angle + size) / CAMERA_VOXELS_PER_FOOTPRINT if math.isfinite(near) else start
    return min(max(finest, footprint), max(start, finest))


def camera_fitting_voxel(
    state: CloudState, inv_view_proj: np.ndarray, voxel: float, active_share: float = 1.0
) -> float:
    """`voxel` (camera_footprint_voxel) or, when the camera-only bake would not fit in memory at that
    size, the smallest size where it does (doubling would overshoot: 15 m that does not fit would become
    30 m where 20 m fits). `active_share` as in plan_bake."""
    try:
        plan_bake(state, voxel, region=view_footprint(state, inv_view_proj), active_share=active_share)
    except BakeTooLarge as err:
        return err.suggested  # the smallest size that fits (smallest_fitting_voxel)
    return voxel


# The bound counts every voxel the tiles evaluate as active; the clouds fill far fewer, so the bound can
# refuse a bake whose trees would fit many times over. The share the clouds fill grows a little towards finer voxels
# (they resolve more of the thin edges), and leaves are only partly full: a share measured by a probe bake
# at a coarser size, times this margin, covers both (docs/bake.md#memory,
# docs/measurements.md#bake-planning).
SHARE_MARGIN = 1.5
# A probe that finds almost no cloud still counts this share, so a bake never plans for nothing.
SHARE_FLOOR = 0.01
# How full the trees' leaves are (docs/measurements.md#bake-planning): a bake that counts its active voxels
# as it goes divides by this for the bytes its trees hold.
LEAF_FILL = 0.8


def measured_share(active: int, evaluated: int) -> float:
    """The active share a bake may plan with (BakePlan.active_share), from a probe bake of the same
    sky that found `active` cloudy voxels among `evaluated` ones: with SHARE_MARGIN, at least
    SHARE_FLOOR, at most 1 (the bound)."""
    if evaluated <= 0:
        return 1.0
    return min(1.0, max(SHARE_FLOOR, active / evaluated * SHARE_MARGIN))


def comparison_voxel_size(
    state: CloudState, start: float, region: tuple[float, float, float, float], budget: int = COMPARE_VOXEL_BUDGET
) -> float:
    """The finest voxel size, halving from `start` down to 20 m, whose camera-only bake stays within
    `budget` voxels (about 1.3 GB while baking)."""
    size = start
    while size / 2 >= COMPARE_FINEST_VOXEL:
        try:  # _plan, not plan_bake: a size that does not fit ends the halving, no suggestion is needed
            finer, too_large = _plan(state, size / 2, DEFAULT_MEMORY_LIMIT, region, False, TILE, False)
        except NubisError:
            break
        if too_large is not None or finer.voxels > budget:
            break
        size /= 2
    return size
