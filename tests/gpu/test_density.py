"""The cloud density on the GPU: the shader against the numpy oracle, and the density's
contract (GPU Pro 7, GDC22; docs/sources.md) checked on GPU read-backs.

The GPU side is the probe stage (tests/gpu_probe.py), which runs the very `nubis_density` the viewport,
the render and the bake call. The oracle (tests/oracle.py) is an independent port fed the same state.
"""

import numpy as np
import pytest
from oracle import DensityOracle, padded_texture, remap, sample_linear

# The viewport and the VDB bake share the density; 1e-3 is far below anything visible
# (the default extinction 0.1 / m turns it into 1e-4 / m) yet catches any formula or constant slip.
TOLERANCE = 1e-3

_noise_sets: dict[int, object] = {}
_sampler_unorm8: dict[int, bool] = {}


def _inputs(scene):
    """(CloudGPU updated to the scene, its CloudState, the NoiseSet behind the GPU textures)."""
    from nubis_addon.blender.host import runtime
    from nubis_addon.blender.scene import cloudstate
    from nubis_addon.core import noise

    seed = scene.nubis.noise_seed
    state = cloudstate.state_from_scene(scene)
    clouds = runtime.cloud_gpu(seed)
    clouds.update(state, light=False)  # densities only
    if seed not in _noise_sets:
        # Already generated and cached by cloud_gpu: this is a load of the very arrays on the GPU.
        _noise_sets[seed] = noise.load_or_generate(runtime.cache_dir(), seed)
    return clouds, state, _noise_sets[seed]


def _measure_sampler(clouds, noise_set) -> dict[str, tuple[float, float]]:
    """Max |GPU - oracle| of raw noise reads under the GL float filter and the 8-bit fixed-point filter."""
    from gpu_probe import probe_noise

    rng = np.random.default_rng(11)
    out = {}
    for which, dims in (("lf", 3), ("hf", 3), ("curl", 2)):
        tex = padded_texture(getattr(noise_set, which), dims)
        # Spans a little beyond [0, 1] so clamp-to-edge is exercised too.
        coords = rng.uniform(-0.02, 1.02, (20000, dims)).astype(np.float32)
        got = probe_noise(clouds, which, coords)[:, : tex.shape[-1]]
        out[which] = tuple(float(np.abs(got - sample_linear(tex, coords, unorm8=u8)).max()) for u8 in (False, True))
    return out


def _oracle(clouds, state, noise_set) -> DensityOracle:
    """The oracle with the filter model of this GPU: the one that reproduces its raw noise reads."""
    seed = noise_set.seed
    if seed not in _sampler_unorm8:
        errors = _measure_sampler(clouds, noise_set)
        float_err = max(e[0] for e in errors.values())
        fixed_err = max(e[1] for e in errors.values())
        _sampler_unorm8[seed] = fixed_err < float_err
    return DensityOracle(state, noise_set, unorm8_filter=_sampler_unorm8[seed])


def _layer_points(rng, n: int, state, radius: float = 36000.0) -> np.ndarray:
    """Uniform points in the cloud layer over a disc around the camera reaching past the draw radius."""
    p = state.params
    r = radius * np.sqrt(rng.uniform(0.0, 1.0, n))
    a = rng.uniform(0.0, 2.0 * np.pi, n)
    cx, cy = state.draw_center
    z = rng.uniform(p["layer_bottom"], p["layer_top"], n)
    return np.stack([cx + r * np.cos(a), cy + r * np.sin(a), z], axis=1).astype(np.float32)


def _cloudy_points(rng, n: int, state, oracle: DensityOracle) -> np.ndarray:
    """Points where the oracle's fine density is positive: uniform points are mostly clear sky."""
    pool = _layer_points(rng, 40 * n, state, radius=30000.0)
    cloudy = pool[oracle.density(pool)[:, 0] > 0.0]
    assert len(cloudy) >= n, f"only {len(cloudy)} cloudy points among {len(pool)}"
    return cloudy[:n]


def _grid(state, step: float = 200.0, half: float = 20000.0, levels: int = 12):
    """A regular grid of columns around the camera, `levels` heights inside the layer: (points, shape)."""
    p = state.params
    cx, cy = state.draw_center
    xs = cx - half + step * (np.arange(int(2 * half / step)) + 0.5)
    ys = cy - half + step * (np.arange(int(2 * half / step)) + 0.5)
    zs = np.linspace(p["layer_bottom"], p["layer_top"], levels + 2)[1:-1]
    x, y, z = np.meshgrid(xs, ys, zs, indexing="ij")
    return np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1).astype(np.float32), (len(xs), len(ys), levels)


def _compare(clouds, state, noise_set, points) -> tuple[np.ndarray, np.ndarray]:
    from gpu_probe import probe_density

    got = probe_density(clouds, points)
    want = _oracle(clouds, state, noise_set).density(points)
    diff = np.abs(got - want)
    print(f"max |GPU - oracle|: fine {diff[:, 0].max():.3g}, coarse {diff[:, 1].max():.3g}, h {diff[:, 2].max():.3g}")
    assert diff[:, 0].max() <= TOLERANCE, diff[:, 0].max()
    assert diff[:, 1].max() <= TOLERANCE, diff[:, 1].max()
    assert diff[:, 2].max() <= 1e-5, diff[:, 2].max()
    return got, want


# ---- the oracle itself ------------------------------------------------------------------------------


def test_oracle_sampler_reproduces_the_gpu_filter(make_scene):
    """The oracle's texture reads are the GPU's: otherwise a density mismatch could hide in filtering."""
    clouds, _state, noise_set = _inputs(make_scene("default"))
    errors = _measure_sampler(clouds, noise_set)
    print("raw noise |GPU - oracle| (GL float filter, 8-bit filter):", errors)
    best = {which: min(e) for which, e in errors.items()}
    # One 8-bit step is 1/255 = 3.9e-3: a model that is off by less than a quarter step reproduces the
    # sampler (Mesa llvmpipe filters 8-bit textures in 8 bits and matches the fixed-point model exactly).
    assert max(best.values()) < 1e-3, errors
    # Both texel-centre conventions agree on the texel values themselves: any misplaced centre, flipped
    # axis or missing wrap texel would be off by whole texel differences (tens of 8-bit steps).
    assert max(max(e) for e in errors.values()) < 8.0 / 255.0, errors


# ---- GPU against the oracle --------------------------------------------------------------------------


def test_remap_on_gpu_and_in_oracle(make_scene):
    from gpu_probe import probe_remap

    clouds, _state, _noise = _inputs(make_scene("default"))
    # GPU Pro 7's remap: a worked example, and the function is unclamped; the shader maps an empty input
    # range to new_min rather than dividing by zero.
    cases = np.array(
        [
            [0.5, 0.2, 1.0, 0.0, 1.0],  # 0.375
            [1.5, 0.2, 1.0, 0.0, 1.0],  # above the range: 1.625, not 1
            [-0.3, 0.2, 1.0, 0.0, 1.0],  # below: -0.625, not 0
            [0.5, 1.0, 0.2, 0.0, 1.0],  # a reversed range: 0.625
            [0.7, 0.4, 0.4, 0.25, 1.0],  # empty range: new_min
        ]
    )
    expected = np.array([0.375, 1.625, -0.625, 0.625, 0.25])
    assert remap(0.5, 0.2, 1, 0, 1) == pytest.approx(0.375, abs=1e-12)
    np.testing.assert_allclose(remap(*cases.T), expected, atol=1e-12)
    np.testing.assert_allclose(probe_remap(clouds, cases), expected, atol=1e-6)

    rng = np.random.default_rng(3)
    args = rng.uniform(-2.0, 2.0, (4096, 5))
    args[:, 2] = args[:, 1] + rng.choice([-1, 1], 4096) * rng.uniform(0.1, 2.0, 4096)  # spans >= 0.1
    args[:, 4] = 1.0
    args = args.astype(np.float32)
    np.testing.assert_allclose(probe_remap(clouds, args), remap(*args.astype(np.float64).T), atol=1e-4)


def test_gpu_density_matches_oracle(make_scene):
    """>= 2000 points: half uniform in the layer (mostly clear sky, the draw-radius fade), half cloudy."""
    scene = make_scene("default")
    clouds, state, noise_set = _inputs(scene)
    oracle = _oracle(clouds, state, noise_set)
    rng = np.random.default_rng(1)
    points = np.concatenate([_layer_points(rng, 1500, state), _cloudy_points(rng, 1500, state, oracle)])
    got, want = _compare(clouds, state, noise_set, points)
    assert (got[:, 0] > 0).mean() > 0.4  # the comparison is not won by agreeing on zeros
    assert (got[:, 1] > 0).mean() > 0.5
    assert got[:, 0].max() > 0.2
    # The 8-bit filter model only accounts for rounding: the plain GL float filter is within a few steps.
    plain = DensityOracle(state, noise_set, unorm8_filter=False).density(points)
    assert np.abs(got[:, :2] - plain[:, :2]).max() < 1e-2


def test_gpu_density_matches_oracle_in_wind(make_scene):
    """Frame 200 with a gale from an oblique heading: skew, drift, upward bias and the faster detail noise."""
    scene = make_scene("default", wind_speed=300.0, wind_direction=0.7)
    scene.frame_set(200)
    clouds, state, noise_set = _inputs(scene)
    assert state.time > 8.0
    assert state.params["wind_speed"] * state.time > 2000.0  # metres of drift: a quarter of the shape noise tile
    oracle = _oracle(clouds, state, noise_set)
    rng = np.random.default_rng(2)
    points = np.concatenate([_layer_points(rng, 1000, state), _cloudy_points(rng, 1500, state, oracle)])
    got, _want = _compare(clouds, state, noise_set, points)
    assert (got[:, 0] > 0).mean() > 0.4
    # The wind really moved the noise: at time 0 the same points hold other densities.
    state.time = 0.0
    still = DensityOracle(state, noise_set, unorm8_filter=oracle.unorm8).density(points)
    assert np.abs(got[:, 0] - still[:, 0]).mean() > 0.5 * got[:, 0].mean()


# ---- the density's contract, on the GPU ------------------------------------------------------------


def test_coarse_bounds_fine(make_scene):
    """GPU Pro 7, S15: erosion only removes density, so fine <= coarse and coarse == 0 => fine == 0; this is
    what makes skipping empty space on the coarse sample exact."""
    from gpu_probe import probe_density

    scene = make_scene("default")
    clouds, state, _noise = _inputs(scene)
    points, _shape = _grid(state)
    rng = np.random.default_rng(4)
    points = np.concatenate([points, _layer_points(rng, 100000, state)])
    d = probe_density(clouds, points)
    fine, coarse = d[:, 0], d[:, 1]
    assert (fine > 0).sum() > 10000  # many cloudy points, not an empty sky
    assert (fine < coarse - 1e-3).sum() > 1000  # the erosion is active, so the bound is not trivially equal
    assert np.all(fine <= coarse + 1e-6), np.max(fine - coarse)  # float32 rounding only
    assert np.all(fine[coarse == 0.0] == 0.0)


def test_a_cheap_sample_erodes_by_the_detail_mean(make_scene):
    """The light's cheap samples skip the detail fetch. Uneroded they made the light darker than full samples
    (docs/viewport.md#light-model); eroded by the detail noise's mean they keep the bound fine <= coarse and
    remove on average what the full sample removes."""
    from gpu_probe import probe_density

    scene = make_scene("default")
    clouds, state, _noise = _inputs(scene)
    points = _layer_points(np.random.default_rng(5), 100000, state)
    full = probe_density(clouds, points)
    cheap = probe_density(clouds, points, cheap=True)
    np.testing.assert_array_equal(cheap[:, 1], full[:, 1])  # the same base shape
    assert np.all(cheap[:, 0] <= cheap[:, 1] + 1e-6)
    cloudy = full[:, 1] > 0.0
    assert cloudy.sum() > 10000
    removed_full = (full[cloudy, 1] - full[cloudy, 0]).sum()
    removed_cheap = (cheap[cloudy, 1] - cheap[cloudy, 0]).sum()
    # Measured 2026-12-02 (5.3, llvmpipe): the means within a few per cent; uneroded, the cheap sample
    # removed nothing.
    assert abs(removed_cheap / removed_full - 1.0) < 0.15, (removed_cheap, removed_full)
    assert abs(cheap[cloudy, 0].mean() / full[cloudy, 0].mean() - 1.0) < 0.1


def test_zero_coverage_gives_no_density(make_scene):
    from gpu_probe import probe_density

    from nubis_addon.blender.scene import datafield

    scene = make_scene("default")
    clouds, state, _noise = _inputs(scene)
    rng = np.random.default_rng(5)
    points = _layer_points(rng, 50000, state)
    before = probe_density(clouds, points)
    assert (before[:, 1] > 0).sum() > 1000  # the same points are cloudy with the preset's coverage

    field_a = state.field_a.copy()
    field_a[..., 0] = 0.0
    datafield.write_field_image(scene.nubis, "a", field_a)
    clouds, state, _noise = _inputs(scene)
    assert float(state.field_a[..., 0].max()) == 0.0
    after = probe_density(clouds, points)
    assert np.all(after[:, :2] == 0.0)
    np.testing.assert_allclose(after[:, 2], before[:, 2], atol=1e-6)  # h does not depend on coverage


def test_density_never_falls_as_coverage_rises(make_scene):
    """GDC22: raising coverage inflates the clouds; nothing may thin out anywhere."""
    from gpu_probe import probe_density

    from nubis_addon.blender.scene import datafield

    scene = make_scene("default")
    clouds, state, _noise = _inputs(scene)
    rng = np.random.default_rng(6)
    points = _layer_points(rng, 40000, state)
    field_a = state.field_a.copy()  # precipitation, top and bottom type stay as the preset made them
    results = []
    for c in (0.2, 0.4, 0.6, 0.8, 1.0):
        field_a[..., 0] = c
        datafield.write_field_image(scene.nubis, "a", field_a)
        clouds, state, _noise = _inputs(scene)
        results.append(probe_density(clouds, points))
    for lower, higher in zip(results, results[1:], strict=False):
        # Exact arithmetic is monotonic (clamp(base - 1 + c, 0, c) then an increasing erosion remap);
        # 1e-6 leaves room for float32 rounding only.
        assert np.all(higher[:, 0] >= lower[:, 0] - 1e-6), np.min(higher[:, 0] - lower[:, 0])
        assert np.all(higher[:, 1] >= lower[:, 1] - 1e-6), np.min(higher[:, 1] - lower[:, 1])
        # ... and coverage does matter: every step adds cloud.
        assert (higher[:, 0] > 0).sum() > (lower[:, 0] > 0).sum()
        assert higher[:, 0].mean() > lower[:, 0].mean() + 1e-3


def test_time_moves_detail_but_keeps_structure(make_scene):
    """GDC22: the noise is animated, the coverage/type field is not, so a minute of
    wind reshapes the clouds in place: the detail changes, the cloudscape's layout does not."""
    from gpu_probe import probe_density

    from nubis_addon.blender.scene import datafield

    scene = make_scene("default")  # 10 m/s: in 60 s the shape noise moves 600 m, the detail 1200 m
    clouds, state, noise_set = _inputs(scene)
    points, shape = _grid(state)  # 200 m columns over 40 km, 12 heights

    def fine_at(offset: float) -> tuple[np.ndarray, float]:
        scene.nubis.wind_time_offset = offset
        gpu_inputs, st, _n = _inputs(scene)
        return probe_density(gpu_inputs, points)[:, 0].reshape(shape), st.time

    now, t0 = fine_at(0.0)
    later, t1 = fine_at(60.0)
    assert t1 - t0 == pytest.approx(60.0)

    def corr(a, b) -> float:
        return float(np.corrcoef(a.ravel(), b.ravel())[0, 1])

    def blocks(f: np.ndarray, k: int = 10) -> np.ndarray:
        # Column-integrated density averaged over k x k columns: 10 x 200 m = 2 km, the scale of the
        # smallest structure the coverage field was painted with (14 km Perlin, 5 octaves).
        col = f.sum(axis=2)
        nx, ny = col.shape
        return col[: nx // k * k, : ny // k * k].reshape(nx // k, k, ny // k, k).mean(axis=(1, 3))

    assert (now > 0).mean() > 0.03  # a cloudy sky to compare, not an empty one
    # The detail moved: a point's density changes by about its own size on average (measured ~1.05x)
    # and per-point correlation drops (measured ~0.63).
    assert np.abs(later - now).mean() > 0.5 * now.mean()
    point_corr = corr(now, later)
    assert point_corr < 0.8, point_corr
    # The large structure stayed (measured ~0.94 at 2 km).
    block_now, block_later = blocks(now), blocks(later)
    block_corr = corr(block_now, block_later)
    assert block_corr > 0.85, block_corr
    assert block_corr > point_corr + 0.1
    # Control: the same 2 km statistic does tell cloudscapes apart; the cloudscape against itself moved
    # 6 km sideways (three blocks) correlates far less (measured ~0.0-0.3).
    shifted = max(corr(block_now[:-3], block_now[3:]), corr(block_now[:, :-3], block_now[:, 3:]))
    assert shifted < 0.5, shifted
    # The field itself never drifts (GDC22): clear a 6 km band across the wind of the coverage field; were
    # the field blown along with the noise, cloud would enter the band's upwind edge within the minute.
    # (Where the preset leaves it, coverage is nowhere exactly 0, so the band is needed to see an edge.)
    field_a = state.field_a.copy()
    res = field_a.shape[1]
    x_texel = state.params["field_origin_x"] + (np.arange(res) + 0.5 - res / 2) * state.params["field_size"] / res
    field_a[:, np.abs(x_texel - state.draw_center[0]) < 3000.0, 0] = 0.0
    datafield.write_field_image(scene.nubis, "a", field_a)
    banded_now, _t = fine_at(0.0)
    banded_later, _t = fine_at(60.0)
    _clouds, banded_state, _n = _inputs(scene)
    cover = DensityOracle(banded_state, noise_set).coverage(points[:, :2].astype(np.float64)).reshape(shape)
    band = cover == 0.0
    assert 0.1 < band.mean() < 0.25
    assert np.all(banded_now[band] == 0.0) and np.all(banded_later[band] == 0.0)
    # ... and the band has cloud right up to its edges, so an edge that moved would have been seen.
    dist_x = np.abs(points[:, 0].reshape(shape) - state.draw_center[0])
    rim = (dist_x > 3200.0) & (dist_x < 4000.0)
    assert (banded_now[rim] > 0).sum() > 100 and (banded_later[rim] > 0).sum() > 100
