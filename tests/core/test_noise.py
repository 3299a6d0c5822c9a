"""Tests of the tiling noise textures (GPU Pro 7, S15) and their cache."""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
import pytest

from nubis_addon.core import noise

TINY = {"lf_size": 16, "hf_size": 8, "curl_size": 32, "cirrus_size": 64}


@pytest.fixture(scope="module")
def full_set() -> noise.NoiseSet:
    return noise.generate_noise_set(0)


SEAM_LIMIT = 1.1


def seam_ratio(a: np.ndarray, axis: int) -> float:
    """Mean |difference| across the wrap seam over the largest mean |difference| between any pair of
    interior neighbour planes. The seam lies on every octave's lattice line, like only a few interior
    planes do, so a seamless texture lands near 1; SEAM_LIMIT allows for the sampling spread of those
    few planes."""
    a = a.astype(np.float32)
    other = tuple(ax for ax in range(a.ndim) if ax != axis)
    interior = float(np.abs(np.diff(a, axis=axis)).mean(axis=other).max())
    seam = float(np.abs(np.take(a, 0, axis=axis) - np.take(a, -1, axis=axis)).mean())
    return seam / interior


def neighbour_difference(a: np.ndarray) -> float:
    a = a.astype(np.float32)
    return float(np.mean([np.abs(np.diff(a, axis=ax)).mean() for ax in range(a.ndim)]))


def central(a: np.ndarray, axis: int) -> np.ndarray:
    return 0.5 * (np.roll(a, -1, axis=axis) - np.roll(a, 1, axis=axis))


# ---------------------------------------------------------------------------------------------------------------
# shapes, dtypes, determinism
# ---------------------------------------------------------------------------------------------------------------


def test_shapes_and_dtypes(full_set: noise.NoiseSet) -> None:
    assert full_set.lf.shape == (128, 128, 128, 4)
    assert full_set.hf.shape == (32, 32, 32, 3)
    assert full_set.curl.shape == (128, 128, 3)
    assert full_set.cirrus.shape == (512, 512, 3)
    for a in full_set.arrays().values():
        assert a.dtype == np.uint8
        assert not a.flags.writeable
    assert full_set.seed == 0
    assert full_set.nbytes == sum(a.nbytes for a in full_set.arrays().values())


def test_channels_use_the_range(full_set: noise.NoiseSet) -> None:
    for name, a in full_set.arrays().items():
        for c in range(a.shape[-1]):
            v = a[..., c]
            assert int(v.max()) - int(v.min()) > 200, (name, c)
            assert v.std() > 25, (name, c)


def test_deterministic_for_a_seed() -> None:
    a = noise.generate_noise_set(7, **TINY)
    b = noise.generate_noise_set(7, **TINY)
    c = noise.generate_noise_set(8, **TINY)
    for name in ("lf", "hf", "curl", "cirrus"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        assert not np.array_equal(getattr(a, name), getattr(c, name)), name


def test_tiny_sizes_have_the_requested_shapes() -> None:
    ns = noise.generate_noise_set(3, **TINY)
    assert ns.lf.shape == (16, 16, 16, 4)
    assert ns.hf.shape == (8, 8, 8, 3)
    assert ns.curl.shape == (32, 32, 3)
    assert ns.cirrus.shape == (64, 64, 3)


@pytest.mark.parametrize("kwargs", [{"seed": -1}, {"lf_size": 100}, {"hf_size": 4}, {"cirrus_size": 96}])
def test_bad_arguments_are_rejected(kwargs: dict) -> None:
    with pytest.raises(ValueError):
        noise.generate_noise_set(**kwargs)


# ---------------------------------------------------------------------------------------------------------------
# tiling
# ---------------------------------------------------------------------------------------------------------------


def test_seam_metric_catches_a_non_tiling_texture() -> None:
    rng = np.random.default_rng(0)
    ramp = np.linspace(0.0, 1.0, 64, dtype=np.float32)[None, :] + 0.01 * rng.random((64, 64), dtype=np.float32)
    assert seam_ratio(ramp, axis=1) > 10


@pytest.mark.parametrize("name", ["lf", "hf"])
def test_3d_textures_tile_in_every_axis(full_set: noise.NoiseSet, name: str) -> None:
    a = getattr(full_set, name)
    for c in range(a.shape[-1]):
        for axis in range(3):
            r = seam_ratio(a[..., c], axis)
            assert r <= SEAM_LIMIT, f"{name} channel {c} axis {axis}: seam ratio {r:.2f}"


@pytest.mark.parametrize("name", ["curl", "cirrus"])
def test_2d_textures_tile_in_every_axis(full_set: noise.NoiseSet, name: str) -> None:
    a = getattr(full_set, name)
    for c in range(a.shape[-1]):
        for axis in range(2):
            r = seam_ratio(a[..., c], axis)
            assert r <= SEAM_LIMIT, f"{name} channel {c} axis {axis}: seam ratio {r:.2f}"


@pytest.mark.parametrize("cells", [2, 4, 8])
def test_helpers_tile(cells: int) -> None:
    # (With a single cell the only lattice line is the seam itself, where Perlin is steepest, so this
    # interior-vs-seam comparison needs at least two cells.)
    for vol in (noise.tiling_perlin_3d(16, cells, 1), noise.tiling_worley_3d(16, cells, 1)):
        for axis in range(3):
            assert seam_ratio(vol, axis) <= SEAM_LIMIT
    for img in (noise.tiling_perlin_2d(32, cells, 1), noise.tiling_worley_2d(32, cells, 1)):
        for axis in range(2):
            assert seam_ratio(img, axis) <= SEAM_LIMIT


def test_warped_perlin_still_tiles() -> None:
    warp = (0.1 * noise.perlin_fbm_2d(64, 2, 2, 5, signed=True), 0.1 * noise.perlin_fbm_2d(64, 2, 2, 6, signed=True))
    img = noise.tiling_perlin_2d(64, (8, 3), 1, warp=warp)
    for axis in range(2):
        assert seam_ratio(img, axis) <= SEAM_LIMIT


# ---------------------------------------------------------------------------------------------------------------
# content
# ---------------------------------------------------------------------------------------------------------------


def test_worley_channels_increase_in_frequency(full_set: noise.NoiseSet) -> None:
    g, b, a = (neighbour_difference(full_set.lf[..., c]) for c in (1, 2, 3))
    assert g < b < a
    r, g, b = (neighbour_difference(full_set.hf[..., c]) for c in range(3))
    assert r < g < b


def test_perlin_worley_is_connected_perlin_not_just_worley(full_set: noise.NoiseSet) -> None:
    # R is built on low-frequency Perlin, so it must vary more slowly than the finest Worley channel.
    assert neighbour_difference(full_set.lf[..., 0]) < neighbour_difference(full_set.lf[..., 3])


def test_perlin_worley_dilates() -> None:
    rng = np.random.default_rng(0)
    p = rng.random(1000, dtype=np.float32)
    w = rng.random(1000, dtype=np.float32)
    pw = noise.perlin_worley(p, w)
    assert np.all(pw >= p - 1e-6)
    assert np.all((pw >= 0) & (pw <= 1))
    np.testing.assert_allclose(noise.perlin_worley(np.ones(3, np.float32), w[:3]), 1.0)


def test_worley_matches_brute_force() -> None:
    size, cells, seed = 8, 2, 11
    vol = noise.tiling_worley_3d(size, cells, seed)
    pts = np.random.default_rng(seed).random((cells, cells, cells, 3), dtype=np.float32)
    feature = []
    for z, y, x in np.ndindex(cells, cells, cells):
        for oz, oy, ox in np.ndindex(3, 3, 3):
            off = (np.array([ox, oy, oz]) - 1) * cells
            feature.append(np.array([x, y, z]) + pts[z, y, x] + off)
    feature = np.array(feature)
    t = (np.arange(size) + 0.5) * cells / size
    zz, yy, xx = np.meshgrid(t, t, t, indexing="ij")
    q = np.stack([xx, yy, zz], axis=-1).reshape(-1, 1, 3)
    ref = np.sqrt(((q - feature[None]) ** 2).sum(-1)).min(1).reshape(size, size, size)
    np.testing.assert_allclose(vol, np.minimum(ref, 1.0), atol=1e-5)


def test_helper_ranges() -> None:
    for a in (
        noise.tiling_perlin_3d(16, 4, 0),
        noise.tiling_worley_3d(16, 4, 0),
        noise.perlin_fbm_3d(16, 2, 7, 0),
        noise.worley_fbm_3d(16, 2, 0),
        noise.tiling_perlin_2d(32, 4, 0),
        noise.perlin_fbm_2d(32, 4, 5, 0),
        noise.worley_fbm_2d(32, 4, 0),
    ):
        assert a.dtype == np.float32
        assert a.min() >= 0.0 and a.max() <= 1.0


def test_block_sizes_must_divide() -> None:
    with pytest.raises(ValueError):
        noise.tiling_worley_3d(10, 4, 0)


def test_curl_helper_is_exactly_divergence_free() -> None:
    potential = noise.perlin_fbm_2d(64, 4, 3, 0, signed=True).astype(np.float64)
    v = noise.curl_2d(potential).astype(np.float64)
    div = central(v[..., 0], 1) + central(v[..., 1], 0)
    assert np.abs(div).max() < 1e-6 * np.abs(v).max()


def test_curl_texture_is_nearly_divergence_free(full_set: noise.NoiseSet) -> None:
    v = full_set.curl[..., :2].astype(np.float32) / 255.0 * 2.0 - 1.0
    vx, vy = v[..., 0], v[..., 1]
    div = central(vx, 1) + central(vy, 0)
    scale = np.abs(central(vx, 1)).mean() + np.abs(central(vy, 0)).mean()
    assert np.abs(div).mean() < 0.05 * scale
    # Control: the same field turned by 90 degrees is a gradient field and strongly divergent.
    gx, gy = -vy, vx
    control = np.abs(central(gx, 1) + central(gy, 0)).mean()
    assert control > 0.3 * (np.abs(central(gx, 1)).mean() + np.abs(central(gy, 0)).mean())
    # Centred encoding: R/G average to 0.5; one shared scale, so the larger component reaches the 8-bit limits.
    assert abs(float(v.mean())) < 0.05
    assert full_set.curl[..., :2].min() <= 1 or full_set.curl[..., :2].max() >= 254


# ---------------------------------------------------------------------------------------------------------------
# mips and memory
# ---------------------------------------------------------------------------------------------------------------


def test_downsample2_box_filter_and_wrap() -> None:
    a = np.arange(4 * 4 * 2, dtype=np.float32).reshape(4, 4, 2)
    d = noise.downsample2(a)
    assert d.shape == (2, 2, 2)
    np.testing.assert_allclose(d[0, 0], a[:2, :2].mean(axis=(0, 1)))
    odd = np.arange(3, dtype=np.float32).reshape(3, 1)
    np.testing.assert_allclose(noise.downsample2(odd)[:, 0], [0.5])
    u8 = np.full((8, 8, 8, 4), 200, np.uint8)
    m = noise.downsample2(u8)
    assert m.dtype == np.uint8 and m.shape == (4, 4, 4, 4) and np.all(m == 200)


def test_mip_chain(full_set: noise.NoiseSet) -> None:
    chain = noise.mip_chain(full_set.hf)
    assert [c.shape[0] for c in chain] == [32, 16, 8, 4, 2, 1]
    assert all(c.dtype == np.uint8 for c in chain)
    assert len(noise.mip_chain(full_set.hf, 3)) == 3
    assert sum(c.nbytes for c in chain) == noise.mip_chain_nbytes(full_set.hf)
    # The mean survives the box filter and a mip of a tiling texture still tiles.
    assert abs(float(chain[2].mean()) - float(full_set.hf.mean())) < 1.0
    curl1 = noise.mip_chain(full_set.curl, 2)[1]
    for axis in range(2):
        assert seam_ratio(curl1[..., 0], axis) <= SEAM_LIMIT


def test_texture_memory_with_mips_is_within_budget(full_set: noise.NoiseSet) -> None:
    # S15: the whole cloud system takes 20 MB; the textures must leave most of it free.
    total = sum(sum(m.nbytes for m in noise.mip_chain(a)) for a in full_set.arrays().values())
    assert total == full_set.nbytes_with_mips
    assert total < 20 * 1000 * 1000
    assert full_set.nbytes < total < 1.2 * full_set.nbytes


# ---------------------------------------------------------------------------------------------------------------
# cache
# ---------------------------------------------------------------------------------------------------------------


@pytest.fixture
def counting_generator(monkeypatch: pytest.MonkeyPatch, full_set: noise.NoiseSet) -> list[int]:
    """Replace generation by the prebuilt set so cache tests stay fast; counts how often it runs."""
    calls: list[int] = []

    def fake(seed: int = 0, **_: int) -> noise.NoiseSet:
        calls.append(seed)
        return noise.NoiseSet(seed=seed, **{k: v.copy() for k, v in full_set.arrays().items()})

    monkeypatch.setattr(noise, "generate_noise_set", fake)
    return calls


def assert_same(a: noise.NoiseSet, b: noise.NoiseSet) -> None:
    assert a.seed == b.seed
    for name in ("lf", "hf", "curl", "cirrus"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_cache_writes_once_and_reloads(tmp_path: Path, counting_generator: list[int], full_set) -> None:
    first = noise.load_or_generate(tmp_path)
    path = tmp_path / noise.cache_file_name(0)
    assert path.name == f"noise_v{noise.NOISE_VERSION}_s0.npz"
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]
    data = path.read_bytes()
    second = noise.load_or_generate(str(tmp_path))
    assert counting_generator == [0]
    assert path.read_bytes() == data  # read, not rewritten (its time is touched: it was used)
    assert_same(first, second)
    assert_same(second, full_set)


def test_cache_is_per_seed(tmp_path: Path, counting_generator: list[int]) -> None:
    noise.load_or_generate(tmp_path, seed=0)
    noise.load_or_generate(tmp_path, seed=5)
    assert counting_generator == [0, 5]
    assert noise.load_or_generate(tmp_path, seed=5).seed == 5
    assert counting_generator == [0, 5]


@pytest.mark.parametrize("damage", ["garbage", "truncate", "flip", "empty"])
def test_corrupt_cache_is_regenerated(tmp_path: Path, counting_generator: list[int], damage: str) -> None:
    good = noise.load_or_generate(tmp_path)
    path = tmp_path / noise.cache_file_name(0)
    data = path.read_bytes()
    if damage == "garbage":
        path.write_bytes(os.urandom(4096))
    elif damage == "truncate":
        path.write_bytes(data[: len(data) // 2])
    elif damage == "flip":
        # Flip bytes inside the LF payload: the zip structure stays valid, only the content is wrong.
        mid = bytearray(data)
        for i in range(len(mid) // 3, len(mid) // 3 + 64):
            mid[i] ^= 0xFF
        path.write_bytes(bytes(mid))
    else:
        path.write_bytes(b"")
    again = noise.load_or_generate(tmp_path)
    assert counting_generator == [0, 0]
    assert_same(good, again)
    # The rewritten file is good again and no temporary files are left.
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]
    noise.load_or_generate(tmp_path)
    assert counting_generator == [0, 0]


def test_wrong_content_is_regenerated(tmp_path: Path, counting_generator: list[int], full_set) -> None:
    path = tmp_path / noise.cache_file_name(0)
    arrays = full_set.arrays()
    np.savez(path, version=np.int64(noise.NOISE_VERSION), seed=np.int64(0), digest=np.array("x"), **arrays)
    noise.load_or_generate(tmp_path)
    assert counting_generator == [0]
    arrays = dict(arrays, hf=np.zeros((16, 16, 16, 3), np.uint8))
    np.savez(path, version=np.int64(noise.NOISE_VERSION), seed=np.int64(0), digest=np.array("x"), **arrays)
    noise.load_or_generate(tmp_path)
    assert counting_generator == [0, 0]


def test_other_version_is_regenerated(tmp_path: Path, counting_generator: list[int], monkeypatch) -> None:
    noise.load_or_generate(tmp_path)
    path = tmp_path / noise.cache_file_name(0)
    # Same file name, but written by another version: the stored version must be checked, not just the name.
    monkeypatch.setattr(noise, "NOISE_VERSION", noise.NOISE_VERSION + 1)
    path.rename(tmp_path / noise.cache_file_name(0))
    noise.load_or_generate(tmp_path)
    assert counting_generator == [0, 0]


def test_unwritable_cache_dir_warns_and_still_returns(tmp_path: Path, counting_generator: list[int]) -> None:
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("x")
    with pytest.warns(RuntimeWarning, match="noise cache"):
        ns = noise.load_or_generate(blocker / "cache")
    assert ns.lf.shape == (128, 128, 128, 4)
    assert counting_generator == [0]
    assert blocker.read_text() == "x"


def test_failed_write_leaves_no_partial_file(tmp_path: Path, counting_generator: list[int], monkeypatch) -> None:
    def broken_savez(f, **arrays):
        f.write(b"PK\x03\x04 half a zip")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(noise, "_savez_fast", broken_savez)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ns = noise.load_or_generate(tmp_path)
    assert ns.seed == 0
    assert any("No space left" in str(w.message) for w in caught)
    assert list(tmp_path.iterdir()) == []


# ---- the compressed, bounded cache -------------------------------------------------------------------------


def test_texel_encoding_round_trips_exactly() -> None:
    rng = np.random.default_rng(3)
    for shape in ((5, 6, 7, 4), (9, 8, 3), (4, 4, 4, 1)):
        a = rng.integers(0, 256, shape, dtype=np.uint8)
        np.testing.assert_array_equal(noise.decode_texels(noise.encode_texels(a)), a)


def test_cache_is_compressed_and_round_trips_bit_identically(tmp_path: Path, full_set) -> None:
    """The real set for seed 0 through the cache: the file is much smaller than the textures, and what
    comes back is the generated set bit for bit."""
    noise._write_cache(tmp_path / noise.cache_file_name(0), full_set)
    size = (tmp_path / noise.cache_file_name(0)).stat().st_size
    assert size < 0.65 * full_set.nbytes, (size, full_set.nbytes)
    back, old_format = noise._read_cache(tmp_path / noise.cache_file_name(0), 0)
    assert back is not None and not old_format
    assert_same(back, full_set)


def test_uncompressed_cache_of_earlier_releases_is_read_and_rewritten_compressed(
    tmp_path: Path, counting_generator: list[int], full_set
) -> None:
    path = tmp_path / noise.cache_file_name(0)
    arrays = full_set.arrays()
    digest = np.array(noise._digest(arrays, 0))
    np.savez(path, version=np.int64(noise.NOISE_VERSION), seed=np.int64(0), digest=digest, **arrays)
    old_size = path.stat().st_size
    assert_same(noise.load_or_generate(tmp_path), full_set)
    assert counting_generator == []  # read, not generated
    assert path.stat().st_size < 0.65 * old_size
    assert_same(noise.load_or_generate(tmp_path), full_set)


def test_dragging_the_seed_through_ten_values_keeps_the_cache_bounded(
    tmp_path: Path, counting_generator: list[int]
) -> None:
    """Ten seeds, as a drag of the Noise Seed slider makes them: at most CACHE_MAX_SEEDS sets and
    CACHE_MAX_BYTES stay, the least recently used go first, and a set in use is kept."""
    for seed in range(10):
        noise.load_or_generate(tmp_path, seed)
        usage = noise.cache_usage(tmp_path)
        assert usage.sets <= noise.CACHE_MAX_SEEDS and usage.nbytes <= noise.CACHE_MAX_BYTES
        if seed == 3:
            os.utime(tmp_path / noise.cache_file_name(0), ns=(0, 0))  # seed 0 unused for ages
            noise.load_or_generate(tmp_path, 1)  # seed 1 used again: recent
    assert counting_generator == list(range(10))
    left = sorted(int(p.stem.split("_s")[1]) for p in tmp_path.glob("noise_*.npz"))
    assert left == [1, 3, 4, 5, 6, 7, 8, 9]  # seed 0 (unused longest), then seed 2 went
    assert noise.cache_usage(tmp_path).sets == noise.CACHE_MAX_SEEDS
    # The byte bound holds too: room for two sets keeps two, the two most recent.
    one = (tmp_path / noise.cache_file_name(9)).stat().st_size
    noise.load_or_generate(tmp_path, 10, max_bytes=int(2.5 * one))
    assert sorted(p.name for p in tmp_path.glob("noise_*.npz")) == [noise.cache_file_name(s) for s in (10, 9)]
    assert noise.cache_usage(tmp_path).nbytes <= 2.5 * one
    assert not list(tmp_path.glob(".*.tmp"))


def test_corrupt_compressed_file_is_refused_cleanly(tmp_path: Path, full_set) -> None:
    """A damaged payload inside an intact zip (the digest catches it), and a cut file, read as "no set":
    the caller regenerates; nothing raises."""
    path = tmp_path / noise.cache_file_name(0)
    noise._write_cache(path, full_set)
    data = bytearray(path.read_bytes())
    for i in range(len(data) // 2, len(data) // 2 + 32):
        data[i] ^= 0x5A
    path.write_bytes(bytes(data))
    assert noise._read_cache(path, 0) == (None, False)
    path.write_bytes(bytes(data[: len(data) // 3]))
    assert noise._read_cache(path, 0) == (None, False)
    assert noise._read_cache(tmp_path / "missing.npz", 0) == (None, False)


def test_clear_cache_empties_it_and_touches_nothing_else(tmp_path: Path, counting_generator: list[int]) -> None:
    for seed in (0, 1):
        noise.load_or_generate(tmp_path, seed)
    (tmp_path / ".noise_v1_s2-k3x_9q0a.tmp").write_bytes(b"left by an interrupted write")
    (tmp_path / "benchmark").mkdir()
    (tmp_path / "notes.txt").write_text("mine")
    before = noise.cache_usage(tmp_path)
    assert before.sets == 2 and before.nbytes > 0
    freed = noise.clear_cache(tmp_path)
    assert (freed.sets, freed.nbytes) == (2, before.nbytes)
    assert noise.cache_usage(tmp_path) == noise.CacheUsage(tmp_path, 0, 0)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["benchmark", "notes.txt"]
    assert noise.clear_cache(tmp_path / "never-made").sets == 0


def test_eviction_and_clearing_never_delete_a_look_alike_file(tmp_path: Path, counting_generator: list[int]) -> None:
    """Only names the cache writes go: a user's study or backup whose name merely looks alike stays, whatever
    the bounds (the probe lost a 70 MB noise_vs_signal_study.npz to the old glob noise_v*_s*.npz)."""
    look_alikes = [
        "noise_vs_signal_study.npz",
        "noise_v1_s0.npz.bak",
        "noise_v1_s0 (copy).npz",
        "noise_v1_s0_old.npz",
        ".noise_v1_s0-mine.tmp",
        "noise_vX_s1.npz",
    ]
    for name in look_alikes:
        (tmp_path / name).write_bytes(b"the user's")
    noise.load_or_generate(tmp_path, 0)
    noise.evict(tmp_path, max_sets=0, max_bytes=0)
    assert noise.cache_usage(tmp_path).sets == 0
    noise.load_or_generate(tmp_path, 1)
    assert noise.clear_cache(tmp_path).sets == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(look_alikes)


def test_fbm_mean_weights_the_first_three_channels():
    tex = np.zeros((4, 4, 4, 4), np.uint8)
    tex[..., 0] = 255
    tex[..., 3] = 255  # the fourth channel is not part of the fBm
    assert noise.fbm_mean(tex) == pytest.approx(noise.FBM_WEIGHTS[0])
    tex[..., 1:3] = 255
    assert noise.fbm_mean(tex) == pytest.approx(1.0)
