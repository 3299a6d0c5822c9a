"""core/storms.py: superstorm stencils rasterised into the data fields (GDC22). No Blender."""

import math

import numpy as np
import pytest

from nubis_addon.core import fields
from nubis_addon.core.presets import load_preset
from nubis_addon.core.schema import defaults
from nubis_addon.core.storms import Storm, apply_storms, lifecycle_keys, storm_weight

RES = 256


def _params(res=RES):
    p = defaults()
    p.update(field_resolution=res, field_size=70000.0, field_origin_x=0.0, field_origin_y=0.0)
    return p


@pytest.fixture(scope="module")
def sky():
    """A varied cloudscape (the default preset), so that 'unchanged' means something."""
    preset = load_preset("default")
    return fields.composite(preset.layers, dict(preset.params, **_params()))


def _copy(f):
    return {k: v.copy() for k, v in f.items()}


def _dist(params, storm, centre=None):
    xs, ys = fields.pixel_centres(params)
    cx, cy = centre or (storm.x, storm.y)
    return np.hypot(xs - cx, ys - cy)


STORM_A = Storm(x=-9000.0, y=-6000.0, radius=12000.0, seed=1, wind_x=1.0, wind_y=0.3)
STORM_B = Storm(x=6000.0, y=5000.0, radius=9000.0, seed=2, height=2.6, wind_x=1.0, wind_y=0.3)  # overlaps A


@pytest.mark.parametrize("storms", [[STORM_A], [STORM_A, STORM_B]], ids=["one", "two"])
def test_outside_every_radius_is_bit_identical(sky, storms):
    params = _params()
    out = _copy(sky)
    apply_storms(out, params, storms)
    outside = np.ones((RES, RES), bool)
    for s in storms:
        outside &= _dist(params, s) >= s.radius
    assert outside.sum() > RES * RES // 2
    for key in ("a", "b"):
        for ch in range(4):
            np.testing.assert_array_equal(out[key][..., ch][outside], sky[key][..., ch][outside], err_msg=f"{key}{ch}")
        assert not np.array_equal(out[key], sky[key])  # and inside something did change
    # The anvil reaches beyond the radius, but only in the cirrus image and only up to reach().
    far = np.ones((RES, RES), bool)
    for s in storms:
        far &= _dist(params, s) >= s.reach()
    assert far.any()
    for ch in range(4):
        np.testing.assert_array_equal(out["cirrus"][..., ch][far], sky["cirrus"][..., ch][far])
    assert not np.array_equal(out["cirrus"], sky["cirrus"])


def test_blend_zero_and_no_storms_leave_fields_bit_identical(sky):
    for storms in ([], [Storm(x=0.0, y=0.0, radius=15000.0, blend=0.0)]):
        out = _copy(sky)
        apply_storms(out, _params(), storms)
        for key in sky:
            np.testing.assert_array_equal(out[key], sky[key])


def test_centre_is_a_towering_cumulonimbus(sky):
    params = _params()
    storm = Storm(x=0.0, y=0.0, radius=12000.0, coverage=0.95, height=3.2, seed=3)
    out = _copy(sky)
    apply_storms(out, params, [storm])
    core = _dist(params, storm) < 0.08 * storm.radius
    assert core.sum() >= 4
    assert out["a"][..., 0][core].min() >= 0.9 * storm.coverage
    assert out["a"][..., 2][core] == pytest.approx(1.0, abs=1e-6)  # top type -> cumulonimbus
    assert out["b"][..., 2][core].min() >= 0.9 * storm.height  # the raised top
    assert out["b"][..., 0][core].min() == pytest.approx(1.0)  # storm coverage = weight x blend
    # ragged underside: bottom type raised towards the storm's
    assert out["a"][..., 3][core].min() >= 0.8 * storm.bottom_type
    # GDC22's variable heights: the foot is lowered by `base`, mostly flat near the centre, never below the ground
    foot = _dist(params, storm) < 0.4 * storm.radius
    mins = out["b"][..., 1][foot]
    assert mins.mean() == pytest.approx(storm.base - 0.03, abs=0.06)
    assert mins.std() < 0.06
    assert out["b"][..., 1].min() >= -params["layer_bottom"] / (params["layer_top"] - params["layer_bottom"])
    assert np.all(out["b"][..., 2] >= out["b"][..., 1] + 0.0099)


def test_blend_scales_the_storm(sky):
    params = _params()
    half = _copy(sky)
    apply_storms(half, params, [Storm(x=0.0, y=0.0, radius=12000.0, blend=0.5)])
    full = _copy(sky)
    apply_storms(full, params, [Storm(x=0.0, y=0.0, radius=12000.0, blend=1.0)])
    core = _dist(params, Storm(x=0.0, y=0.0, radius=1.0)) < 1000.0
    assert half["b"][..., 0][core] == pytest.approx(0.5)
    assert np.all(sky["b"][..., 2][core] < half["b"][..., 2][core])
    assert np.all(half["b"][..., 2][core] < full["b"][..., 2][core])


def test_radial_profile_rises_towards_the_centre():
    """'increase cloud coverage and type radially toward a point' (GDC22): ring averages (over three
    seeds) rise towards the centre, give or take the brim's noise."""
    params = _params()
    rings = {}
    for seed in (5, 6, 7):
        base = fields.base_fields(RES)  # clear sky: the storm's own profile
        storm = Storm(x=0.0, y=0.0, radius=20000.0, seed=seed)
        apply_storms(base, params, [storm])
        r = _dist(params, storm) / storm.radius
        edges = np.linspace(0.0, 1.0, 11)
        for key, ch in (("a", 0), ("a", 2), ("b", 2), ("b", 0)):
            plane = base[key][..., ch]
            ring = [plane[(r >= lo) & (r < hi)].mean() for lo, hi in zip(edges[:-1], edges[1:], strict=True)]
            rings[key, ch] = rings.get((key, ch), 0.0) + np.array(ring) / 3.0
        # the footprint is not a plain disc: coverage varies around the rings of the brim (twisted noise)
        brim = (r > 0.5) & (r < 0.7)
        assert base["a"][..., 0][brim].std() > 0.05
    for (key, ch), ring in rings.items():
        assert np.all(np.diff(ring) < 0.05), (key, ch, ring)
        assert ring[0] > ring[-1] + 0.3, (key, ch, ring)
    assert rings["b", 2][0] > 0.9 * 3.2


def test_storm_coverage_is_the_radial_weight():
    params = _params()
    base = fields.base_fields(RES)
    storm = Storm(x=1000.0, y=-2000.0, radius=15000.0, blend=0.8)
    apply_storms(base, params, [storm])
    d = _dist(params, storm)
    np.testing.assert_allclose(base["b"][..., 0], storm_weight(d, storm.radius) * 0.8, atol=1e-6)


def test_smooth_fade_at_the_radius():
    """No seam (GDC22: the transition from cloud to superstorm is seamless): near the radius the storm's
    own contribution changes by little between neighbouring pixels, and by almost nothing at the rim."""
    params = _params(512)
    preset = load_preset("default")
    f = fields.composite(preset.layers, dict(preset.params, **params))
    out = _copy(f)
    storm = Storm(x=0.0, y=0.0, radius=15000.0, seed=4)
    apply_storms(out, params, [storm])
    r = _dist(params, storm) / storm.radius
    for key in ("a", "b"):
        for ch in range(4):
            delta = out[key][..., ch].astype(np.float64) - f[key][..., ch]  # the storm's own contribution
            for (lo, hi), limit in (((0.85, 1.05), 0.05), ((0.95, 1.05), 0.015)):
                band = (r > lo) & (r < hi)
                jump = max(
                    np.abs(np.diff(delta, axis=0))[band[1:]].max(), np.abs(np.diff(delta, axis=1))[band[:, 1:]].max()
                )
                assert jump < limit, (key, ch, lo, jump)
    # the anvil fades out too, before its reach
    ra = _dist(params, storm, storm.anvil_centre()) / storm.anvil_radius()
    delta = out["cirrus"][..., 0].astype(np.float64) - f["cirrus"][..., 0]
    rim = (ra > 0.95) & (ra < 1.05)
    assert np.abs(np.diff(delta, axis=1))[rim[:, 1:]].max() < 0.02


def test_two_storms_are_order_independent(sky):
    params = _params()
    ab, ba = _copy(sky), _copy(sky)
    apply_storms(ab, params, [STORM_A, STORM_B])
    apply_storms(ba, params, [STORM_B, STORM_A])
    for key in sky:
        np.testing.assert_array_equal(ab[key], ba[key])
    # both storms are there: each centre is a tower
    for s in (STORM_A, STORM_B):
        c = _dist(params, s) < 0.05 * s.radius
        assert ab["b"][..., 2][c].min() > 0.9 * s.height


def test_anvil_is_downwind_in_the_cirrus_layer(sky):
    params = _params()
    storm = Storm(x=-5000.0, y=0.0, radius=10000.0, wind_x=0.0, wind_y=2.0, seed=7)  # wind normalised
    out = _copy(sky)
    apply_storms(out, params, [storm])
    assert storm.anvil_centre() == pytest.approx((-5000.0, 10000.0))
    at_anvil = _dist(params, storm, storm.anvil_centre()) < 0.3 * storm.anvil_radius()
    assert out["cirrus"][..., 0][at_anvil].mean() > 0.75
    upwind = _dist(params, storm, (-5000.0, -14000.0)) < 2000.0
    np.testing.assert_array_equal(out["cirrus"][upwind], sky["cirrus"][upwind])
    # the anvil reaches beyond the storm's radius, yet "a" and "b" stay untouched out there
    beyond = (_dist(params, storm) >= storm.radius) & at_anvil
    assert beyond.any()
    np.testing.assert_array_equal(out["a"][beyond], sky["a"][beyond])
    np.testing.assert_array_equal(out["b"][beyond], sky["b"][beyond])


def test_deterministic_for_a_seed(sky):
    params = _params()
    runs = []
    for seed in (11, 11, 12):
        out = _copy(sky)
        apply_storms(out, params, [Storm(x=0.0, y=0.0, radius=12000.0, seed=seed)])
        runs.append(out)
    for key in sky:
        np.testing.assert_array_equal(runs[0][key], runs[1][key])
    assert not np.array_equal(runs[0]["a"], runs[2]["a"])


def test_storm_at_the_field_edge_and_outside():
    params = _params(64)
    f = fields.base_fields(64)
    apply_storms(f, params, [Storm(x=34000.0, y=-34000.0, radius=8000.0), Storm(x=1e6, y=0.0, radius=5000.0)])
    assert np.all(np.isfinite(f["a"])) and f["b"][..., 0].max() > 0.5


def test_lifecycle_keys():
    keys = lifecycle_keys(10, 24.0)
    assert keys[0] == (10, 0.0)
    assert keys[1] == (10 + 120 * 24, 1.0)  # ramps in over 2 minutes (GDC22)
    assert keys[2] == (10 + 300 * 24, 1.0)  # holds
    assert keys[3] == (10 + 420 * 24, 0.0)  # dissipates over 2 minutes
    frames = [k[0] for k in lifecycle_keys(0, 30.0, 60.0, 0.0, 30.0)]
    assert frames == [0, 1800, 1800, 2700]


def test_lightning_sequence_rises_then_discharges():
    from nubis_addon.core.storms import lightning_keys

    keys = lightning_keys(100, 24.0, flashes=4, discharges=2, peak=50.0, seed=3)
    peaks = [k for k in keys if k["flash"] > 0 and keys[keys.index(k) - 1]["flash"] == 0]
    assert [k["ground"] for k in peaks] == [0, 0, 0, 0, 1, 1]  # intra-cloud first, then ground
    ic = [k["flash"] for k in peaks[:4]]
    assert ic == sorted(ic) and ic[0] < ic[-1] < 50.0  # each intra-cloud flash brighter than the last
    assert all(k["flash"] == 50.0 for k in peaks[4:])
    assert len({(round(k["x"], 6), round(k["y"], 6)) for k in peaks}) == 6  # every flash somewhere new
    assert all(math.hypot(k["x"], k["y"]) <= 0.5 for k in keys)
    frames = [k["frame"] for k in keys]
    assert frames == sorted(frames) and frames[0] == 99
    assert keys == lightning_keys(100, 24.0, flashes=4, discharges=2, peak=50.0, seed=3)


def test_lightning_positions_are_set_before_each_flash():
    """The viewport builds each flash's mask over 16 redraws before it fires (GDC22), so every flash's
    position is keyed at least that long before its light (or right after the previous flash)."""
    from nubis_addon.core.storms import FLASH_MASK_LEAD, lightning_keys, lightning_position_keys

    keys = lightning_keys(100, 24.0, flashes=4, discharges=2, seed=3)
    where = lightning_position_keys(keys)
    assert len(where) == 6
    lit = [k for k in keys if k["flash"] > 0]
    first_light = {}
    for k in lit:
        first_light.setdefault((k["x"], k["y"]), k["frame"])
    for w in where:
        assert w["frame"] <= first_light[(w["x"], w["y"])] - 1
    assert where[0]["frame"] == keys[0]["frame"] - FLASH_MASK_LEAD
    for before, after in zip(where, where[1:], strict=False):
        gap = first_light[(after["x"], after["y"])] - after["frame"]
        assert gap >= 10  # the pauses between flashes are 0.4-1.5 s at 24 fps
        # No flash is still lit at a position key of the next one.
        assert all(k["frame"] < after["frame"] for k in lit if (k["x"], k["y"]) == (before["x"], before["y"]))


def test_vortex_time_integrates_the_lifecycle_fade():
    from nubis_addon.core.storms import vortex_fade, vortex_time

    assert float(vortex_fade(0.0)) == 0.0 and float(vortex_fade(0.25)) == 1.0 and float(vortex_fade(1.0)) == 1.0
    t = np.linspace(0.0, 10.0, 11)
    # A steady storm: the vortex time is the time itself, scaled by the fade.
    assert vortex_time(t, np.full(11, 1.0), 7.5) == pytest.approx(7.5)
    assert vortex_time(t, np.full(11, 0.1), 7.5) == pytest.approx(7.5 * float(vortex_fade(0.1)))
    # Growing in from nothing: it never runs faster than time, and starts at zero.
    ramp = np.clip(t / 10.0, 0.0, 1.0)
    taus = [vortex_time(t, ramp, x) for x in np.linspace(0.0, 10.0, 41)]
    assert taus[0] == 0.0
    assert all(0.0 <= b - a <= 0.25 + 1e-9 for a, b in zip(taus, taus[1:], strict=False))
