"""VDB clouds made outside the extension, for the tests and the pictures: a cumulus written with OpenVDB's
own Python module (Blender's bundle), as a simulation or modelling tool would hand it over.

The cloud is a cauliflower of overlapping spheres on a flat base, eroded at its edges by a few octaves of
value noise; 50 m voxels, about 3 km across and 2 km tall, its values extinction per metre (0.04 in its
core), with a transform of its own: a rotation about the vertical and a translation that puts it about
5 km in front of the default preset's camera, between 1.4 and 3.5 km up.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

# In front of the default preset's camera (at (0, -6000, 2), looking north-west and up): its base centre.
DEFAULT_VIEW_BASE = (-1500.0, -2000.0, 1400.0)


def _openvdb():
    from nubis_addon.core import bundled

    return bundled.openvdb()


def _value_noise(shape, cells, rng) -> np.ndarray:
    """Smooth noise in [0, 1]: a random lattice of `cells` per side (or per axis z, y, x: streaks where one
    axis has few), trilinearly interpolated."""
    cells = (cells,) * 3 if isinstance(cells, int) else tuple(cells)
    lattice = rng.random(tuple(c + 1 for c in cells))
    coords = [np.linspace(0, c, n, endpoint=False) for n, c in zip(shape, cells, strict=True)]
    z, y, x = np.meshgrid(*coords, indexing="ij")
    i, j, k = (np.minimum(a.astype(int), c - 1) for a, c in zip((z, y, x), cells, strict=True))
    fz, fy, fx = z - i, y - j, x - k
    fz, fy, fx = (f * f * (3 - 2 * f) for f in (fz, fy, fx))
    out = np.zeros(shape)
    for dz in (0, 1):
        for dy in (0, 1):
            for dx in (0, 1):
                w = (fz if dz else 1 - fz) * (fy if dy else 1 - fy) * (fx if dx else 1 - fx)
                out += w * lattice[i + dz, j + dy, k + dx]
    return out


CUMULUS_OCTAVES = ((4, 0.55), (9, 0.3), (18, 0.15))  # value noise: (cells per side, amplitude)


def cumulus(
    n_xy: int = 64,
    n_z: int = 44,
    seed: int = 7,
    peak: float = 0.04,
    puffs: int = 34,
    erosion: float = 7.0,
    octaves=CUMULUS_OCTAVES,
) -> np.ndarray:
    """The cloud's extinction per metre, indexed [z, y, x]. Sizes are in voxels of a 64-voxel-wide cloud,
    scaled with `n_xy` (a finer cloud of the same shape at 128); `erosion` is how many such voxels the noise
    moves the surface, and `octaves` its cells per side and amplitudes."""
    rng = np.random.default_rng(seed)
    z, y, x = np.mgrid[0:n_z, 0:n_xy, 0:n_xy].astype(np.float64)
    k = n_xy / 64
    shape = np.full(z.shape, -1e9)
    centre = n_xy / 2
    for _ in range(puffs):
        cx, cy = rng.normal(centre, n_xy * 0.14, 2)
        cz = rng.uniform(8 * k, n_z * 0.6)
        r = rng.uniform(9, 15) * k * (1.0 - 0.4 * cz / n_z)
        d = r - np.sqrt((x - cx) ** 2 + (y - cy) ** 2 + ((z - cz) * 1.1) ** 2)
        shape = np.maximum(shape, d)
    noise = sum(_value_noise(z.shape, c, rng) * a for c, a in octaves)
    field = shape + (noise - 0.5) * erosion * k
    base = np.clip((z - 2.0 * k) / (3.0 * k), 0.0, 1.0)  # a flat, slightly soft base
    density = np.clip(field / (4.0 * k), 0.0, 1.0) * base
    return (density * peak).astype(np.float32)


def write_cumulus(path: Path, base=DEFAULT_VIEW_BASE, voxel: float = 50.0, turn: float = 0.5, vdb=None, **kw) -> Path:
    """The cumulus as a .vdb (grid 'density'), its base centred on `base`, turned by `turn` radians;
    `vdb` the openvdb module (Blender's bundled one by default)."""
    return write_cloud(path, cumulus(**kw), base, voxel, turn, vdb)


def write_cloud(path: Path, dense: np.ndarray, base, voxel: float, turn: float, vdb=None) -> Path:
    """A cloud's extinction [z, y, x] as a .vdb fog volume (grid 'density'), its base centred on `base`,
    turned by `turn` radians about the vertical; written beside and then moved into place."""
    vdb = vdb or _openvdb()
    nz, ny, nx = dense.shape
    grid = vdb.FloatGrid()
    grid.copyFromArray(np.ascontiguousarray(dense.transpose(2, 1, 0)), tolerance=1e-5)
    grid.name = "density"
    grid.gridClass = vdb.GridClass.FOG_VOLUME
    c, s = np.cos(turn), np.sin(turn)
    # Index (i, j, k) -> world: rotate the index box about its base centre, then move it to `base`.
    half = np.array([nx / 2, ny / 2, 0.0]) * voxel
    origin = np.array(base, np.float64) - np.array([c * half[0] - s * half[1], s * half[0] + c * half[1], 0.0])
    grid.transform = vdb.createLinearTransform(
        [[voxel * c, voxel * s, 0, 0], [-voxel * s, voxel * c, 0, 0], [0, 0, voxel, 0], [*origin, 1.0]]
    )
    tmp = Path(path).with_name(f".{Path(path).name}.tmp")
    vdb.write(str(tmp), grids=[grid])
    tmp.replace(path)
    return Path(path)


def ball(n=40, value=0.02) -> np.ndarray:
    z, y, x = np.mgrid[0:n, 0:n, 0:n]
    r = np.sqrt((x - n / 2) ** 2 + (y - n / 2) ** 2 + (z - n / 2) ** 2)
    return (np.clip((n * 0.35 - r) / 4, 0, 1) * value).astype(np.float32)


def write_grid(path, dense_zyx, rows=None, name="density", extra=(), nan_at=None):
    vdb = _openvdb()
    g = vdb.FloatGrid()
    g.copyFromArray(np.ascontiguousarray(dense_zyx.transpose(2, 1, 0)), tolerance=0.0)
    if nan_at is not None:  # copyFromArray drops NaN (it compares values with the background)
        g.getAccessor().setValueOn(nan_at, float("nan"))
    g.name = name
    g.transform = vdb.createLinearTransform(rows or [[50, 0, 0, 0], [0, 50, 0, 0], [0, 0, 50, 0], [0, 0, 0, 1]])
    vdb.write(str(path), grids=[g, *extra])
    return path


BAD_KINDS = ("not a vdb", "missing", "no float grid", "empty", "negative", "nan", "non-uniform", "sheared")


def bad_vdb(tmp_path, kind):
    """A file of one kind of trouble and the words its refusal holds."""
    dense = ball()
    if kind == "not a vdb":
        p = tmp_path / "cloud.vdb"
        p.write_text("this is a text file, not a VDB\n")
        return p, "is not an OpenVDB file"
    if kind == "missing":
        return tmp_path / "gone.vdb", "is not there"
    if kind == "no float grid":
        vdb = _openvdb()
        vec = vdb.Vec3SGrid()
        vec.name = "velocity"
        vec.copyFromArray(np.ones((4, 4, 4, 3), np.float32))
        p = tmp_path / "vec.vdb"
        vdb.write(str(p), grids=[vec])
        return p, "has no float grid to draw as a cloud"
    if kind == "empty":
        return write_grid(tmp_path / "empty.vdb", np.zeros((8, 8, 8), np.float32)), "is empty"
    if kind == "negative":
        dense[20, 20, 20] = -0.5
        return write_grid(tmp_path / "neg.vdb", dense), "negative values"
    if kind == "nan":
        return write_grid(tmp_path / "nan.vdb", dense, nan_at=(20, 20, 20)), "NaN or infinite"
    if kind == "non-uniform":
        rows = [[50, 0, 0, 0], [0, 50, 0, 0], [0, 0, 80, 0], [0, 0, 0, 1]]
        return write_grid(tmp_path / "stretch.vdb", dense, rows), "non-uniform voxels"
    if kind == "sheared":
        rows = [[50, 0, 0, 0], [30, 40, 0, 0], [0, 0, 50, 0], [0, 0, 0, 1]]  # equal lengths, not square
        return write_grid(tmp_path / "shear.vdb", dense, rows), "sheared transform"
    raise AssertionError(kind)


def write_two_voxels(path, far, voxel: float = 10.0) -> Path:
    """A grid 'density' of two voxels: 0.5 at index (0, 0, 0) and 0.25 at `far`, voxels of `voxel` metres."""
    vdb = _openvdb()
    grid = vdb.FloatGrid()
    grid.name = "density"
    acc = grid.getAccessor()
    acc.setValueOn((0, 0, 0), 0.5)
    acc.setValueOn(tuple(far), 0.25)
    grid.transform = vdb.createLinearTransform(voxelSize=voxel)
    vdb.write(str(path), grids=[grid])
    return Path(path)


def trilinear(dense: np.ndarray, ijk: np.ndarray) -> np.ndarray:
    """A dense grid (z, y, x) at index coordinates (N, 3): x, y, z; 0 outside, as OpenVDB's background."""
    padded = np.pad(dense.astype(np.float64), 1)
    p = ijk + 1.0
    i0 = np.floor(p).astype(int)
    t = p - i0
    out = np.zeros(len(p))
    hi = np.array(padded.shape[::-1]) - 1
    for dz in range(2):
        for dy in range(2):
            for dx in range(2):
                w = (
                    (t[:, 0] if dx else 1 - t[:, 0])
                    * (t[:, 1] if dy else 1 - t[:, 1])
                    * (t[:, 2] if dz else 1 - t[:, 2])
                )
                c = i0 + (dx, dy, dz)
                ok = ((c >= 0) & (c <= hi)).all(-1)
                c = np.clip(c, 0, hi)
                out += np.where(ok, w * padded[c[:, 2], c[:, 1], c[:, 0]], 0.0)
    return out
