"""core/paint.py's bounds on a stroke and a dab, with the sentences they print (docs/painting.md#what-is-refused):
a stroke to 1e12 m or to Blender's infinity, radii a float32 cannot hold, a preset's dabs checked as the
brush is, and the notice before a long composite. No Blender; milliseconds."""

from __future__ import annotations

import math
import resource
import time

import numpy as np
import pytest

from nubis_addon.core import paint, paintraster, presets
from nubis_addon.core.errors import NubisError

GRID = paint.Grid(512, 70000.0, 0.0, 0.0)  # the default field: 136.7 m pixels
FLT_MAX = float(np.finfo(np.float32).max)  # what Blender stores for an infinite float property
OUTSIDE = (
    "the stroke lies outside the data field (x -35000 to 35000 m, y -35000 to 35000 m): paint over the field, "
    "or move or enlarge it (Field > Origin, Size)"
)


def refused(call) -> str:
    with pytest.raises(NubisError) as info:
        call()
    return str(info.value)


# ---- defect 1: a stroke far outside the field ------------------------------------------------------------


@pytest.mark.parametrize("far", [1e12, FLT_MAX * 0.85, -1e20])
def test_a_stroke_to_far_away_lays_only_its_part_over_the_field(far):
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    start = time.perf_counter()
    dabs = paint.stroke_dabs([(0.0, 0.0, 1.0, True), (far, 0.0, 1.0, False)], 2500.0, 1.0, grid=GRID)
    assert time.perf_counter() - start < 1.0
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before < 50_000  # kB: no allocation to speak of
    reach = 35000.0 + 2500.0  # the field's half width and the radius: a dab out there still touches it
    assert np.all(np.abs(dabs[:, 0]) <= reach) and np.all(dabs[:, 1] == 0.0)
    assert len(dabs) == round(reach / 500.0) + 1  # SPACING radii apart, from the start to the field's edge
    np.testing.assert_allclose(np.abs(np.diff(dabs[:, 0])), 500.0)
    assert dabs[0, 6] == 1 and not dabs[1:, 6].any()


def test_a_stroke_from_far_away_starts_where_it_meets_the_field_and_a_crossing_is_laid_exactly():
    dabs = paint.stroke_dabs([(-1e12, 0.0, 1.0, True), (0.0, 0.0, 1.0, False)], 2500.0, 1.0, grid=GRID)
    assert dabs[0, 6] == 1 and not dabs[1:, 6].any()  # the first dab laid starts the stroke
    assert -37500.0 <= dabs[0, 0] < -37000.0 and dabs[-1, 0] == pytest.approx(0.0, abs=500.0)
    # Across the field between two points of float32's largest (Blender's infinity is refused before;
    # these are just short of it): exact arithmetic places the crossing on the line, not kilometres off.
    big = FLT_MAX * 0.85
    diag = paint.stroke_dabs([(-big, -big, 1.0, True), (big, big, 1.0, False)], 2500.0, 1.0, grid=GRID)
    assert len(diag) == pytest.approx(2 * 37500.0 * math.sqrt(2) / 500.0, abs=2)
    np.testing.assert_array_equal(diag[:, 0], diag[:, 1])
    # Laid point by point (a live drag) the dabs are the same.
    points = [(0.0, 0.0, 0.5, True), (3000.0, 0.0, 1.0, False), (1e12, 0.0, 1.0, False), (5000.0, 5000.0, 1.0, False)]
    spacer = paint.Spacer(1000.0, 0.5, grid=GRID)
    live = np.concatenate([spacer.add(*p) for p in points])
    np.testing.assert_allclose(live, paint.stroke_dabs(points, 1000.0, 0.5, grid=GRID))


def test_a_stroke_with_no_part_over_the_field_is_refused():
    for points in ([(1e6, 1e6, 1.0, True)], [(1e12, 0.0, 1.0, True), (1e12, 9e11, 1.0, False)]):
        assert refused(lambda p=points: paint.stroke_dabs(p, 2500.0, 1.0, grid=GRID)) == OUTSIDE
    # Both ends outside, crossing the field: the crossing is painted.
    crossing = paint.stroke_dabs([(-999750.0, 0.0, 1.0, True), (1e6, 0.0, 1.0, False)], 2500.0, 1.0, grid=GRID)
    np.testing.assert_allclose(crossing[:, 0], np.arange(-37250.0, 37251.0, 500.0))
    assert crossing[0, 6] == 1 and not crossing[1:, 6].any()


def test_the_dabs_are_counted_before_any_is_laid():
    # Without a field to clip to, the two billion dabs are counted, not laid.
    start = time.perf_counter()
    message = refused(lambda: paint.stroke_dabs([(0.0, 0.0, 1.0, True), (1e12, 0.0, 1.0, False)], 2500.0, 1.0))
    assert time.perf_counter() - start < 1.0
    assert message == (
        "this stroke would lay 2,000,000,001 dabs, over the 1,000,000 a paint layer holds: paint shorter strokes "
        "or with a larger radius, or start a new paint layer (Data Field > +, kind Paint)"
    )
    # Zig-zags over the field add up to the cap the same way.
    zigzag = [(-30000.0 if i % 2 else 30000.0, 0.0, 1.0, i == 0) for i in range(2000)]
    assert "this stroke would lay" in refused(lambda: paint.stroke_dabs(zigzag, 100.0, 1.0, grid=GRID))
    assert refused(lambda: paint.check_room(999_990, 11, "Paint Coverage")) == (
        "the paint layer 'Paint Coverage' holds 999,990 dabs, and this stroke would lay 11 dabs, over the "
        "1,000,000 a paint layer holds: paint shorter strokes or with a larger radius, or start a new paint layer "
        "(Data Field > +, kind Paint)"
    )
    paint.check_room(999_990, 10, "Paint Coverage")


# ---- defects 2 and 3: values past float32, radii it cannot hold --------------------------------------------


def test_infinite_and_float32_sized_values_are_refused_with_what_to_do():
    cases = [
        ([(0.0, 0.0, 1.0, True), (FLT_MAX, 0.0, 1.0, False)], "the x of stroke point 2", " of metres", "infinite"),
        ([(0.0, -math.inf, 1.0, True)], "the y of stroke point 1", " of metres", "infinite"),
        ([(0.0, 3.1e38, 1.0, True)], "the y of stroke point 1", " of metres", "3.1e+38 (3e+38 or more)"),
        ([(0.0, 0.0, math.nan, True)], "the pressure of stroke point 1", "", "NaN"),
    ]
    for points, what, unit, shown in cases:
        fix = "give a pressure between 0 and 1" if "pressure" in what else "give finite world locations"
        assert refused(lambda p=points: paint.check_points(GRID, p)) == (
            f"{what} must be a finite number{unit}, not {shown}: {fix}"
        )
    assert refused(lambda: paint.check_points(GRID, [])) == "the stroke has no points: give it at least one location"
    paint.check_points(GRID, [(1e12, 0.0, 1.0, True), (0.0, 0.0, 1.0, False)])  # far, but a number: clipped


def test_the_brush_radius_and_strength_sentences():
    radius = "the brush radius must be a finite number of metres, not {}: use 68.4 to 70000 m"
    for value, shown in ((math.inf, "infinite"), (FLT_MAX, "infinite"), (math.nan, "NaN")):
        assert refused(lambda v=value: paint.check_brush(GRID, v, 1.0)) == radius.format(shown)
    small = (
        "the brush radius {} m is smaller than half a field pixel (68.4 m): use at least 68.4 m, "
        "or raise the field resolution"
    )
    for value in (0.0, 1e-300):
        assert refused(lambda v=value: paint.check_brush(GRID, v, 1.0)) == small.format(f"{value:g}")
    assert refused(lambda: paint.check_brush(GRID, 1e6, 1.0)) == (
        "the brush radius 1e+06 m is larger than the whole field (70000 m across): use at most 70000 m "
        "(a constant or gradient layer changes the whole field)"
    )
    assert refused(lambda: paint.check_brush(GRID, 2500.0, math.nan)) == (
        "the brush strength must be a finite number, not NaN: use a strength between 0.01 and 1"
    )
    for value in (0.0, 5.0, -0.5):
        assert refused(lambda v=value: paint.check_brush(GRID, 2500.0, v)) == (
            f"the brush strength {value:g} is not in (0, 1]: use a strength between 0.01 and 1"
        )
    paint.check_brush(GRID, 68.4, 1.0)
    paint.check_brush(GRID, 70000.0, 0.01)
    # The finest field: half a pixel is 12 mm, and the millimetre rule is under it.
    fine = paint.Grid(4096, 100.0, 0.0, 0.0)
    assert refused(lambda: paint.check_brush(fine, 0.001, 1.0)).endswith(
        "use at least 0.0123 m, or raise the field resolution"
    )


def test_a_stored_dab_too_small_for_float32_is_skipped_by_the_raster():
    r = paintraster.Raster(GRID)
    for dab in ((0.0, 0.0, 0.0, 1.0, 0, 0, 1), (0.0, 0.0, 1e-300, 1.0, 0, 0, 1), (FLT_MAX, 0.0, 2500.0, 1.0, 0, 0, 1)):
        assert r.add(dab) is None
    assert r.values.max() == 0.0 and np.isfinite(r.values).all()


# ---- defect 4: a preset's dabs, by the same rules --------------------------------------------------------


def preset_with_dab(row: str) -> bytes:
    return (
        '[[field.layers]]\nkind = "paint"\nchannel = "coverage"\n'
        f"dabs = [\n  {row},\n  [0.0, 0.0, 2500.0, 1.0, 0, 0, 0],\n]\n"
    ).encode()


@pytest.mark.parametrize(
    ("row", "sentence"),
    [
        ("[0.0, 0.0, 1e-300, 1.0, 0, 0, 1]", "the radius 1e-300 m is under a millimetre: use at least 0.001 m"),
        (
            "[0.0, 0.0, 1e300, 1.0, 0, 0, 1]",
            "the radius must be a finite number of metres, not 1e+300 (3e+38 or more): use 0.001 to 10000000 m",
        ),
        (
            "[0.0, 0.0, 2e7, 1.0, 0, 0, 1]",
            "the radius 2e+07 m is larger than the widest data field (10000000 m across): use at most 10000000 m "
            "(a constant or gradient layer changes the whole field)",
        ),
        (
            "[1e300, 0.0, 2500.0, 1.0, 0, 0, 1]",
            "x must be a finite number of metres, not 1e+300 (3e+38 or more): fix or remove the dab",
        ),
        (
            "[0.0, -2e8, 2500.0, 1.0, 0, 0, 1]",
            "y = -2e+08 m is too far out: keep a dab within 1e+08 m of the origin (the farthest data field ends "
            "1.5e+07 m from it), or remove it",
        ),
        (
            "[0.0, inf, 2500.0, 1.0, 0, 0, 1]",
            "y must be a finite number of metres, not infinite: fix or remove the dab",
        ),
        (
            "[0.0, 0.0, nan, 1.0, 0, 0, 1]",
            "the radius must be a finite number of metres, not NaN: use 0.001 to 10000000 m",
        ),
        ("[0.0, 0, 2500.0, 1.5, 0, 0, 1]", "the strength 1.5 is outside -1 to 1: use -1 (subtract) to 1 (add)"),
        ("[0.0, 0.0, 2500.0, 1.0, 0, 0, 1e400]", "start must be a finite number, not infinite: fix or remove the dab"),
        (
            f"[0, {10**400}, 2500.0, 1.0, 0, 0, 1]",
            "y must be a finite number of metres, not infinite: fix or remove the dab",
        ),
    ],
)
def test_a_presets_dabs_are_refused_with_their_sentence(tmp_path, row, sentence):
    path = tmp_path / "p.toml"
    message = refused(lambda: presets.preset_from_bytes(preset_with_dab(row), path))
    assert message == f"{path}: field.layers[0].dabs[0]: {sentence}"


def test_a_presets_dabs_keep_what_strokes_make():
    """Negative strengths (Subtract), a pen's zero pressure, a radius of a millimetre, dabs kept off the field."""
    rows = "[-9e7, 0.0, 0.001, -1.0, 2, 1, 1],\n  [0.0, 0.0, 1e7, 0.0, 0, 0, 0],\n  [1, 2, 3, 1, 1, 0, 0]"
    layer = presets.preset_from_bytes(preset_with_dab(rows)).layers[0]
    assert layer["dabs"][:3] == [
        [-9e7, 0.0, 0.001, -1.0, 2, 1, 1],
        [0.0, 0.0, 1e7, 0.0, 0, 0, 0],
        [1.0, 2.0, 3.0, 1.0, 1, 0, 0],
    ]


# ---- defect 5: the notice before a long composite ----------------------------------------------------------


def test_a_long_composite_is_announced_with_its_time_and_an_absurd_one_refused():
    dabs = np.zeros((1_000_000, 7))
    dabs[:, 2] = 2500.0
    dabs[::100, 6] = 1  # 10,000 strokes of 100 dabs
    start = time.perf_counter()
    cost = paintraster.raster_cost(dabs, GRID)
    assert time.perf_counter() - start < 0.5  # arithmetic, nothing rasterized
    # Measured here: 33 s for such a layer (core/paint.py's comment); the estimate says about 40-45 s.
    assert 30.0 < cost.seconds < 60.0
    assert paintraster.notice(cost) == f"compositing 1,000,000 dabs takes about {cost.seconds:.0f} s"
    assert paintraster.notice(paintraster.raster_cost(dabs[:1000], GRID)) is None  # 40 ms: no notice
    paintraster.check_cost(cost)
    huge = paintraster.Cost(128_000_000, 5000.0, 30 * 2**30)
    assert refused(lambda: paintraster.check_cost(huge)) == (
        "compositing 128,000,000 dabs would hold about 30.0 GB, over the 8 GB Nubis allows: clear or disable "
        "paint layers, or lower the field resolution"
    )
    # A cached raster counts as done: only a stroke's new dabs are still to rasterize.
    paintraster.forget()
    some = dabs[:2000]
    paintraster.raster(11, some, GRID)
    grown = np.vstack([some, dabs[:500]])
    assert paintraster.composite_cost([(11, grown)], GRID).dabs == 500
    assert paintraster.composite_cost([(11, dabs[:10])], GRID).dabs == 10  # an undo: from scratch
    paintraster.forget()


def test_the_raster_prints_the_notice_before_a_long_composite(monkeypatch):
    from nubis_addon.core import console

    lines = []
    monkeypatch.setattr(paintraster, "NOTICE_S", 0.0)
    monkeypatch.setattr(console, "current", lambda: type("C", (), {"line": staticmethod(lines.append)})())
    paintraster.forget()
    paintraster.raster(12, paint.stroke_dabs([(0.0, 0.0, 1.0, True), (5000.0, 0.0, 1.0, False)], 2500.0, 1.0), GRID)
    paintraster.forget()
    assert len(lines) == 1 and lines[0].startswith("Nubis: compositing 11 dabs takes about ")


def test_a_stroke_of_more_than_a_million_points_is_refused_before_blender_copies_it():
    paint.check_stroke_length(paint.MAX_STROKE_POINTS)  # at the limit: painted
    with pytest.raises(NubisError) as err:
        paint.check_stroke_length(1_100_000)
    assert str(err.value) == (
        "the stroke has 1,100,000 points, over the 1,000,000 one stroke may hold: paint it as several strokes "
        "(one call each)"
    )
