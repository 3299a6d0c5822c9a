"""The Coverage slider as the fraction of the sky the low clouds cover (docs/sources.md#coverage-slider).

The density model multiplies the painted coverage field by one number before GPU Pro 7's remap
(`density_coverage` in the shaders). That number is steep and depends on the field: on the default
cloudscape 0.5 covers 1.5 % of the sky seen from above, 1.0 covers 27 % and 2.0 only 78 %. The artist
sets the fraction instead, and this module finds the multiplier that gives it for the scene's field.

A column of the sky is covered when the clouds' opacity seen from straight above exceeds 0.05 (the
threshold `render` reports as cloud cover). For a field of one coverage value c everywhere that happens
in a fraction COVERED_AT(c) of the columns: the base noise decides which. For any field the covered
fraction is then the mean of COVERED_AT over the field's texels, each multiplied and clamped as the
shader does. The table below was measured with the viewport's own march (a 256x256 orthographic view
straight down over 44.5 km of the default cloudscape, cumulus and stratocumulus types, 1.5-4 km layer,
erosion 0.3, cirrus off); the same sum predicts the measured fraction of the default field within 0.02
at every multiplier from 0.5 to 2. No bpy here."""

from __future__ import annotations

import numpy as np

# (uniform coverage, fraction of columns covered) measured as described above.
COVERED_AT = (
    (0.0, 0.0),
    (0.05, 0.0),
    (0.10, 0.0003),
    (0.15, 0.0049),
    (0.20, 0.0379),
    (0.25, 0.1416),
    (0.30, 0.3070),
    (0.35, 0.4939),
    (0.40, 0.6770),
    (0.45, 0.8267),
    (0.50, 0.9250),
    (0.55, 0.9743),
    (0.60, 0.9896),
    (0.65, 0.9952),
    (0.70, 0.9961),
    (0.80, 0.9966),
    (0.90, 0.9970),
    (1.00, 0.9974),
)
_UNIFORM_COVERAGE = np.array([c for c, _ in COVERED_AT])
_FRACTION_COVERED = np.array([f for _, f in COVERED_AT])

# The largest multiplier the slider reaches: enough to lift a field's faintest tenth to full coverage.
MAX_MULTIPLIER = 50.0
LEVELS = 1023


def histogram(coverage_field: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(values, weights) of a coverage field, clamped to 0-1 as the shader reads them and rounded to
    1/LEVELS (no coverage stays exactly none, whatever the multiplier)."""
    values = np.clip(np.nan_to_num(np.asarray(coverage_field, np.float32), nan=0.0), 0.0, 1.0)
    levels, counts = np.unique(np.rint(values * LEVELS).astype(np.int32), return_counts=True)
    return levels / LEVELS, counts / max(counts.sum(), 1)


def covered_fraction(multiplier: float, hist: tuple[np.ndarray, np.ndarray]) -> float:
    """The fraction of the sky covered seen from above with this multiplier on the field."""
    centres, weights = hist
    covered = np.interp(np.clip(centres * multiplier, 0.0, 1.0), _UNIFORM_COVERAGE, _FRACTION_COVERED)
    return float(np.dot(weights, covered))


def multiplier_for(cover: float, hist: tuple[np.ndarray, np.ndarray]) -> float:
    """The multiplier on the field that covers `cover` of the sky (0 clear, 1 overcast): the smallest
    one that reaches it, found by bisection (the covered fraction only grows with the multiplier)."""
    if not cover > 0.0:  # also NaN
        return 0.0
    lo, hi = 0.0, MAX_MULTIPLIER
    if covered_fraction(hi, hist) <= cover:
        return hi
    for _ in range(40):
        mid = (lo + hi) / 2
        if covered_fraction(mid, hist) < cover:
            lo = mid
        else:
            hi = mid
    return hi
