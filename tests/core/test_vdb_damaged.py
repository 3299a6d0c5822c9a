"""Damaged and hostile VDB files: every one refused in one sentence, before OpenVDB allocates what it states.

A file cut at every length, garbage after a true header, bytes changed in place, a folder, a FIFO, a
device, names too long, grids spread far apart, values beyond half floats, nameless grids, objects scaled
to zero (docs/vdb.md#damaged-files).
"""

from __future__ import annotations

import os
import random
import tracemalloc

import numpy as np
import pytest

from nubis_addon.core import bricks, vdbcheck, vdbplacement, vdbread
from nubis_addon.core.errors import NubisError
from tests.vdb_helpers import _openvdb, ball, write_cumulus, write_grid, write_two_voxels


def one_sentence(err: NubisError) -> str:
    text = str(err)
    assert "\n" not in text and len(text) < 1000, text[:1200]
    assert "internal error" not in text and "Traceback" not in text
    return text


@pytest.fixture(scope="module")
def small_vdb(tmp_path_factory):
    """A cumulus of the project's own, under 64 KB, with file metadata and two grids."""
    path = tmp_path_factory.mktemp("small") / "small.vdb"
    vdb = _openvdb()
    write_cumulus(path, n_xy=14, n_z=14)
    grids, meta = vdb.readAll(str(path))
    extra = vdb.FloatGrid()
    extra.name = "temperature"
    extra.copyFromArray(np.ones((8, 8, 8), np.float32))
    vdb.write(str(path), grids=[*grids, extra], metadata={"creator": "nubis tests", "frame": 12})
    assert path.stat().st_size <= 64 * 1024
    return path


def test_a_file_cut_at_every_length_is_refused_in_one_sentence(small_vdb, tmp_path):
    data = small_vdb.read_bytes()
    assert vdbread.read_cloud(small_vdb).active_voxels > 0  # whole, it reads
    cut = tmp_path / "cut.vdb"
    cut.write_bytes(data)
    seen = set()
    for n in range(len(data) - 1, 0, -1):
        os.truncate(cut, n)  # (writing each cut anew takes a millisecond on some file systems)
        with pytest.raises(NubisError) as err:
            vdbread.read_cloud(cut)
        text = one_sentence(err.value)
        assert "is damaged (" in text and ("cut short" in text or "more than" in text), (n, text)
        seen.add(text.split("is damaged (")[1][:12])
    assert len(seen) >= 3  # cut in the header, the metadata, the descriptors and the grids: each says where


@pytest.mark.parametrize("seed", range(6))
def test_a_true_header_followed_by_garbage_is_refused(small_vdb, tmp_path, seed):
    rng = random.Random(seed)
    bad = tmp_path / "garbage.vdb"
    bad.write_bytes(small_vdb.read_bytes()[:64] + bytes(rng.randrange(256) for _ in range(rng.randrange(10, 9000))))
    with pytest.raises(NubisError, match="is damaged") as err:
        vdbread.read_cloud(bad)
    one_sentence(err.value)


def test_bytes_changed_in_place_never_allocate_what_they_state(small_vdb, tmp_path):
    """Bytes changed anywhere: one sentence (or a readable cloud), and the memory OpenVDB and numpy take
    stays small (a delayed-load count of 3.2 billion once filled 3.2 GB before it was checked)."""
    data = small_vdb.read_bytes()
    rng = random.Random(11)
    bad = tmp_path / "flipped.vdb"
    read = refused = 0
    for trial in range(150):
        b = bytearray(data)
        span = 600 if trial % 2 else len(b)
        for _ in range(rng.randrange(1, 5)):
            b[rng.randrange(0, span)] = rng.randrange(256)
        bad.write_bytes(bytes(b))
        try:
            vdbread.read_cloud(bad)
            read += 1
        except NubisError as err:
            one_sentence(err)
            refused += 1
    assert refused > 50 and read + refused == 150
    # The delayed-load table's node count, checked against its value's size.
    at = data.index(b"__delayedload") + len(b"__delayedload") + 4
    b = bytearray(data)
    b[at : at + 4] = (3_200_000_000).to_bytes(4, "little")
    bad.write_bytes(bytes(b))
    with pytest.raises(NubisError, match=r"delayed-load table .* states more than its \d+ bytes hold"):
        vdbread.read_cloud(bad)


def test_what_is_not_a_vdb_file_is_named_for_what_it_is(tmp_path):
    cases = {tmp_path: "is a folder, not a VDB file", "/dev/zero": "is a device, pipe or other special file"}
    fifo = tmp_path / "pipe.vdb"
    os.mkfifo(fifo)
    cases[fifo] = "is a device, pipe or other special file"
    cases[tmp_path / ("n" * 300 + ".vdb")] = "has a name longer than the file system allows"
    cases[tmp_path / "gone.vdb"] = r"is not there \(moved or deleted\?\)"
    (tmp_path / "empty.vdb").write_bytes(b"")
    cases[tmp_path / "empty.vdb"] = r"is empty \(0 bytes\)"
    (tmp_path / "text.vdb").write_text("a text file\n")
    cases[tmp_path / "text.vdb"] = "is not an OpenVDB file"
    for path, words in cases.items():
        with pytest.raises(NubisError, match=words) as err:
            vdbread.choose_grid(path)
        text = one_sentence(err.value)
        assert len(text) < 400  # the 300-character name is shortened


def test_two_voxels_far_apart_are_drawn_within_the_memory_bound(tmp_path):
    """16,000 voxels apart along x and y: drawn, its index 4 MB and its bricks the sixteen that read the
    two voxels, the copy following the two nodes that hold them (a slab of the box dense in x and y took
    121 GiB). 60,000 apart along x: wider than the index texture's 2048 leaves at the file's voxels, so
    drawn at level 2 (4 x 4 x 4 voxels to one, each voxel's value a 64th), copying its two nodes only. A
    cloud too wide even at the coarsest level is refused in one sentence."""
    for name, far, level in (("wide", (60_000, 0, 0), 2), ("drawn", (16_000, 16_000, 0), 0)):
        path = write_two_voxels(tmp_path / f"{name}.vdb", far)
        tracemalloc.start()
        try:
            cloud = vdbread.read_cloud(path, dtype=np.float32)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert peak < 64 * 1024**2, (name, peak)
        assert cloud.level == level and cloud.bricks.count == 16  # each voxel in the 8 bricks that read it
        step = 2**level
        ijk = np.array([[far[0] // step, far[1] // step, 0.0], [0.0, 0.0, 0.0]]) - cloud.bricks.leaf_origin
        atlas, per_side, _ = bricks.layout([cloud.bricks.data])
        got = bricks.sample(atlas, per_side, cloud.bricks.index, 0, ijk)
        np.testing.assert_allclose(got, np.array([0.25, 0.5]) / step**3)
    path = write_two_voxels(tmp_path / "widest.vdb", (16_400 * 16, 0, 0))
    too_wide = "spans 262401 voxels along x, more than the 262144 .* averaged 16 x 16 x 16 voxels to one"
    with pytest.raises(NubisError, match=too_wide) as err:
        vdbread.read_cloud(path)
    one_sentence(err.value)


def test_active_tiles_count_in_the_estimate(tmp_path):
    """A region stored as an active tile has no leaves, but every voxel of it is cloud: the plan counts it."""
    vdb = _openvdb()
    grid = vdb.FloatGrid()
    grid.name = "density"
    grid.fill((0, 0, 0), (4095, 4095, 4095), 0.01, True)
    grid.transform = vdb.createLinearTransform(voxelSize=1.0)
    path = tmp_path / "tiles.vdb"
    vdb.write(str(path), grids=[grid])
    # A coarser level's bricks would fit, but it would be averaged from 69 billion voxels: refused.
    with pytest.raises(NubisError, match="needs at least .* on the GPU as bricks.*68.7 billion voxels") as err:
        vdbread.check_fits(path)
    one_sentence(err.value)
    assert vdbread.estimate_gpu_bytes(path)[1] > 131072 * 729 * 2  # 16^3 leaves of tile per node, 32 nodes


def test_values_beyond_half_floats_stay_finite_and_exact_in_ratio(tmp_path):
    dense = ball() * 1e7 / 0.02  # a peak of 1e7 per metre: half floats end at 65504
    cloud = vdbread.read_cloud(write_grid(tmp_path / "hot.vdb", dense))
    assert np.isfinite(cloud.bricks.data.astype(np.float32)).all()
    assert cloud.storage_scale > 1.0
    stored = bricks.unpack(cloud.bricks).max() * cloud.storage_scale
    assert stored == pytest.approx(dense.max(), rel=2e-3)
    placed = vdbplacement.Placement(cloud, np.eye(4), 2.0)
    assert placed.extinction_scale == pytest.approx(2.0 * cloud.storage_scale)


def test_a_nameless_grid_is_refused_as_blender_cannot_draw_it(tmp_path):
    path = write_grid(tmp_path / "nameless.vdb", ball(), name="")
    with pytest.raises(NubisError, match="one float grid with no name, which Blender's renderers cannot draw"):
        vdbread.choose_grid(path)


@pytest.mark.parametrize(
    "matrix, words",
    [
        (np.diag([0.0, 1.0, 1.0, 1.0]), "is scaled to zero along an axis"),
        (np.diag([1e-7, 1.0, 1.0, 1.0]), r"is flattened: its axes' scales \(1e-07, 1, 1\) differ more than 1e\+06"),
        (np.diag([np.nan, 1.0, 1.0, 1.0]), "not a finite number"),
    ],
)
def test_a_placement_that_cannot_be_inverted_is_one_sentence(tmp_path, matrix, words):
    cloud = vdbread.read_cloud(write_grid(tmp_path / "ball.vdb", ball()))
    with pytest.raises(NubisError, match=words) as err:
        vdbplacement.Placement(cloud, matrix, 1.0).check("Cloud")
    one_sentence(err.value)


@pytest.mark.parametrize("scale", [1e-9, 1e-6, 1e6])
def test_a_uniform_scale_of_any_size_is_drawn(tmp_path, scale):
    """The limit is the matrix's shape, not its size: a Volume scaled 1e-6 was refused as 'scaled to zero'
    (an absolute determinant test), though its matrix inverts exactly."""
    cloud = vdbread.read_cloud(write_grid(tmp_path / "ball.vdb", ball()))
    placed = vdbplacement.Placement(cloud, np.diag([scale, scale, scale, 1.0]), 1.0)
    placed.check("Cloud")
    assert np.allclose(placed.world_to_leaf_index[:, :3] @ placed.index_to_world[:3, :3], np.eye(3))


def test_the_layout_check_reads_every_transform_and_value_type(tmp_path):
    """Every linear map and tree type OpenVDB writes passes the layout check, so no good file is refused."""
    vdb = _openvdb()
    c, s = np.cos(0.3), np.sin(0.3)
    maps = {
        "uniform": vdb.createLinearTransform(voxelSize=0.5),
        "uniform_translate": vdb.createLinearTransform([[2, 0, 0, 0], [0, 2, 0, 0], [0, 0, 2, 0], [1, 2, 3, 1]]),
        "scale": vdb.createLinearTransform([[1, 0, 0, 0], [0, 2, 0, 0], [0, 0, 3, 0], [0, 0, 0, 1]]),
        "scale_translate": vdb.createLinearTransform([[1, 0, 0, 0], [0, 2, 0, 0], [0, 0, 3, 0], [4, 5, 6, 1]]),
        "affine": vdb.createLinearTransform([[c, s, 0, 0], [-s, c, 0, 0], [0, 0, 1, 0], [4, 5, 6, 1]]),
        "frustum": vdb.createFrustumTransform(xyzMin=(0, 0, 0), xyzMax=(10, 10, 10), taper=0.5, depth=5),
    }
    kinds = [vdb.FloatGrid, vdb.DoubleGrid, vdb.Int32Grid, vdb.Int64Grid, vdb.BoolGrid, vdb.Vec3SGrid, vdb.Vec3DGrid]
    for label, transform in maps.items():
        grids = []
        for n, kind in enumerate(kinds):
            g = kind()
            g.name = f"g{n}"
            value = True if kind is vdb.BoolGrid else ((1, 2, 3) if "Vec3" in kind.__name__ else 3)
            for ijk in ((0, 0, 0), (5000, 0, 0), (0, -9000, 300)):
                g.getAccessor().setValueOn(ijk, value)
            g.transform = transform
            grids.append(g)
        half = vdb.FloatGrid()
        half.name = "half"
        half.getAccessor().setValueOn((1, 1, 1), 2.0)
        half.saveFloatAsHalf = True
        tiles = vdb.FloatGrid()
        tiles.name = "tiles"
        tiles.fill((0, 0, 0), (4500, 130, 130), 1.0, True)
        path = tmp_path / f"{label}.vdb"
        vdb.write(str(path), grids=[*grids, half, tiles], metadata={"note": "x" * 3000})
        layout = vdbcheck.check(path)
        assert [g.name for g in layout.grids] == [*(g.name for g in grids), "half", "tiles"], label
        assert layout.grids[-2].half
